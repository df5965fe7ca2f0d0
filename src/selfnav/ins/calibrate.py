"""Noise and timing from the data: the navigator calibrates itself (DESIGN §10, issue 10).

An outlier defence is only as good as the covariance it trusts, and a preset is a guess. Three
measurements replace the guess before and during the run:

1. **IMU noise at rest** (:func:`measure_noise`): on the still segments (the IMU quiet *and*,
   where GNSS says so, the vehicle stopped), the white noise of each sensor is the Allan
   deviation in its white-noise region, taken conservatively as ``max σ_A(τ)·√τ`` over
   ``τ`` = 0.3…3 s — engine vibration and a rocking car count as noise, which they are for a
   filter; the gyro bias is the still mean (less the Earth rate it contains, unknown in
   direction: its size goes into the bias σ); the accelerometers' error shows as
   ``| |f| − g |``.
2. **IMU–GNSS time offset** (:func:`estimate_time_offset`): the gyro heading (yaw rate about
   the mean specific-force direction, integrated) against the GNSS course, over every
   stretch faster than 3 m/s, with a constant per stretch and one heading drift (the gyro
   bias); the offset minimises the misfit (5 ms grid, parabolic refinement). Turns carry the
   information: a drive without turns returns no estimate.
3. **Process-noise scale online** (:class:`NoiseAdapter`): ``λ`` multiplies the filter's
   process noise. It is driven only by the fixes the fault bank trusts
   (:mod:`selfnav.ins.hypotheses`: used, no episode open), by the filter's normalised
   innovations (upward, when the INS is more uncertain than it says), as a fixed point;
   never below 1 — an outlier that is not trusted never enters, so outliers cannot pump
   ``λ`` up.
4. **Covariance reopening** (:meth:`NoiseAdapter.on_fix`): ``λ`` moves by at most 5 % a fix,
   too slow for a filter whose *state* is off by more than its covariance says (a start in
   motion that left the tilt 5σ off: its velocity ran 8 m/s off in 10 s with every fix fused
   at NIS 5–16). The sum of the last ``n`` trusted fixes' NIS, for ``n`` = 8, 16, 32, is a χ²
   test of ``2n`` dimensions (each at a third of the false-alarm probability); beyond its gate
   ``P`` is scaled by their mean per dimension — one step of a fading-memory filter (Xia,
   Rao, Ying & Shen 1994), taken once and the window begun again. Only while no reference of
   the fault bank stands (a start, a restart): with references, innovations that grow are
   theirs to judge — a drag's first fixes reopened ``P`` and the drag captured the filter
   (drive_0708, a held-out placement: 273 m RMS after the window).

A preset is a prior: where the data is noisier than it says, the measured values win and
:func:`calibrated_config` returns one warning line saying so.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from selfnav import sensors
from selfnav.allan import allan_deviation
from selfnav.earth import OMEGA_EARTH, enu_offset, normal_gravity
from selfnav.ins.config import FilterConfig, ImuNoise
from selfnav.ins.policy import chi2_gate
from selfnav.kernels import median_abs_second_difference
from selfnav.types import GnssData, ImuData
from selfnav.units import DEG

#: a still segment needs this many seconds of quiet IMU (and, with GNSS, a stopped vehicle)
STILL_MIN_S = 5.0
#: GNSS speed below which the vehicle is stopped, m/s
STILL_SPEED = 0.3
#: Allan cluster times of the white-noise measurement, s
WHITE_TAU = (0.3, 3.0)
#: the measured noise wins over the prior when it is this many times larger (and is reported)
NOISIER_THAN_PRIOR = 2.0
#: median of χ² with 2 degrees of freedom (2 ln 2)
CHI2_2_MEDIAN = 1.3862943611198906
#: seconds of still data after which the measured white noise replaces the prior both ways
WHITE_TRUST_S = 20.0
#: the GNSS course is used above this speed, m/s
COURSE_MIN_SPEED = 3.0
#: time offsets searched by the pre-pass, s
OFFSET_RANGE = 0.6
#: m: fixes this precise (RTK) give the course from their positions, free of the lag a
#: receiver's velocity may have (drive_0708's .pos velocity lags 0.12 s)
PRECISE_POSITION_M = 0.3
#: a course from position differences is used only below this speed, m/s, and where it agrees
#: with its neighbours' velocity within ``COURSE_MAX_ACCEL`` m/s² (unflagged outliers)
COURSE_MAX_SPEED = 70.0
COURSE_MAX_ACCEL = 15.0
#: course residuals beyond this count as this (a truncated misfit: outliers cannot pull), rad
COURSE_TRUNCATE = 20.0 * DEG


@dataclass
class MeasuredNoise:
    """What :func:`measure_noise` found (SI units; ``None`` where nothing was still)."""

    still_s: float
    vibration: tuple | None = None       # (gyro, accelerometer) vibration_level at rest
    arw: float | None = None
    vrw: float | None = None
    gyro_bias: np.ndarray | None = None
    gyro_bias_sigma: float | None = None
    accel_error: float | None = None


def _runs(mask):
    """``(start, stop)`` index pairs of the True runs of a boolean array."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def still_mask(imu: ImuData, gnss: GnssData | None = None, *, window_s: float = 1.0) -> np.ndarray:
    """Samples in still segments: runs of quiet 1 s windows (|f| steady, no turn) at least
    :data:`STILL_MIN_S` long during which the GNSS (where it covers them) shows a stopped
    vehicle: its speed below :data:`STILL_SPEED` where the file has velocity, else its fixes
    within ``3σ + 0.5 m`` of their mean. Without GNSS an IMU-quiet run counts (an IMU cannot
    tell rest from a steady cruise: prefer giving the GNSS)."""
    n = len(imu.t)
    m = max(2, int(round(window_s / imu.dt)))
    nb = n // m
    if nb < 2:
        return np.zeros(n, bool)
    fn = np.linalg.norm(imu.f_ib_b[: nb * m], axis=1).reshape(nb, m)
    w = imu.omega_ib_b[: nb * m].reshape(nb, m, 3).mean(axis=1)
    # quiet: specific-force magnitude steady to 0.2 m/s², no turn faster than 3 °/s
    quiet = (fn.std(axis=1) < 0.2) & (np.abs(fn.mean(axis=1) - np.median(fn)) < 0.3) & (
        np.linalg.norm(w - np.median(w, axis=0), axis=1) < 3.0 * DEG)
    out = np.zeros(n, bool)
    out[: nb * m] = np.repeat(quiet, m)
    keep = np.zeros(n, bool)
    f_win = imu.f_ib_b[: nb * m].reshape(nb, m, 3).mean(axis=1)
    blk = max(1, int(round(STILL_MIN_S / window_s)))      # windows per block
    for a, b in _runs(out):
        # judge each run block by block: a stop ends with the car pulling away, and the
        # blocks before that are still
        ka, kb = a // m, b // m
        for j0 in range(ka, kb - blk + 1, blk):
            j1 = j0 + blk if kb - (j0 + blk) >= blk else kb
            i0, i1 = j0 * m, min(j1 * m, n)
            if gnss is not None and not _gnss_stopped(gnss, imu.t[i0], imu.t[i1 - 1]):
                continue
            # at rest the window means do not move: no braking, no pulling away, no turn
            if (np.max(np.linalg.norm(f_win[j0:j1] - f_win[j0:j1].mean(axis=0), axis=1)) > 0.1
                    or np.max(np.linalg.norm(w[j0:j1] - w[j0:j1].mean(axis=0), axis=1))
                    > 0.5 * DEG):
                continue
            keep[i0:i1] = True
    return keep


