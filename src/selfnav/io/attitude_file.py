"""Attitude files (DESIGN §6: ``t, roll_deg, pitch_deg, heading_deg``) and their use on IMU times.

Checks (each failure is one :class:`~selfnav.errors.InputError` line naming file, row, column):

* time strictly increasing; no gap longer than ``gap_factor`` × the median step (default 5);
* roll within ±180°, pitch within ±90° (columns swapped or not degrees otherwise);
* heading wrap-around (359° → 1°) is *not* an error: attitude is converted to rotation matrices
  and interpolated by slerp, never as angles; a genuine jump is caught against the gyros;
* angles in radians where degrees are expected: the attitude then turns ~57× less than the
  gyros say (checked when the vehicle moves; at rest the units cannot be told apart);
* attitude and IMU spans that do not overlap; a partial overlap is trimmed to the common span
  (and reported); different rates are fine: an attitude at least as fast as the IMU is slerped
  onto the IMU times; a slower one is not interpolated, the gyros are composed onto its times
  (:func:`gyro_rotations_on_grid`).

Attitude sources: a file (above) or :func:`internal_attitude` (strapdown from the same gyros,
circular). :func:`navigate_imu_attitude` runs the moving-base method on an IMU and an attitude.
"""
from __future__ import annotations


import numba
import numpy as np

from selfnav import attitude as att
from selfnav.earth import OMEGA_EARTH
from selfnav.errors import InputError
from selfnav.io.csvio import check_time, read_table
from selfnav.types import AttitudeData
from selfnav.moving import (MovingBaseNavigator, _cumulative_rotation, _rodrigues,
                            coning_increments, gyro_increments)

ATTITUDE_COLUMNS = ("t", "roll_deg", "pitch_deg", "heading_deg")




def check_gaps(t, path, *, lines=None, factor=5.0, what="attitude"):
    """Raise if a time step exceeds ``factor`` × the median step (a gap slerp must not bridge)."""
    d = np.diff(np.asarray(t, float))
    if len(d) == 0:
        return
    med = float(np.median(d))
    bad = d > factor * med
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(path, f"{what} gap of {d[k]:.4g} s after t = {t[k]:.6g} s (median step "
                         f"{med:.4g} s): split the record or fill the gap",
                         row=None if lines is None else int(lines[k + 1]), column="t")


def read_attitude(path, *, gap_factor=5.0) -> AttitudeData:
    """Read an attitude CSV and build ``C_n^b`` with :func:`selfnav.attitude.dcm_nb_from_euler`."""
    tab = read_table(path, ATTITUDE_COLUMNS)
    t = check_time(tab, min_rows=2)
    lines = tab["_lines"]
    for col, lim in (("roll_deg", 180.0), ("pitch_deg", 90.0)):
        v = tab[col]
        bad = np.abs(v) > lim + 1e-9
        if bad.any():
            k = int(np.argmax(bad))
            raise InputError(path, f"{col} = {v[k]:.6g} is outside ±{lim:g}°: columns swapped "
                             "or not degrees?", row=int(lines[k]), column=col)
    h = tab["heading_deg"]
    bad = np.abs(h) > 720.0
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(path, f"heading_deg = {h[k]:.6g} is not an angle in degrees",
                         row=int(lines[k]), column="heading_deg")
    check_gaps(t, path, lines=lines, factor=gap_factor)
    C = att.dcm_nb_from_euler(np.radians(tab["roll_deg"]), np.radians(tab["pitch_deg"]),
                              np.radians(h))
    return AttitudeData(t, C, str(path), lines)


def overlap(att_t, imu_t, path, imu_path="IMU"):
    """Mask of IMU samples inside the attitude span; raise if the spans do not overlap."""
    a0, a1 = float(att_t[0]), float(att_t[-1])
    i0, i1 = float(imu_t[0]), float(imu_t[-1])
    if a1 <= i0 or i1 <= a0:
        raise InputError(path, f"attitude spans t = {a0:.6g}..{a1:.6g} s but the IMU {imu_path} "
                         f"spans {i0:.6g}..{i1:.6g} s: no overlap (different time bases?)",
                         column="t")
    mask = (imu_t >= a0) & (imu_t <= a1)
    if mask.sum() < 3:
        raise InputError(path, f"attitude and IMU overlap in only {int(mask.sum())} IMU samples",
                         column="t")
    return mask


