"""Start anywhere: at rest, or moving at any speed, with or without a heading (issue 20).

The car's start (:func:`selfnav.ins.align.init_from_gnss`) waits for a straight run faster than
5 m/s and takes the heading from the course. A walker, a slow robot, a boat or a drone may
never give one. This start needs neither a speed nor a straight line:

1. **The fixes.** After a run of healthy fixes (:func:`selfnav.ins.align.healthy_start`), the
   last ``any_window_s`` of them — or, where the course may give the heading, the longest
   trailing window up to ``course_window_s`` on a straight line at constant speed
   (:func:`course_window`: a walker's course from 12 s of 2 m fixes is known to 6°, from 4 s
   to 20°): position and velocity from a weighted straight-line fit at the window's centre
   ``t0``; the fit's covariance is scaled up by its residuals when the
   platform turned or accelerated inside the window (``max(1, χ²/dof)``), and the position σ
   is never below one fix's (the receivers' errors drift: averaging does not remove them).
2. **At rest** — the fit's speed within three σ of zero *and* the IMU quiet over the window
   (its scatter within what a hand holding the unit still shows, the ceilings of
   :func:`selfnav.ins.rest.find_still`, or every sample still against the buffer's own noise
   floor): levelled
   on the mean specific force (:func:`selfnav.ins.rest.level_at_rest`: the accelerometer bias
   is in the tilt σ, ``σ_ba / g``), the gyro bias from the mean rate less the vertical Earth
   rate, the velocity zero (σ 0.05 m/s — a hand holding the unit trembles — and the fitted
   speed: a rover creeping at 0.3 m/s is as quiet as one parked). Quiet is not at rest: a
   steady acceleration (a car braking smoothly) is as quiet and levelled is a tilt, so the
   fixes over the longest trailing span of quiet IMU (up to 32 s) must show no motion and
   bound the acceleration to a 6° tilt at one σ (:func:`_rest_verdict`; that σ joins the
   tilt σ); until they can, no start.
   **Moving** — the specific force over the window, each sample carried by the gyros into the
   body frame at the window's start (:func:`selfnav.latitude.gyro_attitude`), averages to
   gravity plus the window's mean acceleration ``ā``; the fit's second-order term bounds
   ``ā``, which cannot be rotated into the body without the heading, so it goes into the tilt
   σ: ``atan((|ā| + 2 σ_ā + σ_ba) / g)`` plus the gyro bias σ over the window. The gyro
   bias from the last still stretch of the buffer, if there is one (a walker who stood first).
3. **Heading** — the course of the velocity where the platform moves along its body's forward
   axis (``course_heading``, a fact of the platform: a car, a rover, a walker holding the unit
   ahead, a boat; not a multirotor) and moves fast enough for it (six velocity σ), with the
   platform's yaw about its course (``course_heading_sigma``) as σ. Else the magnetometer
   where there is one, levelled with the start's tilt, with IGRF's declination
   (:func:`selfnav.ins.rest.heading_from_magnetometer`; σ floored at
   :data:`MAG_START_FLOOR_DEG`: its iron is not calibrated). Otherwise unknown: a σ the whole
   circle wide (:data:`UNKNOWN_HEADING_SIGMA`). A heading σ beyond the filter's linear range
   is split by the navigator into hypotheses that the motion resolves
   (:mod:`selfnav.ins.headings`).

Everything is from the buffer it is given (the start-up stage's past); the fixes of the window
are in the state with a quarter of their information (σ doubled, ``fix_share``), so the filter
takes the window's fixes after the start's time with the rest of it and every fix after
``t_used`` in full.
"""
from __future__ import annotations

import math

import numpy as np

from selfnav import attitude as att
from selfnav.earth import enu_offset, radii
from selfnav.errors import SelfnavError
from selfnav.ins.align import START_FIX_SHARE, fix_sigmas, healthy_start
from selfnav.ins.config import FilterConfig, chi2_999
from selfnav.ins.rest import (IGRF_DECLINATION_SIGMA_DEG, MAX_GYRO_BIAS, MAX_STILL_ACCEL_STD,
                              MAX_STILL_GYRO_STD, declination_at, find_still,
                              heading_from_magnetometer, level_at_rest)
