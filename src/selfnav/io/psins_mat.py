"""Readers of PSINS CSV exports: increments (``mimu.csv``) and navigation output (``fogavp.csv``),
and the vehicle record ``psins_fog_mems_vehicle`` as a whole.

``mimu.csv``: MEMS increments at 100 Hz, ``dθx, dθy, dθz`` [rad], ``dvx, dvy, dvz`` [m/s], ``t``
(end of each interval). ``fogavp.csv``: the fibre-optic INS at 10 Hz, ``pitch, roll, yaw`` [rad],
``vE, vN, vU``, ``lat, lon`` [rad], ``h``, ``t``. PSINS: ENU, body RFU, ``C_b^n =
R_z(yaw) R_x(pitch) R_y(roll)`` with yaw counter-clockwise, so heading = −yaw (the seeds' ψ).
The ``.mat`` file also holds the upstream demo's reference MEMS gyro bias ``eb0`` (rad/s) and
MEMS-to-FOG mounting angles ``mu0`` (rad).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from selfnav import attitude as att
from selfnav.errors import InputError
from selfnav.io.csvio import check_time, read_table
from selfnav.io.imu import check_imu_units
from selfnav.types import AttitudeData, ImuData, Trajectory


def _load(path, ncol):
    try:
        arr = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError) as e:
        raise InputError(path, f"cannot be read as a numeric CSV ({e})") from None
    if arr.shape[1] != ncol:
        raise InputError(path, f"has {arr.shape[1]} columns, expected {ncol}")
    return arr


INCREMENT_COLUMNS = ("dtheta_x_rad", "dtheta_y_rad", "dtheta_z_rad", "dv_x_mps", "dv_y_mps",
                     "dv_z_mps", "t_s")
AVP_COLUMNS = ("pitch_rad", "roll_rad", "yaw_rad", "ve_mps", "vn_mps", "vu_mps", "lat_rad",
               "lon_rad", "h_m", "t_s")


def header_of(path) -> tuple:
    """The lower-case column names of a CSV's first line (empty when unreadable)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            return tuple(x.strip().lower() for x in fh.readline().split(","))
    except OSError:
        return ()


def read_increments_csv(path) -> ImuData:
    """PSINS increments as CSV (``mimu.csv``: dθ [rad], dv [m/s], t at each interval's end)."""
    tab = read_table(path, INCREMENT_COLUMNS)
    t = check_time(tab, "t_s", min_rows=2)
    dt = np.diff(t, prepend=t[0] - float(np.median(np.diff(t))))
    dth = np.column_stack([tab[c] for c in INCREMENT_COLUMNS[:3]])
    dv = np.column_stack([tab[c] for c in INCREMENT_COLUMNS[3:6]])
    imu = ImuData(t, dth / dt[:, None], dv / dt[:, None], source=str(path),
                  meta={"format": "psins-increments"})
    check_imu_units(imu, path)
    return imu


def read_avp_csv(path) -> Trajectory:
    """A PSINS navigation output as CSV (``fogavp.csv``: pitch, roll, yaw [rad, yaw
    counter-clockwise], vE, vN, vU, lat, lon [rad], h, t) as a :class:`Trajectory`."""
    tab = read_table(path, AVP_COLUMNS)
    t = check_time(tab, "t_s", min_rows=1)
    C_nb = att.dcm_nb_from_euler(tab["roll_rad"], tab["pitch_rad"], -tab["yaw_rad"])
    v = np.column_stack([tab["ve_mps"], tab["vn_mps"], tab["vu_mps"]])
    return Trajectory(t, tab["lat_rad"], tab["lon_rad"], tab["h_m"], v, C_nb, source=str(path))


def read_fog_mems(folder) -> dict:
    """Read the record.

    Returns
    -------
    dict
        ``imu`` (:class:`ImuData`, rates = increments / 0.01 s, stamped at interval ends),
        ``dtheta_b`` (N, 3) raw gyro increments (row k covers ``(t[k-1], t[k]]``),
        ``attitude`` (:class:`AttitudeData`, the FOG INS), ``t_ref, lat_ref, lon_ref, v_ref``
        (FOG INS position, rad), and ``eb0``, ``mu0`` (3,) when the .mat file can be read.
    """
    folder = Path(folder)
    m = _load(folder / "mimu.csv", 7)
    a = _load(folder / "fogavp.csv", 10)
    t = m[:, 6]
    dt = np.diff(t, prepend=t[0] - 0.01)
    imu = ImuData(t, m[:, :3] / dt[:, None], m[:, 3:6] / dt[:, None],
                  source=str(folder / "mimu.csv"), meta={"format": "psins-increments"})
    pitch, roll, yaw = a[:, 0], a[:, 1], a[:, 2]
    C_nb = att.dcm_nb_from_euler(roll, pitch, -yaw)
    out = {
        "imu": imu, "dtheta_b": m[:, :3].copy(),
        "attitude": AttitudeData(a[:, 9], C_nb, str(folder / "fogavp.csv")),
        "t_ref": a[:, 9], "lat_ref": a[:, 6], "lon_ref": a[:, 7], "v_ref": a[:, 3:6],
    }
    mat = folder / "transfer_align_fog_mems.mat"
    if mat.exists():
        from scipy.io import loadmat

        d = loadmat(mat, variable_names=["eb0", "mu0"])
        out["eb0"] = np.asarray(d["eb0"], float).ravel()
        out["mu0"] = np.asarray(d["mu0"], float).ravel()
    return out