def _gnss_stopped(gnss: GnssData, t0, t1) -> bool:
    """Does the GNSS show the vehicle stopped over [t0, t1]? (True where it has no fix.)"""
    k = (gnss.t >= t0) & (gnss.t <= t1)
    if k.sum() < 2:
        return True
    if gnss.velocity_n is not None and np.all(np.isfinite(gnss.velocity_n[k, :2])):
        return bool(np.all(np.hypot(gnss.velocity_n[k, 0], gnss.velocity_n[k, 1]) < STILL_SPEED))
    sig = gnss.sigma_m[k] if gnss.sigma_m is not None else np.full(int(k.sum()), 5.0)
    sig = np.where(np.isfinite(sig), sig, 5.0)
    p = enu_offset(gnss.lat[k][0], gnss.lon[k][0], 0.0, gnss.lat[k], gnss.lon[k], 0.0)[:, :2]
    spread = np.hypot(*(p - p.mean(axis=0)).T)
    return bool(np.all(spread <= 3.0 * sig + 0.5))


def vibration_level(w, f):
    """The vibration an IMU block carries: per axis the variance of the high-frequency part,
    from the second differences ``x_{k+1} − 2 x_k + x_{k−1}`` (6σ² for white noise; smooth
    motion, even a ramp of acceleration, leaves none) as a median (a kink where the motion
    changes does not decide), the mean over axes, for the rates and the specific force."""
    if len(w) < 5:
        return None

    def level(x):
        s = median_abs_second_difference(np.ascontiguousarray(x, dtype=float)) / (
            0.6744897501960817 * np.sqrt(6.0))
        return float((s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) / 3.0)

    return level(np.asarray(w)), level(np.asarray(f))