def check_against_gyros(att_data: AttitudeData, imu_t, rotvec_b, path, *, min_rate=0.01,
                        jump_deg=5.0, imu_path=None):
    """Compare the attitude's turn per attitude step with the gyros' (units, jumps).

    ``rotvec_b`` (M-1, 3) are gyro rotation vectors over ``[imu_t[k], imu_t[k+1]]``. When the
    gyros turn ~57× more than the attitude, the file to blame is the one whose values fit the
    other unit: attitude angles that reach beyond radian magnitudes are degrees, so then the
    gyros (``imu_path``) are in deg/s.
    """
    t = att_data.t
    inside = (t >= imu_t[0]) & (t <= imu_t[-1])
    idx = np.flatnonzero(inside)
    if len(idx) < 2:
        return
    cum = np.vstack([np.zeros(3), np.cumsum(rotvec_b, axis=0)])
    g = np.column_stack([np.interp(t[idx], imu_t, cum[:, j]) for j in range(3)])
    dg = np.linalg.norm(np.diff(g, axis=0), axis=1)        # gyro turn (vector sum) per step
    C = att_data.C_nb[idx]
    da = np.linalg.norm(att.dcm_to_rotvec(C[:-1] @ np.swapaxes(C[1:], -1, -2)), axis=1)
    step = np.diff(t[idx])
    jump = da - dg > np.radians(jump_deg)
    if jump.any():
        k = int(np.argmax(jump))
        row = None if att_data.lines is None else int(att_data.lines[idx[k + 1]])
        raise InputError(path, f"attitude turns {np.degrees(da[k]):.1f}° in one step at "
                         f"t = {t[idx[k + 1]]:.6g} s while the gyros turn {np.degrees(dg[k]):.2f}°: "
                         "a heading wrap-around written as a jump, or a glitch", row=row)
    moving = dg / step > min_rate
    if moving.sum() >= 5:
        ratio = float(np.median(da[moving] / dg[moving]))
        if ratio < 0.1:
            if _angles_beyond_radians(C) and imu_path is not None:
                raise InputError(imu_path, f"the gyros turn {1 / max(ratio, 1e-12):.0f}× more than "
                                 "the attitude: gyro rates in deg/s where rad/s are expected?",
                                 column="wx")
            raise InputError(path, f"the attitude turns {1 / max(ratio, 1e-12):.0f}× less than the "
                             "gyros: angles in radians where degrees are expected (or gyro "
                             "rates in deg/s)?", column="roll_deg")
        if ratio > 10.0:
            raise InputError(path, f"the attitude turns {ratio:.0f}× more than the gyros: gyro "
                             "rates too small (units?), or attitude of another vehicle?",
                             column="roll_deg")


def _angles_beyond_radians(C_nb) -> bool:
    """True when some roll, pitch or heading (read as degrees) exceeds what radians can be
    (|roll|, |pitch| > 3.2, heading outside 0-6.3 and 353.7-360)."""
    roll, pitch, hdg = (np.degrees(a) for a in att.euler_from_dcm_nb(C_nb))
    hdg = np.mod(hdg, 360.0)
    return bool(np.any(np.abs(roll) > 3.2) or np.any(np.abs(pitch) > 3.2)
                or np.any((hdg > 6.3) & (hdg < 353.7)))


def attitude_on_imu_times(att_data: AttitudeData, imu_t):
    """Slerp the attitude onto the IMU times (which must lie inside the attitude span)."""
    return att.slerp_dcm(att_data.t, att_data.C_nb, np.asarray(imu_t, float))


def gyro_rotations_on_grid(t_imu, rotvec_b, t_grid):
    """Body rotation vectors over ``[t_grid[j], t_grid[j+1]]`` composed from IMU rotation vectors.

    For an attitude slower than the IMU: instead of interpolating the attitude (slerp makes its
    rate piecewise constant, an attitude-rate error ``~ α h / 2`` at each knot that the observer
    sees as ``K δ``), the gyro increments are composed exactly onto the attitude times. The body
    orientation is the cumulative product ``Q_k = Π exp([Δθ_i])``; a grid time inside an IMU
    interval adds the partial rotation from a cubic interpolation of the summed increments.
    """
    from scipy.interpolate import CubicSpline

    t_imu = np.asarray(t_imu, float)
    rv = np.ascontiguousarray(rotvec_b, float)
    Q = _cumulative_rotation(rv)                              # (M, 3, 3), Q[0] = I
    k = np.clip(np.searchsorted(t_imu, t_grid, side="right") - 1, 0, len(t_imu) - 1)
    S = np.vstack([np.zeros(3), np.cumsum(rv, axis=0)])
    frac = np.asarray(t_grid, float) - t_imu[k]
    part = np.zeros((len(t_grid), 3))
    need = frac > 1e-9 * np.median(np.diff(t_imu))
    if need.any():
        part[need] = CubicSpline(t_imu, S, axis=0)(t_grid[need]) - S[k[need]]
    R = Q[k] @ att.rotvec_to_dcm(part)
    return att.dcm_to_rotvec(np.swapaxes(R[:-1], -1, -2) @ R[1:])


