"""The trajectory every simulator produces and every evaluator reads (DESIGN §6 truth file)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from selfnav import attitude as att
from selfnav.errors import InputError
from selfnav.io.csvio import check_time, read_table, write_csv

TRUTH_COLUMNS = ("t", "lat_deg", "lon_deg", "h_m", "ve", "vn", "vu", "roll_deg", "pitch_deg",
                 "heading_deg")


@dataclass
class Trajectory:
    """Position, velocity and attitude against time.

    Attributes
    ----------
    t : (N,) s
    lat, lon : (N,) rad (WGS-84 geodetic)
    h : (N,) m
    velocity_n : (N, 3) m/s, ENU
    C_nb : (N, 3, 3) nav ENU -> body RFU
    source : str
        ``"simulated ..."`` for simulated data.
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    velocity_n: np.ndarray
    C_nb: np.ndarray
    source: str = "simulated"

    def __len__(self) -> int:
        return len(self.t)

    def euler(self):
        """``(roll, pitch, heading)`` arrays, rad."""
        return att.euler_from_dcm_nb(self.C_nb)


def write_truth(path, traj: Trajectory, comments=()):
    """Write a truth/solution CSV (DESIGN §6) atomically."""
    cols = {"t": traj.t, "lat_deg": np.degrees(traj.lat), "lon_deg": np.degrees(traj.lon),
            "h_m": traj.h}
    # unknown velocity or attitude (NaN) is left out rather than written as nan
    if np.all(np.isfinite(traj.velocity_n)):
        cols.update(ve=traj.velocity_n[:, 0], vn=traj.velocity_n[:, 1], vu=traj.velocity_n[:, 2])
    if np.all(np.isfinite(traj.C_nb)):
        roll, pitch, heading = traj.euler()
        cols.update(roll_deg=np.degrees(roll), pitch_deg=np.degrees(pitch),
                    heading_deg=np.degrees(heading))
    fmt = {k: "%.10f" for k in ("lat_deg", "lon_deg")}
    return write_csv(path, cols, comments=[traj.source, *comments], fmt=fmt)


def read_truth(path) -> Trajectory:
    """Read a truth or solution CSV; velocity and attitude default to NaN when absent."""
    tab = read_table(path, ("t", "lat_deg", "lon_deg"), optional=TRUTH_COLUMNS[3:])
    t = check_time(tab, min_rows=1)
    lat = np.radians(tab["lat_deg"])
    if np.any(np.abs(lat) > np.pi / 2):
        k = int(np.argmax(np.abs(lat) > np.pi / 2))
        raise InputError(path, "latitude outside ±90°: columns swapped or not degrees?",
                         row=int(tab["_lines"][k]), column="lat_deg")
    n = len(t)
    nan3 = np.full((n, 3), np.nan)
    v = np.column_stack([tab[k] for k in ("ve", "vn", "vu")]) if all(
        k in tab for k in ("ve", "vn", "vu")) else nan3
    if all(k in tab for k in ("roll_deg", "pitch_deg", "heading_deg")):
        C = att.dcm_nb_from_euler(np.radians(tab["roll_deg"]), np.radians(tab["pitch_deg"]),
                                  np.radians(tab["heading_deg"]))
    else:
        C = np.full((n, 3, 3), np.nan)
    h = tab.get("h_m", np.zeros(n))
    return Trajectory(t, lat, np.radians(tab["lon_deg"]), h, v, C, source=str(path))
