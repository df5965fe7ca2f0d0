"""KF-GINS (i2Nav, Wuhan University) text formats: IMU increments, GNSS positions, ``.nav`` results.

Layouts from the KF-GINS README §2.2 (also used by i2Nav's awesome-gins-datasets); whitespace
separated text, one epoch per line, no header (``#`` lines and commas are tolerated here):

=========  =====================================================================================
IMU        ``sow, dθx, dθy, dθz [rad], dvx, dvy, dvz [m/s]`` — increments over the interval that
           *ends* at ``sow`` (GNSS seconds of week); axes **front-right-down** (FRD). Extra
           columns (e.g. an odometer increment) are ignored, as KF-GINS does (``imudatalen``).
GNSS       ``sow, lat [deg], lon [deg], h [m, ellipsoidal], σN, σE, σD [m]``
``.nav``   ``week, sow, lat [deg], lon [deg], h [m], vN, vE, vD [m/s], roll, pitch, yaw [deg]``
           (navigation frame **north-east-down**, Euler angles yaw-pitch-roll, ZYX order)
=========  =====================================================================================

Conversions (DESIGN §2: ENU navigation frame, RFU body frame, done once at load time):

* body FRD → RFU: ``x_RFU = y_FRD``, ``y_RFU = x_FRD``, ``z_RFU = −z_FRD``, i.e. ``u_RFU = M u_FRD``
  with ``M = [[0,1,0],[1,0,0],[0,0,−1]]`` (a proper rotation, det M = +1, and M = Mᵀ = M⁻¹);
* navigation NED → ENU with the same matrix M;
* attitude: ``C_b^n(ENU, RFU) = M C_b^n(NED, FRD) M``, with ``C_b^n(NED, FRD) = R_z(yaw) R_y(pitch)
  R_x(roll)`` (active rotations, the ZYX convention of the README). The physical angles agree
  with selfnav's (heading clockwise from North = yaw, pitch nose-up, roll right side down), but
  the conversion goes through the matrices so that a convention slip cannot hide.

Time: the IMU and GNSS files carry seconds of week only; a week rollover inside a file shows
as time going backwards and is reported. ``.nav`` rows carry the week: time is counted from
the first row's week (``(week − week₀)·604800 + sow``).
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.io.csvio import open_text, atomic_path
from selfnav.types import GnssData
from selfnav.types import ImuData
from selfnav.types import Trajectory

WEEK = 604800.0
#: FRD ↔ RFU and NED ↔ ENU axis permutation (symmetric, its own inverse, det +1)
M_SWAP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


# ---------------------------------------------------------------------------------- frames
def frd_to_rfu(v):
    """Body vectors FRD → RFU (also NED → ENU): ``(a, b, c) → (b, a, −c)``; works on (..., 3)."""
    v = np.asarray(v, dtype=float)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


rfu_to_frd = frd_to_rfu  # the permutation is its own inverse
ned_to_enu = frd_to_rfu
enu_to_ned = frd_to_rfu


def dcm_bn_ned_frd(roll, pitch, yaw):
    """``C_b^n`` (FRD body → NED) from KF-GINS Euler angles (rad): ``R_z(yaw) R_y(pitch) R_x(roll)``."""
    r, p, y = (np.asarray(a, dtype=float) for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack([
        np.stack([cp * cy, -cr * sy + sr * sp * cy, sr * sy + cr * sp * cy], -1),
        np.stack([cp * sy, cr * cy + sr * sp * sy, -sr * cy + cr * sp * sy], -1),
        np.stack([-sp, sr * cp, cr * cp], -1)], -2)


def euler_ned_frd(C_bn):
    """Roll, pitch, yaw (rad, yaw in (−π, π]) from a ``C_b^n`` (FRD → NED)."""
    C = np.asarray(C_bn, dtype=float)
    pitch = np.arcsin(np.clip(-C[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(C[..., 2, 1], C[..., 2, 2])
    yaw = np.arctan2(C[..., 1, 0], C[..., 0, 0])
    return roll, pitch, yaw


def c_nb_enu_rfu(roll, pitch, yaw):
    """selfnav ``C_n^b`` (ENU → RFU) from KF-GINS roll, pitch, yaw (rad): ``(M C_b^n M)ᵀ``."""
    C_bn = M_SWAP @ dcm_bn_ned_frd(roll, pitch, yaw) @ M_SWAP
    return np.swapaxes(C_bn, -1, -2)


def kfgins_euler(C_nb):
    """KF-GINS roll, pitch, yaw (rad) of a selfnav ``C_n^b`` (ENU → RFU)."""
    C_bn_ned = M_SWAP @ np.swapaxes(np.asarray(C_nb, dtype=float), -1, -2) @ M_SWAP
    return euler_ned_frd(C_bn_ned)


# ---------------------------------------------------------------------------------- parsing
def _numeric(path, min_cols: int, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Whitespace/comma separated numbers → (rows, ≥min_cols) array and 1-based line numbers."""
    path = Path(path)
    text = open_text(path)
    lines = text.splitlines()
    keep = [i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not keep:
        raise InputError(path, f"has no data rows (expected a KF-GINS {what} file)")
    body = "\n".join(lines[i].replace(",", " ") for i in keep)
    try:
        arr = np.loadtxt(io.StringIO(body), ndmin=2)
    except ValueError:
        arr = None
    if arr is None or arr.shape[1] < min_cols:
        for i in keep:  # find the first bad row to name it
            parts = lines[i].replace(",", " ").split()
            if len(parts) < min_cols:
                raise InputError(path, f"{len(parts)} fields, a KF-GINS {what} row has at least "
                                 f"{min_cols}", row=i + 1)
            try:
                [float(x) for x in parts]
            except ValueError:
                raise InputError(path, f"non-numeric field in a KF-GINS {what} row (a header "
                                 "line? comment it with '#')", row=i + 1) from None
        raise InputError(path, f"rows of different lengths (expected a KF-GINS {what} file)")
    if not np.all(np.isfinite(arr[:, :min_cols])):
        k = int(np.argmax(~np.all(np.isfinite(arr[:, :min_cols]), axis=1)))
        raise InputError(path, "NaN or infinite value", row=keep[k] + 1)
    return arr, np.asarray(keep) + 1


def _check_time(path, t, line_no, column="sow"):
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0)) + 1
        why = "repeated" if d[k - 1] == 0 else (
            "going backwards (a GPS week rollover? unsorted rows?)")
        raise InputError(path, f"time {float(t[k]):.10g} is {why}: samples must be strictly increasing",
                         row=int(line_no[k]), column=column)