from selfnav.latitude import gyro_attitude
from selfnav.types import GnssData, ImuData

#: A heading prior wide enough to be uniform over the circle for the hypotheses, rad (their
#: split spans ±π; a Gaussian of this σ weighs its edges 0.5 % below its centre).
UNKNOWN_HEADING_SIGMA = 10.0
#: σ of the velocity of a platform found at rest (a hand holding the unit still trembles), m/s
REST_VELOCITY_SIGMA = 0.05
#: Heading σ floor of an uncalibrated magnetometer at the start, deg: a body's hard and soft
#: iron (the simulator's car-grade 500 nT / 2 %) leave the heading 10-20° off
MAG_START_FLOOR_DEG = 20.0
#: Motion the fallback start needs to see in the fixes, whatever their σ: metres, m/s
MIN_DISPLACEMENT_M = 1.0
MIN_SPEED = 0.1
#: The longest trailing span of quiet IMU over which the fixes are asked to confirm rest, s
REST_CONFIRM_LONGEST_S = 32.0
#: A start at rest must bound, by its fixes, the steady acceleration a quiet IMU cannot tell
#: from a tilt to this tilt (one σ), deg (:func:`_rest_verdict`): else no start yet
REST_MAX_TILT_DEG = 6.0


def _fit(t, x, w, t0, order):
    """Weighted polynomial fit of ``x`` (N, k) in ``t − t0``; returns coefficients (order+1, k),
    their covariance for unit weights (order+1, order+1) and the weighted χ² per column."""
    tt = np.asarray(t, float) - t0
    A = np.vander(tt, order + 1, increasing=True)
    Aw = A * w[:, None]
    N = A.T @ Aw
    cov = np.linalg.inv(N)
    coef = cov @ (Aw.T @ x)
    r = x - A @ coef
    chi2 = (w[:, None] * r * r).sum(axis=0)
    return coef, cov, chi2


def _bias_from_last_stop(imu: ImuData, j_end: int, dt: float, accel_sig: float, lat: float,
                         cfg: FilterConfig, min_s: float = 2.0):
    """The gyro bias from the last still stretch (at least ``min_s``) of the buffer before
    sample ``j_end``: the mean rate less the vertical Earth rate, σ the white noise of the
    mean, the scatter of its quarter means and the bias instability — or None. A walker who
    stood before walking, a rover parked before driving: their yaw bias (a consumer part's
    1 °/s, 60° a minute) need not be learnt in motion."""
    if j_end < 10:
        return None
    still = find_still(imu.t[:j_end], imu.omega_ib_b[:j_end], imu.f_ib_b[:j_end])
    runs = still.stretches(imu.t[:j_end], min_s=min_s)
    if not runs:
        return None
    a, b = runs[-1]
    w, f = imu.omega_ib_b[a:b], imu.f_ib_b[a:b]
    lev = level_at_rest(f, w, dt=dt, accel_bias_sigma=accel_sig, lat=lat)
    sub_w, _ = _quarter_scatter(w, f)
    return lev.gyro_bias_b, np.sqrt(lev.sigma_gyro_bias**2 + sub_w**2
                                    + cfg.imu.gyro_bias_instability**2)


def _quarter_scatter(omega_b, f_b):
    """σ of the mean rate (per axis, rad/s) and of the levelled tilt (rad) from the scatter of
    the window's four quarter means: ``std / √4`` (zero for fewer than 8 samples)."""
    n = len(omega_b) // 4
    if n < 2:
        return np.zeros(3), 0.0
    q = np.arange(4 * n).reshape(4, n)
    w = omega_b[q].mean(axis=1)
    f = f_b[q].mean(axis=1)
    up = f / np.linalg.norm(f, axis=1, keepdims=True)
    tilt = np.column_stack([np.arcsin(np.clip(up[:, 1], -1, 1)), np.arctan2(-up[:, 0], up[:, 2])])
    return w.std(axis=0, ddof=1) / 2.0, float(np.max(tilt.std(axis=0, ddof=1))) / 2.0