def vibration_scale(level, reference, cap: float):
    """Process-noise factors ``(k_g, k_a)`` of a block whose vibration ``level`` is this many
    times the ``reference`` (the still segment's, or the white noise the model assumes):
    vibration is noise to a strapdown INS — aliased into the band, rectified into bias,
    coning and sculling — and its power is what the factor follows (at least 1, at most
    ``cap``)."""
    if level is None or reference is None:
        return 1.0, 1.0
    (lg, la), (rg, ra) = level, reference
    return (float(min(max(lg / max(rg, 1e-30), 1.0), cap)),
            float(min(max(la / max(ra, 1e-30), 1.0), cap)))


def _white_density(x, dt):
    """Conservative white-noise density of a rate record: ``max σ_A(τ)·√τ`` on WHITE_TAU;
    ``None`` when the record is not noise at rest (the density grows with τ: motion, a drift)."""
    tau, adev, _ = allan_deviation(x, dt)
    sel = (tau >= WHITE_TAU[0]) & (tau <= WHITE_TAU[1])
    if sel.sum() < 2:
        return None
    n = adev[sel] * np.sqrt(tau[sel])
    if n[-1] > 3.0 * n[0]:
        return None
    return float(np.max(n))


def measure_noise(imu: ImuData, still: np.ndarray) -> MeasuredNoise:
    """White noise, gyro bias and accelerometer error from the still samples (module doc)."""
    runs = [(a, b) for a, b in _runs(still) if (b - a) * imu.dt >= STILL_MIN_S]
    if not runs:
        return MeasuredNoise(0.0)
    dt = imu.dt
    dens_g, dens_a, weights = [], [], []
    for a, b in runs:
        w = imu.omega_ib_b[a:b]
        f = imu.f_ib_b[a:b]
        dg = [_white_density(w[:, k], dt) for k in range(3)]
        da = [_white_density(f[:, k], dt) for k in range(3)]
        if None in dg or None in da:
            continue
        # isotropic equivalents (the filter's noise is one figure per sensor triad)
        dens_g.append(math.sqrt(np.mean(np.square(dg))))
        dens_a.append(math.sqrt(np.mean(np.square(da))))
        weights.append(b - a)
    if not weights:
        return MeasuredNoise(0.0)
    idx = np.concatenate([np.arange(a, b) for a, b in runs])
    w_mean = imu.omega_ib_b[idx].mean(axis=0)
    f_norm = float(np.linalg.norm(imu.f_ib_b[idx].mean(axis=0)))
    lat = imu.meta.get("lat")
    g = float(normal_gravity(lat if lat is not None else np.radians(45.0)))
    # the still mean is bias + Earth rate (direction unknown): σ covers the Earth-rate part
    bias_sigma = math.hypot(OMEGA_EARTH, float(np.max(np.abs(w_mean))) * 0.1)
    vib = vibration_level(imu.omega_ib_b[idx], imu.f_ib_b[idx])
    # the median over the still runs: one run with a door slammed does not decide
    return MeasuredNoise(float(sum(weights) * dt), vib, float(np.median(dens_g)),
                         float(np.median(dens_a)), w_mean, bias_sigma, abs(f_norm - g))


