"""Reader of the rtklibexplorer GNSS_IMU car-roof IMU logs (``imu_*.csv`` + ``.csv.tag``).

Format (``shared/data/rtklibexplorer_drive_0708/README.md``): no header; columns ``ax ay az``
[g], ``gx gy gz`` [deg/s], ``t`` [ms since power-up]; upstream skips the first and the last row
(the logger starts and stops mid-line), and so does this reader: a partial first or last line
is dropped with one warning, a bad line in between is one error naming it.
The RTKLIB demo5 time-tag file holds a 60-byte header, ``uint32`` (tick frequency),
``uint32`` whole GPST seconds counted like Unix time, ``float64`` fraction, then
``(uint32 tick ms, uint32 file position)`` pairs. Upstream maps the ms counter linearly onto
``[start, start + last_tick/1000]`` and adds ``imu_t_off = −0.125 s``.

Axes: this reader returns the **sensor's own axes** (SI units). Which way they point on a
vehicle is not the logger's property but the installation's: :func:`selfnav.io.readers.read_imu`
applies ``axes=`` / ``mount=`` (``--imu-axes``, ``--imu-mount``), by default the preset
:data:`DEFAULT_AXES` (``rtklibexplorer-drive0708`` of :data:`selfnav.axes.PRESETS`: x back,
y right, z up; mounting pitch −6.79°, yaw +5.35°, upstream's ``imu_misalign``). Time is
returned as GPS seconds of week.
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from selfnav.errors import InputError, warn
from selfnav.io.csvio import open_text
from selfnav.io.gnss import gps_seconds_of_week
from selfnav.io.imu import check_imu_units
from selfnav.types import ImuData

G0 = 9.80665
IMU_T_OFF = -0.125
#: The axes and mounting :func:`selfnav.io.readers.read_imu` gives this format when the user
#: gives none: the drive_0708 preset, **for now** (tests/test_realdata_drive0708.py reads the
#: drive with the defaults). When the navigator detects the axes itself, the one-line switch is
#: ``DEFAULT_AXES = "detect"`` (then the reader leaves the sensor's axes and says so in
#: ``meta["axes_source"]``).
DEFAULT_AXES = "rtklibexplorer-drive0708"
NCOL = 7


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


def _parse_rows(csv_path: Path, text: str) -> np.ndarray:
    """The numeric rows of a log, the first and last line dropped as upstream does (with one
    warning when either is partial); any other bad line is one :class:`InputError`."""
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if len(lines) < 12:
        raise InputError(csv_path, f"has {len(lines)} lines: not an rtklibexplorer IMU log (7 "
                         "columns ax,ay,az g, gx,gy,gz deg/s, t ms; at least 12 lines)")

    def complete(line):
        parts = line.split(",")
        if len(parts) != NCOL:
            return False
        try:
            [float(p) for p in parts]
        except ValueError:
            return False
        return True

    partial = [(k + 1, what) for k, what in ((0, "first"), (len(lines) - 1, "last"))
               if not complete(lines[k])]
    if partial:
        which = " and ".join(f"{w} line ({n})" for n, w in partial)
        warn(f"{csv_path}: the {which} {'is' if len(partial) == 1 else 'are'} partial (the logger "
             "started or stopped mid-line) and skipped, as upstream skips the first and last "
             "lines")
    body = lines[1:-1]
    try:
        return np.loadtxt(body, delimiter=",", ndmin=2)
    except ValueError:
        pass
    for k, line in enumerate(body):
        parts = line.split(",")
        row = k + 2
        if len(parts) != NCOL:
            cause = ("a partial line (the logger lost bytes?)" if 0 < len(parts) < NCOL
                     else "more fields than the logger writes (is it another format?)")
            raise InputError(csv_path, f"has {len(parts)} fields where an rtklibexplorer IMU log "
                             f"has {NCOL} (ax,ay,az g, gx,gy,gz deg/s, t ms): {cause}", row=row)
        for name, p in zip(("ax", "ay", "az", "gx", "gy", "gz", "t"), parts):
            try:
                float(p)
            except ValueError:
                raise InputError(csv_path, f"value '{p.strip()[:20]}' is not a number (a "
                                 "corrupted line?)", row=row, column=name) from None
    raise InputError(csv_path, "cannot be parsed as a 7-column numeric IMU log")


def read_rtklibexplorer_imu(csv_path, tag_path=None, *, t_offset=IMU_T_OFF) -> ImuData:
    """Read a drive_0708-style IMU log: rates and specific force in the **sensor's axes** (SI),
    time in GPS seconds of week.

    Parameters
    ----------
    csv_path : path of ``imu_*.csv``
    tag_path : path of the ``.tag`` file (default: ``csv_path + '.tag'``)
    t_offset : added to the mapped time, s (upstream ``imu_t_off``)

    Returns
    -------
    ImuData
        ``meta["axes_source"] = "sensor"``: not yet in a vehicle frame (``read_imu`` applies
        the axes and mounting).
    """
    csv_path = Path(csv_path)
    tag_path = Path(tag_path) if tag_path else csv_path.with_name(csv_path.name + ".tag")
    d = _parse_rows(csv_path, open_text(csv_path))
    if np.any(np.diff(d[:, 6]) <= 0):
        k = int(np.argmax(np.diff(d[:, 6]) <= 0)) + 2
        raise InputError(csv_path, "ms counter not increasing (rows out of order, or the "
                         "logger restarted)", row=k + 1, column="t")
    start, pairs = read_tag(tag_path)
    tick = d[:, 6] - d[0, 6]
    span = float(pairs[-1, 0]) / 1000.0
    t_unix = start + tick / tick[-1] * span + t_offset
    t = gps_seconds_of_week(np.floor(t_unix)) + (t_unix - np.floor(t_unix))
    a = d[:, 0:3] * G0
    w = np.radians(d[:, 3:6])
    imu = ImuData(t, w, a, source=str(csv_path), meta={"format": "rtklibexplorer",
                                                       "axes_source": "sensor"})
    check_imu_units(imu, csv_path)
    return imu