def _steady(mag) -> bool:
    """The field's direction over the samples is steady (within 5°): not turning."""
    u = mag / np.linalg.norm(mag, axis=1, keepdims=True)
    return bool(np.min(u @ u.mean(axis=0)) >= math.cos(math.radians(5.0)) * np.linalg.norm(
        u.mean(axis=0)))


def fixes_window(gnss: GnssData, window_s: float, min_fixes: int = 3):
    """Indices of the last ``window_s`` of fixes (at least ``min_fixes``)."""
    t = np.asarray(gnss.t, float)
    sel = np.flatnonzero(t >= t[-1] - window_s)
    if len(sel) < min_fixes:
        sel = np.arange(max(len(t) - min_fixes, 0), len(t))
    if len(sel) < min_fixes:
        raise SelfnavError(f"{len(t)} GNSS fixes: a start needs {min_fixes}")
    return sel


def course_window(gnss: GnssData, sig_h, shortest_s: float, longest_s: float):
    """The longest trailing window of fixes (``longest_s`` down to twice ``shortest_s``) on
    a straight line at constant speed (χ² of the fit at 99.9 %) whose speed is beyond six of
    its σ: there the course is known best. None when there is none."""
    t = np.asarray(gnss.t, float)
    for w_s in np.arange(longest_s, 2.0 * shortest_s - 1e-9, -shortest_s):
        sel = np.flatnonzero(t >= t[-1] - w_s)
        m = len(sel)
        if m < 5 or t[-1] - t[sel[0]] < 0.75 * w_s:
            continue
        xy = enu_offset(gnss.lat[sel[0]], gnss.lon[sel[0]], 0.0, gnss.lat[sel], gnss.lon[sel],
                        0.0)[:, :2]
        coef, cov, chi2 = _fit(t[sel], xy, 1.0 / sig_h[sel] ** 2, float(t[sel].mean()), 1)
        if float(chi2.sum()) > chi2_999(2 * (m - 2)):
            continue
        if np.hypot(coef[1, 0], coef[1, 1]) > 6.0 * math.sqrt(cov[1, 1]):
            return sel
    return None


def _quiet(imu: ImuData, still, j0: int, j1: int) -> bool:
    """The IMU quiet over samples ``j0:j1``: its scatter within what a hand holding the unit
    still shows (walking, driving, rocking are beyond it), or every sample still against the
    buffer's own floor (``still``, :func:`selfnav.ins.rest.find_still`'s mask)."""
    wj, fj = imu.omega_ib_b[j0:j1], imu.f_ib_b[j0:j1]
    return bool(np.sqrt(np.mean(wj.std(axis=0) ** 2)) <= MAX_STILL_GYRO_STD
                and np.sqrt(np.mean(fj.std(axis=0) ** 2)) <= MAX_STILL_ACCEL_STD
                and np.linalg.norm(wj.mean(axis=0)) <= MAX_GYRO_BIAS) or bool(still[j0:j1].all())