def estimate_time_offset(imu: ImuData, gnss: GnssData, *, search_s: float = OFFSET_RANGE):
    """IMU time offset from the gyro heading against the GNSS course (module docstring).

    Returns ``(offset_s, sigma_s)``: the offset to *add* to the IMU stamps; ``None`` when the
    drive has too little turning, or no course (no velocity and fixes too noisy).
    """
    sig = gnss.sigma_m if gnss.sigma_m is not None else np.full(len(gnss.t), 5.0)
    precise = len(gnss.t) >= 5 and np.nanmedian(sig) <= PRECISE_POSITION_M
    if not precise and gnss.velocity_n is not None and np.all(np.isfinite(gnss.velocity_n[:, :2])):
        # the receiver's velocity (it may lag: the caller shifts it by the lag it knows)
        t = gnss.t
        ve, vn = gnss.velocity_n[:, 0], gnss.velocity_n[:, 1]
    else:
        # the course from positions, central differences: no lag (RTK: the better course)
        if len(gnss.t) < 5 or np.nanmedian(sig) > 1.0:
            return None
        p = enu_offset(gnss.lat[0], gnss.lon[0], 0.0, gnss.lat, gnss.lon, 0.0)
        dtk = gnss.t[2:] - gnss.t[:-2]
        ve = (p[2:, 0] - p[:-2, 0]) / dtk
        vn = (p[2:, 1] - p[:-2, 1]) / dtk
        t = gnss.t[1:-1]
    speed = np.hypot(ve, vn)
    # a velocity is plausible when it is a car's and agrees with both neighbours (an
    # unflagged outlier differenced into a velocity is neither)
    dv = np.hypot(np.diff(ve), np.diff(vn)) / np.maximum(np.diff(t), 1e-3)
    smooth = np.r_[dv, np.inf] < COURSE_MAX_ACCEL
    smooth &= np.r_[np.inf, dv] < COURSE_MAX_ACCEL
    inside = (t > imu.t[0] + search_s + 1.0) & (t < imu.t[-1] - search_s - 1.0)
    m = (speed > COURSE_MIN_SPEED) & (speed < COURSE_MAX_SPEED) & smooth & inside
    if m.sum() < 20:
        return None
    u = imu.f_ib_b.mean(axis=0)
    u = u / np.linalg.norm(u)
    yaw_rate = imu.omega_ib_b @ u
    dts = np.diff(imu.t, prepend=imu.t[0] - imu.dt)
    # heading clockwise: minus the integral of the rate about "up"; rows are interval means
    # ending at t, so the integral at t_k is exact at the sample stamps
    psi = -np.concatenate([[0.0], np.cumsum(yaw_rate[1:] * dts[1:])])
    course = np.arctan2(ve[m], vn[m])
    tm = t[m]
    seg = np.cumsum(np.r_[True, np.diff(np.flatnonzero(m)) > 1]) - 1
    nseg = int(seg.max()) + 1
    count = np.bincount(seg, minlength=nseg)
    # the offset is seen only in turns, and only the gyro says the vehicle turned: a course
    # differenced from noisy fixes "turns" on a straight leg (a simulated drone's 0.7 m fixes
    # at 5 Hz, its turns all made hovering: the search fitted that noise to −0.44 ± 0.03 s,
    # the state was reset to it and the filter lost the drone, 280 m)
    turn = np.abs(np.interp(tm + 0.5, imu.t, psi) - np.interp(tm - 0.5, imu.t, psi))
    if float(np.sum(turn > 5.0 * DEG)) < 8:
        return None

    step = 0.005
    taus = np.arange(-search_s, search_s + 1e-9, step)

    def residuals(tau, keep):
        # course = ψ_gyro(t + τ) + a constant per stretch + one drift rate: the constants and
        # the rate are removed in closed form (stretch means, then a common slope)
        sk, tk = seg[keep], tm[keep]
        y = np.unwrap(course[keep] - np.interp(tk + tau, imu.t, psi))
        ck = np.maximum(np.bincount(sk, minlength=nseg), 1)
        y_c = y - np.bincount(sk, y, nseg)[sk] / ck[sk]
        t_ck = tk - np.bincount(sk, tk, nseg)[sk] / ck[sk]
        b = float(t_ck @ y_c) / max(float(t_ck @ t_ck), 1e-12)
        return np.angle(np.exp(1j * (y_c - b * t_ck)))

    def best(keep, grid):
        f = np.array([np.mean(np.minimum(r * r, COURSE_TRUNCATE**2))
                      for r in (residuals(x, keep) for x in grid)])
        k = int(np.argmin(f))
        if k in (0, len(grid) - 1):
            return None, f, k
        # parabola through the minimum and its neighbours
        a, b, c = f[k - 1], f[k], f[k + 1]
        den = a - 2 * b + c
        return grid[k] + (0.5 * (a - c) / den * step if den > 0 else 0.0), f, k

    everything = np.ones(len(tm), bool)
    tau, f, k = best(everything, taus)
    if tau is None:
        return None
    # σ: the residuals are correlated over seconds (a curvature σ would claim milliseconds
    # that removing a few minutes of data moves by 15 ms on drive_0708): the jackknife over
    # the stretches, grouped into up to 10 blocks of similar length
    order = np.argsort(-count)
    group = np.empty(nseg, int)
    load = np.zeros(min(10, nseg))
    for j in order:
        g = int(np.argmin(load))
        group[j] = g
        load[g] += count[j]
    ng = len(load)
    near = taus[max(k - 12, 0):k + 13]
    jack = [best(group[seg] != g, near)[0] for g in range(ng)] if ng >= 3 else []
    jack = np.array([x for x in jack if x is not None])
    if len(jack) >= 3:
        sigma = math.sqrt((len(jack) - 1) / len(jack) * float(np.sum((jack - jack.mean()) ** 2)))
    else:
        a, b, c = f[k - 1], f[k], f[k + 1]
        kappa = (a - 2 * b + c) / (2 * step * step)
        sigma = math.sqrt(max(b, 1e-12) / (max(kappa, 1e-12) * len(tm))) if kappa > 0 else 0.1
    # the IMU event at t_gnss + τ: the IMU stamps are late by τ, add −τ
    return -float(tau), float(max(sigma, 0.002))


