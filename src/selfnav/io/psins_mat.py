"""Reader of the PSINS vehicle record ``psins_fog_mems_vehicle`` (CSV exports of the .mat file).

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
from selfnav.types import AttitudeData
from selfnav.types import ImuData


def _load(path, ncol):
    try:
        arr = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError) as e:
        raise InputError(path, f"cannot be read as a numeric CSV ({e})") from None
    if arr.shape[1] != ncol:
        raise InputError(path, f"has {arr.shape[1]} columns, expected {ncol}")
    return arr


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