def _rest_verdict(imu: ImuData, still, gnss: GnssData, sig_h, t_end: float,
                  shortest_s: float) -> tuple[bool, float]:
    """Whether the fixes agree that a platform whose IMU is quiet is at rest, and the σ of the
    steady acceleration they cannot exclude (m/s²).

    A quiet IMU tells rest from a steady turn but not from a steady acceleration, which
    levelling turns into a tilt (``atan(a / g)``: a car braking smoothly at 2 m/s², 12°). Over
    the trailing spans of quiet IMU (``shortest_s`` doubling up to
    :data:`REST_CONFIRM_LONGEST_S`), a weighted quadratic fit of the fixes (covariance scaled
    by ``max(1, χ²/dof)``): a speed or an acceleration beyond three σ is motion; else rest,
    with the acceleration σ of the longest span (an RTK receiver bounds it in seconds, a 10 m
    one at 1 Hz in some 20 s of standing still).
    """
    t = np.asarray(gnss.t, float)
    sig_h = np.asarray(sig_h, float)
    spans, L = [], float(shortest_s)
    while L < REST_CONFIRM_LONGEST_S:
        spans.append(L)
        L *= 2.0
    spans.append(REST_CONFIRM_LONGEST_S)
    held = t_end - max(float(imu.t[0]), float(t[0]))       # what the buffer holds
    spans = sorted({min(L, held) for L in spans})
    s_acc = np.inf
    for i, L in enumerate(spans):
        j0 = int(np.searchsorted(imu.t, t_end - L))
        j1 = int(np.searchsorted(imu.t, t_end, side="right"))
        if i > 0 and not _quiet(imu, still, j0, j1):    # the first: the caller's window
            break
        sel = np.flatnonzero((t >= t_end - L) & (t <= t_end))
        m = len(sel)
        if m < 4:
            continue
        xy = enu_offset(gnss.lat[sel[0]], gnss.lon[sel[0]], 0.0, gnss.lat[sel], gnss.lon[sel],
                        0.0)[:, :2]
        coef, cov, chi2 = _fit(t[sel], xy, 1.0 / sig_h[sel] ** 2, float(t[sel].mean()), 2)
        dof = 2 * (m - 3)
        scale = max(1.0, float(chi2.sum()) / dof) if dof > 0 else 1.0
        sv, sa = math.sqrt(cov[1, 1] * scale), 2.0 * math.sqrt(cov[2, 2] * scale)
        if (np.hypot(coef[1, 0], coef[1, 1]) > max(3.0 * sv, MIN_SPEED)
                or 2.0 * np.hypot(coef[2, 0], coef[2, 1]) > 3.0 * sa):
            return False, 0.0
        s_acc = sa
    return True, float(s_acc)