def estimate_velocity_lag(gnss: GnssData, *, search_s: float = 0.5, span_s: float = 1.0):
    """How late the GNSS velocity is against the positions, s (``None``: not measurable).

    Receivers and post-processors often report the velocity of the *last* interval (a
    position difference, or Doppler smoothed back in time) at the end of it. Over ``span_s``
    the displacement between fixes must equal the integral of the velocity; the lag ``τ`` that
    best makes it so (velocity taken at ``t + τ``) is searched on a 5 ms grid. Needs precise
    positions (σ below 0.5 m) and velocities.
    """
    if gnss.velocity_n is None or len(gnss.t) < 20:
        return None
    sig = gnss.sigma_m if gnss.sigma_m is not None else np.full(len(gnss.t), 5.0)
    if not np.nanmedian(sig) < 0.5:
        return None
    dt = float(np.median(np.diff(gnss.t)))
    W = max(1, int(round(span_s / dt)))
    p = enu_offset(gnss.lat[0], gnss.lon[0], 0.0, gnss.lat, gnss.lon, 0.0)[:, :2]
    v = gnss.velocity_n[:, :2]
    ok = np.all(np.isfinite(v), axis=1)
    if ok.sum() < 2 * W + 5:
        return None
    h = np.diff(gnss.t)
    close = np.r_[h <= 2.5 * dt]

    def mismatch(tau):
        vs = np.column_stack([np.interp(gnss.t + tau, gnss.t, v[:, k]) for k in range(2)])
        cs = np.concatenate([[[0.0, 0.0]], np.cumsum(0.5 * (vs[1:] + vs[:-1]) * h[:, None], axis=0)])
        e = (p[W:] - p[:-W]) - (cs[W:] - cs[:-W])
        good = np.convolve(close.astype(float), np.ones(W), "valid") == W
        return float(np.median(np.sum(e[good] ** 2, axis=1))) if good.any() else np.inf

    taus = np.arange(-search_s, search_s + 1e-9, 0.005)
    f = np.array([mismatch(x) for x in taus])
    k = int(np.argmin(f))
    if not np.isfinite(f[k]) or k in (0, len(taus) - 1):
        return None
    # worth it only when it clearly beats no shift
    if f[k] > 0.5 * mismatch(0.0):
        return 0.0
    return float(taus[k])


def shift_velocity(gnss: GnssData, lag_s: float) -> GnssData:
    """A copy of ``gnss`` whose velocity at ``t`` is the one reported at ``t + lag_s``."""
    out = gnss.copy()
    if gnss.velocity_n is None or not lag_s:
        return out
    out.velocity_n = np.column_stack([np.interp(gnss.t + lag_s, gnss.t, gnss.velocity_n[:, k])
                                      for k in range(3)])
    return out


