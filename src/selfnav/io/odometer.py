"""Odometer (wheel speed) files: ``t, speed_mps`` (``selfnav navigate --odometer``).

A separate CSV with the columns ``t, speed_mps`` (s on the IMU's clock, forward speed in m/s),
or the ``speed_mps`` column of the IMU CSV itself. Speeds are the vehicle's forward speed at the
time stamp (a speed counted over an interval belongs to its middle).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.io.csvio import check_time, open_text, read_table
from selfnav.types import OdometerData

#: a car's wheel speed above this (m/s) is another unit (km/h, mm/s, counts)
MAX_SPEED_MPS = 120.0


def csv_columns(path) -> tuple:
    """The lower-case column names of a CSV's header row (the first line that is not a
    ``#`` comment); empty when the file has none."""
    for line in open_text(Path(path)).splitlines():
        s = line.strip()
        if s and not s.startswith("#"):
            delim = "," if "," in s else None
            return tuple(x.strip().lower() for x in (s.split(delim) if delim else s.split()))
    return ()


def has_odometer(path) -> bool:
    """Does this CSV (an IMU file, say) carry a ``speed_mps`` column?"""
    p = Path(path)
    if not (p.is_file() and p.name.lower().endswith((".csv", ".csv.gz", ".txt"))):
        return False
    try:
        return "speed_mps" in csv_columns(p)
    except InputError:
        return False


def read_odometer(path) -> OdometerData:
    """Read ``t, speed_mps`` from a CSV (an odometer file or an IMU file with that column).

    Negative speeds (a sensor with a direction signal, reversing) are kept. Speeds whose
    median magnitude over the moving samples exceeds :data:`MAX_SPEED_MPS` are refused as
    another unit.
    """
    p = Path(path)
    tab = read_table(p, ("t", "speed_mps"))
    t = check_time(tab, min_rows=2)
    v = np.asarray(tab["speed_mps"], float)
    moving = np.abs(v) > 0.1
    if moving.any() and np.median(np.abs(v[moving])) > MAX_SPEED_MPS:
        k = int(np.argmax(np.abs(v) > MAX_SPEED_MPS))
        raise InputError(p, f"wheel speeds around {np.median(np.abs(v[moving])):.4g}: the "
                         "column needs m/s (km/h? divide by 3.6)", row=int(tab["_lines"][k]),
                         column="speed_mps")
    return OdometerData(t, v, source=str(p))