def init_anywhere(imu: ImuData, gnss: GnssData, cfg: FilterConfig, sig_h,
                  magnetometer=()) -> dict:
    """The start of any platform from the buffered past (module docstring).

    Parameters
    ----------
    imu : ImuData, true time, up to now
    gnss : GnssData, WGS-84, true time, healthy fixes up to now
    cfg : FilterConfig — ``init.any_window_s``, ``init.course_heading`` and
        ``init.course_heading_sigma``, the IMU noise
    sig_h : (N,) horizontal σ per axis of the fixes, m
    magnetometer : sequence of ``(t, mag_b)`` (true time, body RFU, any unit), optional

    Returns
    -------
    dict
        As :func:`selfnav.ins.align.init_from_gnss`, plus ``start_kind`` (``"rest"`` or
        ``"moving"``) and ``heading_source`` (``"course"``, ``"magnetometer"`` or
        ``"unknown"``).
    """
    ini = cfg.init
    sig_h = np.asarray(sig_h, float)
    sel = (course_window(gnss, sig_h, ini.any_window_s, ini.course_window_s)
           if ini.course_heading else None)
    if sel is None:
        sel = fixes_window(gnss, ini.any_window_s)
    t = np.asarray(gnss.t, float)[sel]
    t0 = float(np.mean(t))
    t_used = float(t[-1])
    lat_r, lon_r = float(gnss.lat[sel[0]]), float(gnss.lon[sel[0]])
    rm, rn = radii(lat_r, 0.0)
    xy = enu_offset(lat_r, lon_r, 0.0, gnss.lat[sel], gnss.lon[sel], 0.0)[:, :2]
    h = np.asarray(gnss.h, float)[sel]
    s = sig_h[sel]
    w = 1.0 / s**2
    m = len(sel)
    coef, cov, chi2 = _fit(t, np.column_stack([xy, h]), w, t0, 1)
    dof = 2 * (m - 2)
    scale = max(1.0, float(chi2[:2].sum()) / dof) if dof > 0 else 1.0
    sv = float(np.sqrt(cov[1, 1] * scale))
    v0 = np.array([coef[1, 0], coef[1, 1], coef[1, 2]])
    if gnss.velocity_n is not None:
        v0 = np.array([np.interp(t0, t, np.asarray(gnss.velocity_n)[sel, i]) for i in range(3)])
        sv = float(cfg.gnss.velocity_sigma)
    speed = float(np.hypot(v0[0], v0[1]))
    s_fix = float(np.median(s))
    sp = max(float(np.sqrt(cov[0, 0] * scale)), s_fix)

    # the IMU over the window (at most ``any_window_s`` about its centre: the gyros carry the
    # specific force to one frame, and their bias turns it the longer they carry it)
    half = 0.5 * min(float(t[-1] - t[0]), ini.any_window_s)
    j0 = int(np.searchsorted(imu.t, t0 - half))
    j1 = int(np.searchsorted(imu.t, t0 + half, side="right"))
    jc = int(np.clip(np.searchsorted(imu.t, t0), j0, max(j1 - 1, j0)))
    if j1 - j0 < 10:
        raise SelfnavError("too few IMU samples over the start's fixes")
    dt = float(np.median(np.diff(imu.t[j0:j1])))
    gyro_sig = float(cfg.imu.gyro_bias_sigma)
    accel_sig = float(cfg.imu.accel_bias_sigma)
    # still: the scatter of the window within what a hand holding the unit shows (walking,
    # driving, rocking are beyond it), or still against the buffer's own floor
    at_rest = bool(speed <= 3.0 * max(sv, 0.02))
    still = find_still(imu.t, imu.omega_ib_b, imu.f_ib_b).mask if at_rest else None
    at_rest = at_rest and _quiet(imu, still, j0, j1)
    tilt_rest = 0.0
    if at_rest:
        # quiet is not at rest: a steady acceleration (a car braking smoothly) is as quiet, and
        # levelled it is a tilt (2 m/s² a 12° one) — the fixes must rule it out first
        at_rest, s_rest_acc = _rest_verdict(imu, still, gnss, sig_h, t_used, ini.any_window_s)
        if at_rest:
            g_seen = float(np.linalg.norm(imu.f_ib_b[j0:j1].mean(axis=0)))
            tilt_rest = math.atan(s_rest_acc / g_seen)
            if tilt_rest > math.radians(REST_MAX_TILT_DEG):
                raise SelfnavError("the IMU is quiet but the fixes cannot yet tell rest from a "
                                   "steady acceleration")
    out = dict(t=t0, t_used=t_used, h=float(coef[0, 2]), fix_share=START_FIX_SHARE)
    if at_rest:
        lev = level_at_rest(imu.f_ib_b[j0:j1], imu.omega_ib_b[j0:j1], dt=dt,
                            accel_bias_sigma=accel_sig, lat=lat_r)
        roll, pitch = lev.roll, lev.pitch
        # a rocking platform (a boat drifting in the waves) is quiet but not at rest: its
        # window's mean rate and specific force wander from one part of it to the next, which
        # the white-noise σ of the mean does not see — the scatter of quarter-window means does
        sub_w, sub_t = _quarter_scatter(imu.omega_ib_b[j0:j1], imu.f_ib_b[j0:j1])
        s_tilt = math.hypot(math.hypot(lev.sigma_roll, sub_t), math.radians(0.1), tilt_rest)
        p0 = (w[:, None] * np.column_stack([xy, h])).sum(axis=0) / w.sum()
        out["h"] = float(p0[2])
        xy0 = p0[:2]
        # zero, with a σ that still covers what the fixes cannot exclude (a rover creeping
        # at 0.3 m/s is as quiet as one parked; a drifting receiver moves while the unit rests)
        s_v = np.full(3, math.hypot(REST_VELOCITY_SIGMA, speed))
        v0 = np.zeros(3)
        out["gyro_bias"] = lev.gyro_bias_b
        out["gyro_bias_sigma"] = np.sqrt(lev.sigma_gyro_bias**2 + sub_w**2
                                         + cfg.imu.gyro_bias_instability**2)
        kind = "rest"
    else:
        # the specific force in the body frame at the window's start, carried by the gyros
        om = np.ascontiguousarray(imu.omega_ib_b[j0:j1])
        q = gyro_attitude(om, np.full(len(om), dt))
        R = att.quat_to_dcm(q[:-1])                      # C_{b_k}^{b_0}
        f_b0 = np.einsum("kij,kj->i", R, imu.f_ib_b[j0:j1]) / (j1 - j0)
        roll0 = math.atan2(-f_b0[0], f_b0[2])
        pitch0 = math.atan2(f_b0[1], math.hypot(f_b0[0], f_b0[2]))
        C0 = att.dcm_nb_from_euler(roll0, pitch0, 0.0)
        roll, pitch, _ = att.euler_from_dcm_bn(C0.T @ att.quat_to_dcm(q[jc - j0]))
        # the window's mean acceleration, bounded by the fixes' second-order fit
        if m >= 4:
            c2, cov2, _ = _fit(t, xy, w, t0, 2)
            a_mean = 2.0 * float(np.hypot(c2[2, 0], c2[2, 1]))
            s_a = 2.0 * float(np.sqrt(cov2[2, 2]))
        else:
            a_mean, s_a = 0.0, 2.0 * sv / max(t[-1] - t[0], dt)
        g = float(np.linalg.norm(f_b0))
        dur = float(imu.t[j1 - 1] - imu.t[j0])
        s_tilt = math.hypot(math.atan((a_mean + 2.0 * s_a + accel_sig) / g),
                            gyro_sig * dur, math.radians(0.3))
        xy0 = coef[0, :2]
        s_v = np.array([2 * sv, 2 * sv, 2 * sv + 0.2])
        kind = "moving"
        bias = _bias_from_last_stop(imu, j0, dt, accel_sig, lat_r, cfg)
        if bias is not None:
            out["gyro_bias"], out["gyro_bias_sigma"] = bias
    lat = lat_r + xy0[1] / rm
    lon = lon_r + xy0[0] / (rn * math.cos(lat_r))
    if not at_rest and ini.course_heading and speed > 6.0 * sv:
        hdg = math.atan2(v0[0], v0[1])
        s_hdg = math.atan2(sv, speed) + ini.course_heading_sigma
        out["course_cov"] = np.eye(2) * (2 * sv) ** 2
        source = "course"
    else:
        hdg, s_hdg = 0.0, UNKNOWN_HEADING_SIGMA
        source = "unknown"
        mag = [mb for (tm, mb) in magnetometer if abs(tm - t0) <= 0.5 * ini.any_window_s]
        if mag and (at_rest or len(mag) == 1 or _steady(np.array(mag))):
            # the field at the start, levelled: uncalibrated (hard and soft iron) it is a
            # loose heading, but one the hypotheses need not search the circle for
            dec, _ = declination_at(lat, lon, out["h"])
            hdg, s_hdg = heading_from_magnetometer(np.array(mag), roll, pitch,
                                                   declination=dec, sigma_tilt=s_tilt,
                                                   sigma_declination=math.radians(
                                                       IGRF_DECLINATION_SIGMA_DEG),
                                                   floor_deg=MAG_START_FLOOR_DEG)
            source = "magnetometer"
    out.update(lat=lat, lon=lon, velocity_n=v0, C_nb=att.dcm_nb_from_euler(roll, pitch, hdg),
               sigmas=([2 * sp, 2 * sp, 3 * sp], s_v, [s_tilt, s_tilt, s_hdg]),
               start_kind=kind, heading_source=source)
    return out


