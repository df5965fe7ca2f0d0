"""Attitude files (DESIGN §6: ``t, roll_deg, pitch_deg, heading_deg``): reading and checking.

Checks (each failure is one :class:`~selfnav.errors.InputError` line naming file, row, column):

* time strictly increasing; no gap longer than ``gap_factor`` × the median step (default 5);
* roll within ±180°, pitch within ±90° (columns swapped or not degrees otherwise);
* heading wrap-around (359° → 1°) is *not* an error: attitude is converted to rotation matrices
  at once and never handled as angles; a genuine jump is caught against the gyros;
* angles in radians where degrees are expected: the attitude then turns ~57× less than the
  gyros say (checked when the vehicle moves; at rest the units cannot be told apart);
* attitude and IMU spans that do not overlap; a partial overlap is trimmed to the common span
  (and reported); different rates are fine (the attitude is never interpolated: the moving-base
  driver composes the gyros onto its times, :mod:`selfnav.moving_driver`).

This module only reads and checks; the moving-base method and its driver are
:mod:`selfnav.moving` and :mod:`selfnav.moving_driver`.
"""
from __future__ import annotations

import numpy as np

from selfnav import attitude as att
from selfnav.errors import InputError
from selfnav.io.csvio import check_time, read_table
from selfnav.types import AttitudeData

ATTITUDE_COLUMNS = ("t", "roll_deg", "pitch_deg", "heading_deg")


def check_gaps(t, path, *, lines=None, factor=5.0, what="attitude"):
    """Raise if a time step exceeds ``factor`` × the median step (a gap no interpolation may bridge)."""
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