def combine(prior: ImuNoise, measured: MeasuredNoise) -> tuple[ImuNoise, list]:
    """The prior noise where the data is quieter, the measured one where it is noisier.

    Returns the noise and the list of what the data overruled (for one warning line).
    """
    out = dataclasses.replace(prior)
    notes = []
    if measured.arw is not None and measured.arw > NOISIER_THAN_PRIOR * prior.arw:
        notes.append(f"gyro noise {measured.arw / (DEG / 60):.3g} °/√h vs {prior.arw / (DEG / 60):.3g}")
    if measured.vrw is not None and measured.vrw > NOISIER_THAN_PRIOR * prior.vrw:
        notes.append(f"accelerometer noise {measured.vrw * 60:.3g} m/s/√h vs {prior.vrw * 60:.3g}")
    # white noise is what a still segment measures well: it replaces the prior both ways
    # (after WHITE_TRUST_S of still data); the bias terms it cannot measure only go up
    if measured.still_s >= WHITE_TRUST_S:
        out.arw = measured.arw
        out.vrw = measured.vrw
        # an installation noisier than the part (vibration, a loose mount) is not steadier
        # than it either: the in-run bias variation, which a still segment cannot measure,
        # is raised by the same factor as the white noise it can
        kg, ka = measured.arw / prior.arw, measured.vrw / prior.vrw
        if kg > 1.0:
            out.gyro_bias_instability = prior.gyro_bias_instability * kg
        if ka > 1.0:
            out.accel_bias_instability = prior.accel_bias_instability * ka
    else:
        out.arw = max(prior.arw, measured.arw or 0.0)
        out.vrw = max(prior.vrw, measured.vrw or 0.0)
    if measured.gyro_bias is not None:
        b = float(np.max(np.abs(measured.gyro_bias)))
        if b > NOISIER_THAN_PRIOR * max(prior.gyro_bias_sigma, OMEGA_EARTH):
            notes.append(f"gyro bias {b / (DEG / 3600):.3g} °/h vs {prior.gyro_bias_sigma / (DEG / 3600):.3g}")
            out.gyro_bias_sigma = max(prior.gyro_bias_sigma, b)
            out.gyro_bias_instability = max(prior.gyro_bias_instability, 0.01 * b)
    if measured.accel_error is not None and measured.accel_error > NOISIER_THAN_PRIOR * prior.accel_bias_sigma:
        notes.append(f"accelerometer error {measured.accel_error:.3g} m/s² vs {prior.accel_bias_sigma:.3g}")
        out.accel_bias_sigma = measured.accel_error
        out.accel_bias_instability = max(prior.accel_bias_instability, 0.01 * measured.accel_error)
    if notes:
        out.grade = f"{prior.grade}, raised to the measured noise"
    return out, notes