def any_start(imu: ImuData, gnss: GnssData, cfg: FilterConfig, magnetometer=()) -> dict:
    """:func:`init_anywhere` on the fixes from the first healthy run on
    (:func:`selfnav.ins.align.healthy_start`, ``init.healthy_window`` fixes): an outlier
    window at power-on must not seed the start. ``magnetometer``: ``(t, mag_b)`` samples."""
    sig = fix_sigmas(gnss, cfg.gnss.sigma_floor)
    xy = enu_offset(gnss.lat[0], gnss.lon[0], 0.0, gnss.lat, gnss.lon, 0.0)[:, :2]
    window = int(cfg.init.healthy_window)
    k = healthy_start(gnss.t, xy, sig, window)
    if k is None:
        raise SelfnavError(f"no run of {window} healthy GNSS fixes yet")
    # the start is fitted on the latest fixes: they too must look healthy (an outlier window
    # after the first healthy run scatters the fit, and a start inside it — its σ the scatter's
    # — took the next outlier, 250 m off, at the receiver's 10 m σ: simulated drive 108)
    n = window + 2
    if k + n < len(sig) and healthy_start(gnss.t[-n:], xy[-n:], sig[-n:], window, each=False) != 0:
        raise SelfnavError(f"the last {n} GNSS fixes do not look healthy (an outlier window?)")
    out = init_anywhere(imu, gnss.select(slice(k, None)), cfg, sig[k:], magnetometer)
    out["t_healthy"] = float(gnss.t[k])         # where the healthy run begins
    return out


