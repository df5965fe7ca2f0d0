"""The native IMU CSV reader (DESIGN §6: ``t, wx, wy, wz, fx, fy, fz``) and the unit checks
every IMU reader applies."""
from __future__ import annotations

import numpy as np

from selfnav.earth import OMEGA_EARTH
from selfnav.errors import InputError
from selfnav.io.csvio import check_time, read_table
from selfnav.types import ImuData

IMU_COLUMNS = ("t", "wx", "wy", "wz", "fx", "fy", "fz")


def check_imu_units(imu: ImuData, path=None) -> None:
    """Reject gyro and accelerometer values whose magnitudes betray wrong units.

    Gyros: a rate above 35 rad/s (2000 deg/s, the top of MEMS ranges) for more than 1 % of the
    samples means deg/s or deg/h. Accelerometers: a median |f| near 1 means g units; above
    60 m/s^2 means cm/s^2, mg or counts; below 3 m/s^2 is not a specific force on Earth.
    """
    path = path or imu.source
    w = np.sqrt(np.einsum("ij,ij->i", imu.omega_ib_b, imu.omega_ib_b))
    if np.mean(w > 35.0) > 0.01:
        raise InputError(path, f"gyro rates reach {np.max(w):.4g} (median {np.median(w):.4g}): "
                         "these look like deg/s or deg/h, the file needs rad/s", column="wx")
    fn = np.sqrt(np.einsum("ij,ij->i", imu.f_ib_b, imu.f_ib_b))
    med = float(np.median(fn))
    if 0.7 < med < 1.4:
        raise InputError(path, f"median specific force is {med:.4g}: this looks like g units, the "
                         "file needs m/s^2 (multiply by 9.80665)", column="fx")
    if med > 60.0:
        raise InputError(path, f"median specific force is {med:.4g}: this looks like cm/s^2, mg or "
                         "raw counts, the file needs m/s^2", column="fx")
    if med < 3.0:
        raise InputError(path, f"median specific force is {med:.4g} m/s^2, far from gravity "
                         "(9.8): is it gravity-compensated acceleration, or in other units? "
                         "The file needs specific force in m/s^2", column="fx")


def read_imu_csv(path) -> ImuData:
    """Read the native IMU CSV (DESIGN §6)."""
    tab = read_table(path, IMU_COLUMNS, optional=("mx", "my", "mz", "position"))
    t = check_time(tab, min_rows=2)
    w = np.column_stack([tab["wx"], tab["wy"], tab["wz"]])
    f = np.column_stack([tab["fx"], tab["fy"], tab["fz"]])
    mag = None
    if all(k in tab for k in ("mx", "my", "mz")):
        mag = np.column_stack([tab["mx"], tab["my"], tab["mz"]])
    pos = tab["position"].astype(int) if "position" in tab else None
    imu = ImuData(t, w, f, mag, pos, source=str(path))
    check_imu_units(imu, path)
    return imu


def earth_rate_ratio(imu: ImuData) -> float:
    """|mean ω| / Earth rate: ~1 at rest; ~57 for deg/s, ~2e5 for deg/h."""
    return float(np.linalg.norm(imu.omega_ib_b.mean(axis=0)) / OMEGA_EARTH)