class NoiseAdapter:
    """The process noise the data shows, online (module docstring, item 3).

    Two witnesses, both fed only with *trusted* fixes (fused in normal mode, no fault
    episode open), every step bounded, never below the model (``λ ≥ 1``: quiet minutes must
    not leave the next outage overconfident):

    * the main filter's normalised innovations (:meth:`on_fix`): above their dimension on
      average, the INS is more uncertain than it says;
    * the dead-reckoning references of :mod:`selfnav.ins.hypotheses` (:meth:`on_reference`):
      each trusted fix against each reference is a test of the dead reckoning over its age
      (10 s … 10 min) — exactly the horizon where the process noise, not the fix noise,
      decides. The variance ratio κ (actual / predicted) comes from the share of tests beyond
      the χ²₂ median: for errors κ times the predicted variance,
      ``P(χ² > 1.386) = ½^(1/κ)``, so ``κ̂ = ln ½ / ln p̂`` — robust: the heavy tails of dead
      reckoning in turns do not decide. κ̂ scales the references' tests at once
      (:attr:`reference_ratio`) and pulls ``λ`` towards it for what follows.

    Parameters
    ----------
    cfg : NoiseAdaptation
    p_false_alarm : float
        The reopening test's false-alarm probability (``integrity.p_false_alarm``).
    """

    def __init__(self, cfg, p_false_alarm=1e-4):
        self.cfg = cfg
        wins = tuple(cfg.reopen_windows)
        # each window's test at its share of the false-alarm probability
        self.reopen_gates = {n: chi2_gate(2 * n, p_false_alarm / len(wins)) for n in wins}
        self.window = []         # the last trusted fixes' NIS since the last reopening
        self.reopenings = 0
        self.alpha = 1.0 / cfg.memory
        self.fix_ratio = 1.0     # running mean of NIS/dof of trusted fixes
        self.ref_ratio = 1.0     # running mean of χ²/dof of trusted fixes against references
        self.ref_lambda = 1.0    # running mean of λ over the same memory (what they predicted with)
        self._t_ref = None
        self.ref_samples = 0
        self.updates = 0

    @property
    def reference_ratio(self) -> float:
        """κ̂, the young references' actual/predicted error variance (≥ 1)."""
        return max(self.ref_ratio, 1.0)

    def on_fix(self, flt, nis_value, dof, may_reopen=True):
        """A trusted fix with normalised innovation ``nis_value`` of ``dof`` dimensions: ``λ``
        moves towards what both witnesses ask for — the references' ratio times the ``λ`` they
        were propagated with (a fixed point: once the references are honest, κ̂ = 1 and the
        target is the ``λ`` that made them so), the fix ratio over its trigger — at most
        ``up_step`` per fix, never below 1. Returns True when the fix reopened ``P`` (the
        module docstring, item 4); ``may_reopen`` False: the test is not made and its window
        begins again."""
        c = self.cfg
        reopened = False
        if not may_reopen:
            self.forget()
        else:
            k = self.reopen_factor(nis_value, dof)
            if k is not None:
                flt.P *= k
                reopened = True
        x = min(nis_value / dof, c.clip)
        self.fix_ratio += self.alpha * (x - self.fix_ratio)
        target = max(1.0, self.fix_ratio / c.trigger,
                     self.ref_lambda * self.ref_ratio if self.ref_samples else 1.0)
        k = min(max(target / flt.q_scale, c.decay), c.up_step)
        new = min(max(flt.q_scale * k, 1.0), c.hi)
        if new != flt.q_scale:
            flt.q_scale = new
            self.updates += 1
        return reopened

    def reopen_factor(self, nis_value, dof):
        """The reopening test alone (module docstring, item 4): the fix's ``nis_value`` joins
        the window; when the last ``n`` of them sum beyond their gate, the factor ``P`` is to
        be multiplied by (their mean over their dimension, at most ``reopen_cap``) — the
        window begins again and the reopening is counted — else None. For a filter whose
        noise scale is not this adapter's to move (a heading hypothesis)."""
        if not self.reopen_gates or dof != 2:
            return None
        self.window = (self.window + [float(nis_value)])[-max(self.reopen_gates):]
        for n, gate in self.reopen_gates.items():
            total = sum(self.window[-n:])
            if len(self.window) >= n and total > gate:
                self.forget()
                self.reopenings += 1
                return min(total / (2 * n), self.cfg.reopen_cap)
        return None

    def forget(self):
        """The reopening test's window begins again (its innovations were another
        filter's, or ``P`` was just reopened)."""
        self.window = []

    def on_reference(self, t, chi2_value, age, q_scale=1.0):
        """A trusted fix at time ``t`` against a mature reference of ``age`` s (2 dof) that was
        propagated with noise scale ``q_scale``: the references up to ``reference_age_s`` old
        feed κ̂ with a memory of ``reference_memory_s`` seconds."""
        c = self.cfg
        if age > c.reference_age_s:
            return
        dt = 0.0 if self._t_ref is None else max(t - self._t_ref, 0.0)
        self._t_ref = t
        a = 1.0 - math.exp(-max(dt, 1e-3) / c.reference_memory_s)
        self.ref_ratio += a * (min(chi2_value / 2.0, c.clip) - self.ref_ratio)
        self.ref_lambda += a * (q_scale - self.ref_lambda)
        self.ref_samples += 1


def calibrated_config(cfg: FilterConfig, imu: ImuData, gnss: GnssData | None = None):
    """``cfg`` with its IMU noise raised to what the still data shows; returns
    ``(cfg, measured, notes)``."""
    still = still_mask(imu, gnss)
    measured = measure_noise(imu, still)
    noise, notes = combine(cfg.imu, measured)
    return dataclasses.replace(cfg, imu=noise), measured, notes


def grade_noise(grade: str) -> ImuNoise:
    """The prior noise of a grade (``auto``: the consumer preset, the widest)."""
    key = sensors.grade_key(grade)
    key = "consumer" if key == "auto" else key
    return ImuNoise.from_model(sensors.GRADES[key], key)


__all__ = ["MeasuredNoise", "still_mask", "measure_noise", "estimate_time_offset",
           "estimate_velocity_lag", "shift_velocity", "combine",
           "NoiseAdapter", "calibrated_config", "grade_noise"]