def _check_latlon(path, lat_deg, lon_deg, line_no):
    for name, v, lim in (("lat", lat_deg, 90.0), ("lon", lon_deg, 360.0)):
        bad = np.abs(v) > lim
        if bad.any():
            k = int(np.argmax(bad))
            raise InputError(path, f"{v[k]} is not a {name}itude in degrees (radians? swapped or "
                             "shifted columns?)", row=int(line_no[k]), column=name)


# ---------------------------------------------------------------------------------- readers
def _interval(t, dt_first=None):
    """Interval lengths of samples stamped at interval ends; the first one is the median step."""
    med = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    return np.diff(t, prepend=t[0] - (med if dt_first is None else dt_first))


def read_kfgins_imu(path) -> ImuData:
    """Read a KF-GINS IMU file (increments, FRD) into :class:`ImuData` (rates, RFU).

    Rates are the increments divided by the interval (mean rate over ``(t[k−1], t[k]]``); the
    first interval is taken equal to the median step. ``meta`` keeps ``format`` and ``dt0``.
    """
    path = Path(path)
    a, ln = _numeric(path, 7, "IMU")
    t = a[:, 0]
    if len(t) < 2:
        raise InputError(path, "needs at least 2 IMU rows")
    _check_time(path, t, ln)
    dt = _interval(t)
    dth, dv = a[:, 1:4], a[:, 4:7]
    med = float(np.median(np.linalg.norm(dv, axis=1)))
    if med > 1.0:
        raise InputError(path, f"median |Δv| {med:.3g} m/s per sample: columns 5–7 look like "
                         "specific force in m/s² (rates), not velocity increments", column="dvx")
    if float(np.median(np.linalg.norm(dth, axis=1))) > 0.5:
        raise InputError(path, "gyro increments above 0.5 rad per sample: deg/s rates or "
                         "degrees, not radian increments?", column="dthx")
    return ImuData(t, frd_to_rfu(dth) / dt[:, None], frd_to_rfu(dv) / dt[:, None],
                   source=str(path),
                   meta={"format": "kf-gins-increments", "dt0": float(dt[0]),
                         "time": "GNSS seconds of week", "extra_columns": int(a.shape[1] - 7)})


def read_kfgins_gnss(path, *, return_std: bool = False):
    """Read a KF-GINS GNSS position file into :class:`GnssData` (WGS-84, rad).

    ``sigma_m`` (σ per horizontal axis) is ``max(σN, σE)``, as for RTKLIB files. With
    ``return_std=True`` also returns the (N, 3) σ array in ENU order (σE, σN, σU = σD).
    """
    path = Path(path)
    a, ln = _numeric(path, 7, "GNSS")
    t = a[:, 0]
    _check_time(path, t, ln)
    _check_latlon(path, a[:, 1], a[:, 2], ln)
    std = a[:, 4:7]
    if np.any(std <= 0):
        k = int(np.argmax(np.any(std <= 0, axis=1)))
        raise InputError(path, "position σ must be positive (columns 5–7: σN, σE, σD in m)",
                         row=int(ln[k]))
    g = GnssData(t, np.radians(a[:, 1]), np.radians(a[:, 2]), a[:, 3].copy(),
                 np.maximum(std[:, 0], std[:, 1]), None, None, str(path))
    if return_std:
        return g, np.column_stack([std[:, 1], std[:, 0], std[:, 2]])
    return g


