"""IMU data container and the IMU readers (DESIGN §6: ``t, wx, wy, wz, fx, fy, fz``)."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from selfnav.earth import OMEGA_EARTH
from selfnav.errors import InputError
from selfnav.io.csvio import check_time, read_table

IMU_COLUMNS = ("t", "wx", "wy", "wz", "fx", "fy", "fz")


@dataclass
class ImuData:
    """IMU samples in the body RFU frame, SI units.

    Attributes
    ----------
    t : (N,) float64
        Time, s, strictly increasing. For increment formats, the end of each interval.
    omega_ib_b : (N, 3)
        Angular rate (mean over the sample interval for increment formats), rad/s.
    f_ib_b : (N, 3)
        Specific force, m/s^2.
    mag_b : (N, 3) or None
        Magnetometer, any unit.
    position : (N,) int or None
        Position index for multi-position records.
    source : str
        Where the data came from (file name, "simulated ...").
    meta : dict
        Format-specific header values (e.g. PSINS site and nominal g).
    """

    t: np.ndarray
    omega_ib_b: np.ndarray
    f_ib_b: np.ndarray
    mag_b: np.ndarray | None = None
    position: np.ndarray | None = None
    source: str = ""
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)

    @cached_property
    def dt(self) -> float:
        """Median sample interval, s (computed once)."""
        return float(np.median(np.diff(self.t))) if len(self.t) > 1 else float("nan")

    @property
    def duration(self) -> float:
        """Covered time span, s (N samples of interval dt)."""
        return float(self.t[-1] - self.t[0] + self.dt) if len(self.t) > 1 else 0.0

    def select(self, mask) -> "ImuData":
        """A subset of the samples."""
        return ImuData(
            self.t[mask], self.omega_ib_b[mask], self.f_ib_b[mask],
            None if self.mag_b is None else self.mag_b[mask],
            None if self.position is None else self.position[mask],
            self.source, dict(self.meta),
        )


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


def read_imu(path, fmt: str = "auto") -> ImuData:
    """Read an IMU file.

    Parameters
    ----------
    path : str or Path
    fmt : {"auto", "csv", "psins"}
        ``auto`` picks PSINS for ``.imu`` / ``.imu.gz`` names, CSV otherwise.
    """
    p = Path(path)
    if fmt == "auto":
        name = p.name.lower()
        fmt = "psins" if name.endswith(".imu") or name.endswith(".imu.gz") else "csv"
    if fmt == "csv":
        return read_imu_csv(p)
    if fmt == "psins":
        from selfnav.io.psins import read_psins_imu

        return read_psins_imu(p)
    raise InputError(p, f"unknown IMU format '{fmt}' (use csv or psins)")


def read_imu_positions(paths, fmt: str = "auto") -> ImuData:
    """Read a multi-position record: several files (one per position) or one with ``position``."""
    paths = list(paths)
    if len(paths) == 1:
        return read_imu(paths[0], fmt)
    parts = [read_imu(p, fmt) for p in paths]
    t = np.concatenate([p.t for p in parts])
    pos = np.concatenate([np.full(len(p), k) for k, p in enumerate(parts)])
    return ImuData(
        t, np.concatenate([p.omega_ib_b for p in parts]), np.concatenate([p.f_ib_b for p in parts]),
        None, pos, source=" + ".join(str(p) for p in paths),
    )


def earth_rate_ratio(imu: ImuData) -> float:
    """|mean ω| / Earth rate: ~1 at rest; ~57 for deg/s, ~2e5 for deg/h."""
    return float(np.linalg.norm(imu.omega_ib_b.mean(axis=0)) / OMEGA_EARTH)