def moving_seconds(gnss: GnssData, sig_h, half_window_s: float = 5.0,
                   step_s: float = 1.0) -> float:
    """Seconds in which the fixes show the platform moving: on a grid of ``step_s``, a
    straight-line fit over the fixes within ``± half_window_s`` whose speed is beyond three of
    its σ and :data:`MIN_SPEED` (engine vibration, a trembling hand or an RTK receiver's
    centimetres are not motion)."""
    t = np.asarray(gnss.t, float)
    if len(t) < 3:
        return 0.0
    xy = enu_offset(gnss.lat[0], gnss.lon[0], 0.0, gnss.lat, gnss.lon, 0.0)[:, :2]
    w = 1.0 / np.asarray(sig_h, float) ** 2
    moved = 0.0
    for tau in np.arange(t[0] + half_window_s, t[-1] - half_window_s + 1e-9, step_s):
        a, b = np.searchsorted(t, [tau - half_window_s, tau + half_window_s], side="left")
        if b - a < 3:
            continue
        coef, cov, _ = _fit(t[a:b], xy[a:b], w[a:b], tau, 1)
        if np.hypot(coef[1, 0], coef[1, 1]) > max(3.0 * math.sqrt(cov[1, 1]), MIN_SPEED):
            moved += step_s
    return moved


def displaced(gnss: GnssData, sig_h, window_s: float = 30.0) -> bool:
    """Whether the fixes of the last ``window_s`` moved beyond their noise: some fix lies more
    than ``3 √2 σ`` (σ their median) and :data:`MIN_DISPLACEMENT_M` from the last one, and a
    straight-line fit's speed is beyond three of its σ and :data:`MIN_SPEED` (an RTK
    receiver at rest wanders by centimetres, many of its σ)."""
    sel = fixes_window(gnss, window_s, min_fixes=2)
    xy = enu_offset(gnss.lat[sel[-1]], gnss.lon[sel[-1]], 0.0, gnss.lat[sel], gnss.lon[sel],
                    0.0)[:, :2]
    s = np.asarray(sig_h, float)[sel]
    tol = max(3.0 * math.sqrt(2.0) * float(np.median(s)), MIN_DISPLACEMENT_M)
    if len(sel) < 3 or not np.max(np.hypot(xy[:, 0], xy[:, 1])) > tol:
        return False
    t = np.asarray(gnss.t, float)[sel]
    coef, cov, _ = _fit(t, xy, 1.0 / s**2, float(t.mean()), 1)
    return bool(np.hypot(coef[1, 0], coef[1, 1]) > max(3.0 * math.sqrt(cov[1, 1]), MIN_SPEED))


def recent_speed(gnss: GnssData, sig_h, window_s: float = 10.0) -> float:
    """Horizontal speed of a straight-line fit over the last ``window_s`` of fixes, m/s."""
    sel = fixes_window(gnss, window_s)
    t = np.asarray(gnss.t, float)[sel]
    xy = enu_offset(gnss.lat[sel[0]], gnss.lon[sel[0]], 0.0, gnss.lat[sel], gnss.lon[sel],
                    0.0)[:, :2]
    coef, _, _ = _fit(t, xy, 1.0 / np.asarray(sig_h, float)[sel] ** 2, float(t.mean()), 1)
    return float(np.hypot(coef[1, 0], coef[1, 1]))


__all__ = ["UNKNOWN_HEADING_SIGMA", "any_start", "course_window", "displaced", "fixes_window",
           "init_anywhere", "moving_seconds", "recent_speed"]