def read_kfgins_nav(path) -> Trajectory:
    """Read a KF-GINS ``.nav`` file (result or ground truth) into a :class:`Trajectory` (ENU, RFU).

    Time: ``(week − week₀)·604800 + sow`` (plain seconds of week when the week is constant or
    set to 0, as in i2Nav's reference files).
    """
    path = Path(path)
    a, ln = _numeric(path, 11, ".nav")
    week = a[:, 0]
    t = (week - week[0]) * WEEK + a[:, 1]
    _check_time(path, t, ln, column="sow")
    _check_latlon(path, a[:, 2], a[:, 3], ln)
    ang = np.radians(a[:, 8:11])
    if np.any(np.abs(a[:, 9]) > 90.0):
        k = int(np.argmax(np.abs(a[:, 9]) > 90.0))
        raise InputError(path, "pitch beyond ±90°: attitude columns shifted or not degrees?",
                         row=int(ln[k]), column="pitch")
    C_nb = c_nb_enu_rfu(ang[:, 0], ang[:, 1], ang[:, 2])
    return Trajectory(t, np.radians(a[:, 2]), np.radians(a[:, 3]), a[:, 4].copy(),
                      ned_to_enu(a[:, 5:8]), C_nb, source=str(path))


# ---------------------------------------------------------------------------------- writers
def _write_rows(path, arr, fmts):
    with atomic_path(path) as tmp, open(tmp, "w", newline="\n") as fh:
        np.savetxt(fh, arr, fmt=fmts, delimiter=" ")
    return Path(path)


def write_kfgins_imu(path, imu: ImuData, *, dt0: float | None = None):
    """Write :class:`ImuData` as a KF-GINS IMU file (increments, FRD), atomically.

    Increments are rate × interval with the intervals of :func:`read_kfgins_imu` (the first one
    ``dt0``, default ``imu.meta['dt0']`` or the median step), so a round trip is exact to
    float precision. ``imu.t`` is written as is: give it in GNSS seconds of week.
    """
    dt0 = dt0 if dt0 is not None else imu.meta.get("dt0")
    dt = _interval(imu.t, dt0)
    arr = np.column_stack([imu.t, rfu_to_frd(imu.omega_ib_b) * dt[:, None],
                           rfu_to_frd(imu.f_ib_b) * dt[:, None]])
    return _write_rows(path, arr, ["%.9f"] + ["%.17g"] * 6)


def write_kfgins_gnss(path, gnss: GnssData, std_enu=None):
    """Write :class:`GnssData` as a KF-GINS GNSS file, atomically.

    ``std_enu`` (N, 3) σE, σN, σU; default σN = σE = ``sigma_m`` (5 m where NaN), σD = 1.5 σ.
    """
    n = len(gnss.t)
    if std_enu is None:
        s = np.asarray(gnss.sigma_m if gnss.sigma_m is not None else np.full(n, np.nan), float)
        s = np.where(np.isfinite(s), s, 5.0)
        std_enu = np.column_stack([s, s, 1.5 * s])
    std_enu = np.asarray(std_enu, float)
    arr = np.column_stack([gnss.t, np.degrees(gnss.lat), np.degrees(gnss.lon), gnss.h,
                           std_enu[:, 1], std_enu[:, 0], std_enu[:, 2]])
    return _write_rows(path, arr, ["%.9f", "%.12f", "%.12f", "%.6f", "%.6f", "%.6f", "%.6f"])


def write_kfgins_nav(path, traj: Trajectory, *, week: int = 0):
    """Write a :class:`Trajectory` as a KF-GINS ``.nav`` file (NED velocity, ZYX Euler), atomically.

    ``traj.t`` must be seconds of week (one week); ``week`` fills column 1.
    """
    r, p, y = kfgins_euler(traj.C_nb)
    arr = np.column_stack([np.full(len(traj.t), float(week)), traj.t, np.degrees(traj.lat),
                           np.degrees(traj.lon), traj.h, enu_to_ned(traj.velocity_n),
                           np.degrees(r), np.degrees(p), np.degrees(y)])
    return _write_rows(path, arr, ["%d", "%.9f", "%.12f", "%.12f", "%.6f"] + ["%.9f"] * 3
                       + ["%.12f"] * 3)
