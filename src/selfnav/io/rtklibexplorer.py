"""Reader of the rtklibexplorer GNSS_IMU car-roof IMU logs (``imu_*.csv`` + ``.csv.tag``).

Format (``shared/data/rtklibexplorer_drive_0708/README.md``): no header; columns ``ax ay az``
[g], ``gx gy gz`` [deg/s], ``t`` [ms since power-up]; upstream skips the first and the last row.
The RTKLIB demo5 time-tag file holds a 60-byte header, ``uint32`` (tick frequency),
``uint32`` whole GPST seconds counted like Unix time, ``float64`` fraction, then
``(uint32 tick ms, uint32 file position)`` pairs. Upstream maps the ms counter linearly onto
``[start, start + last_tick/1000]`` and adds ``imu_t_off = −0.125 s``.

Axes: the IMU is x backward, y right, z up. selfnav's body is RFU: ``x_R = y, y_F = −x,
z_U = z``, then the mounting rotation (about −6.8° about x and −5.4° about z, upstream's
``imu_misalign``) levels the sensor on the car. Time is returned as GPS seconds of week.
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from selfnav import attitude as att
from selfnav.errors import InputError
from selfnav.io.gnss import gps_seconds_of_week
from selfnav.io.imu import check_imu_units
from selfnav.types import ImuData

G0 = 9.80665
#: Upstream drive_config.py mounting angles of the drive_0708 roof mount, applied in RFU.
MOUNT_X_DEG = -6.79
MOUNT_Z_DEG = -5.35
IMU_T_OFF = -0.125


def read_tag(path):
    """Start time (Unix-like GPST seconds) and the (tick ms, file position) pairs."""
    path = Path(path)
    try:
        b = path.read_bytes()
    except OSError as e:
        raise InputError(path, f"cannot be read ({e.strerror})") from None
    if len(b) < 76 or not b.startswith(b"TIMETAG"):
        raise InputError(path, "not an RTKLIB time-tag file (no TIMETAG header)")
    sec, = struct.unpack("<I", b[64:68])
    frac, = struct.unpack("<d", b[68:76])
    pairs = np.frombuffer(b[76:76 + (len(b) - 76) // 8 * 8], dtype="<u4").reshape(-1, 2)
    return sec + frac, pairs


def read_rtklibexplorer_imu(csv_path, tag_path=None, *, mount=True, t_offset=IMU_T_OFF) -> ImuData:
    """Read a drive_0708-style IMU log into RFU rates and specific force (GPS seconds of week).

    Parameters
    ----------
    csv_path : path of ``imu_*.csv``
    tag_path : path of the ``.tag`` file (default: ``csv_path + '.tag'``)
    mount : apply the mounting rotation that levels the unit on the car
    t_offset : added to the mapped time, s (upstream ``imu_t_off``)
    """
    csv_path = Path(csv_path)
    tag_path = Path(tag_path) if tag_path else csv_path.with_name(csv_path.name + ".tag")
    try:
        d = np.loadtxt(csv_path, delimiter=",", ndmin=2)
    except OSError as e:
        raise InputError(csv_path, f"cannot be read ({e})") from None
    except ValueError as e:
        raise InputError(csv_path, f"not a 7-column numeric IMU log ({str(e)[:80]})") from None
    if d.shape[1] != 7 or len(d) < 10:
        raise InputError(csv_path, f"expected 7 columns (ax ay az g, gx gy gz deg/s, t ms), got {d.shape[1]}")
    d = d[1:-1]  # as upstream
    if np.any(np.diff(d[:, 6]) <= 0):
        k = int(np.argmax(np.diff(d[:, 6]) <= 0)) + 2
        raise InputError(csv_path, "ms counter not increasing", row=k + 1)
    start, pairs = read_tag(tag_path)
    tick = d[:, 6] - d[0, 6]
    span = float(pairs[-1, 0]) / 1000.0
    t_unix = start + tick / tick[-1] * span + t_offset
    t = gps_seconds_of_week(np.floor(t_unix)) + (t_unix - np.floor(t_unix))
    a = d[:, 0:3] * G0
    w = np.radians(d[:, 3:6])
    # sensor (x back, y right, z up) -> RFU
    P = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    f_b = a @ P.T
    w_b = w @ P.T
    if mount:
        R = att.rotvec_to_dcm(np.array([0, 0, np.radians(MOUNT_Z_DEG)])) @ att.rotvec_to_dcm(
            np.array([np.radians(MOUNT_X_DEG), 0, 0]))
        f_b = f_b @ R.T
        w_b = w_b @ R.T
    imu = ImuData(t, w_b, f_b, source=str(csv_path), meta={"format": "rtklibexplorer",
                                                          "mount_deg": (MOUNT_X_DEG, MOUNT_Z_DEG)})
    check_imu_units(imu, csv_path)
    return imu