# ----------------------------------------------------------------------------- attitude sources
@numba.njit(cache=True)
def _strapdown_attitude(C_bn0, dtheta, zeta):  # pragma: no cover - compiled
    n = dtheta.shape[0]
    out = np.empty((n + 1, 3, 3))
    C = C_bn0.copy()
    out[0] = C
    for k in range(n):
        C = _rodrigues(-zeta[k]) @ C @ _rodrigues(dtheta[k])
        out[k + 1] = C
    return out


def internal_attitude(t, dtheta_b, C_nb0, lat_assumed, velocity_n=None, h=0.0):
    """Attitude ``C_n^b`` (N, 3, 3) by strapdown integration of the same gyros (no external source).

    ``C_b^n(k+1) = exp(−[ζ_k]) C_b^n(k) exp([Δθ_k])`` with ``ζ_k = ω_in^n(φ_assumed, v) Δt``.
    **Circular**: the nav-frame rate this attitude embodies is the one computed from the assumed
    latitude, so form (b) on it returns ``φ_assumed`` exactly, whatever the true latitude (a test
    measures the slope dφ_out/dφ_assumed = 1). It is useful only to check the tool chain, or
    with a latitude from elsewhere to propagate the longitude.
    """
    from selfnav.simulate.ship import transport_rate_n

    t = np.asarray(t, float)
    n = len(t)
    lat = np.full(n, float(lat_assumed))
    w = OMEGA_EARTH * np.stack([np.zeros(n), np.cos(lat), np.sin(lat)], -1)
    if velocity_n is not None:
        w = w + transport_rate_n(lat, np.asarray(velocity_n, float), h)
    zeta = 0.5 * (w[1:] + w[:-1]) * np.diff(t)[:, None]
    C_bn = _strapdown_attitude(np.ascontiguousarray(np.asarray(C_nb0, float).T),
                               np.ascontiguousarray(dtheta_b, float), np.ascontiguousarray(zeta))
    return np.swapaxes(C_bn, -1, -2)


def navigate_imu_attitude(imu, attitude, lat0, lon0, **kw):
    """Run :class:`MovingBaseNavigator` on an :class:`~selfnav.io.ImuData` and an
    :class:`~selfnav.io.attitude_file.AttitudeData` with the checks of the attitude reader
    (overlap, gaps, units against the gyros); the attitude is slerped onto the IMU times.

    Increment formats (PSINS) are used as increments; CSV rates as rate samples. Returns a
    :class:`MovingSolution` (trimming notes in its ``warnings``).
    """
    check_gaps(imu.t, imu.source or "IMU", what="IMU")
    mask = overlap(attitude.t, imu.t, attitude.source or "attitude", imu.source or "")
    t = imu.t[mask]
    notes = []
    if mask.sum() < len(imu.t):
        notes.append(f"IMU trimmed to the attitude span: {int(mask.sum())} of {len(imu.t)} samples")
    increments = str(imu.meta.get("format", "")).startswith("psins")
    if increments:
        rv = coning_increments(imu.omega_ib_b[mask][1:] * np.diff(t)[:, None])
    else:
        rv = gyro_increments(t, imu.omega_ib_b[mask])
    check_against_gyros(attitude, t, rv, attitude.source or "attitude", imu_path=imu.source)
    nav = MovingBaseNavigator(lat0, lon0, **kw)
    step_att = float(np.median(np.diff(attitude.t)))
    if step_att > 1.5 * float(np.median(np.diff(t))) and nav.method != "euler":
        # attitude slower than the IMU: compose the gyros onto the attitude times (no slerp)
        ta = attitude.t[(attitude.t >= t[0]) & (attitude.t <= t[-1])]
        ka = np.searchsorted(attitude.t, ta)
        rv_a = gyro_rotations_on_grid(t, rv, ta)
        sol = nav.run(ta, attitude.C_nb[ka], rotvec_b=rv_a)
        sol.warnings.extend(notes + [f"attitude ({1 / step_att:.3g} Hz) slower than the IMU: "
                                     "solution on the attitude times"])
        return sol
    C_nb = attitude_on_imu_times(attitude, t)
    if increments:
        sol = nav.run(t, C_nb, dtheta_b=imu.omega_ib_b[mask][1:] * np.diff(t)[:, None])
    else:
        sol = nav.run(t, C_nb, omega_ib_b=imu.omega_ib_b[mask])
    sol.warnings.extend(notes)
    return sol
