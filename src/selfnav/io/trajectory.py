"""Truth and solution files (DESIGN §6): ``t, lat_deg, lon_deg, h_m`` and, where known,
``ve, vn, vu, roll_deg, pitch_deg, heading_deg``."""
from __future__ import annotations

import warnings

import numpy as np

from selfnav import attitude as att
from selfnav.errors import InputError, SelfnavWarning
from selfnav.io.csvio import check_time, read_table, write_csv
from selfnav.io.fleet import radians_hint
from selfnav.io.gnss import read_rtklib_pos
from selfnav.io.psins_mat import AVP_COLUMNS, header_of, read_avp_csv
from selfnav.types import Trajectory

TRUTH_COLUMNS = ("t", "lat_deg", "lon_deg", "h_m", "ve", "vn", "vu", "roll_deg", "pitch_deg",
                 "heading_deg")


def trajectory_columns(traj: Trajectory, lat=None, lon=None, h=None) -> dict:
    """The DESIGN §6 columns of a trajectory (positions replaced by ``lat, lon, h`` in rad, m
    when given, e.g. in another datum); unknown velocity or attitude (NaN) is left out rather
    than written as nan."""
    lat, lon, h = (traj.lat if lat is None else lat, traj.lon if lon is None else lon,
                   traj.h if h is None else h)
    cols = {"t": traj.t, "lat_deg": np.degrees(lat), "lon_deg": np.degrees(lon), "h_m": h}
    if np.all(np.isfinite(traj.velocity_n)):
        cols.update(ve=traj.velocity_n[:, 0], vn=traj.velocity_n[:, 1], vu=traj.velocity_n[:, 2])
    if np.all(np.isfinite(traj.C_nb)):
        roll, pitch, heading = att.euler_from_dcm_nb(traj.C_nb)
        cols.update(roll_deg=np.degrees(roll), pitch_deg=np.degrees(pitch),
                    heading_deg=np.degrees(heading))
    return cols


def write_truth(path, traj: Trajectory, comments=()):
    """Write a truth/solution CSV (DESIGN §6) atomically."""
    fmt = {k: "%.10f" for k in ("lat_deg", "lon_deg")}
    return write_csv(path, trajectory_columns(traj), comments=[traj.source, *comments], fmt=fmt)


def read_truth(path) -> Trajectory:
    """Read a truth or solution CSV; velocity and attitude default to NaN when absent.

    An RTKLIB solution (``.pos``) is read as a truth too (positions and velocity, no attitude):
    the usual reference of a drive with RTK; so is a PSINS navigation output (``avp`` CSV) and a
    smartLoc ground-truth file (``point3`` lines, ECEF)."""
    first = header_of(path)[:1]
    if first == (AVP_COLUMNS[0],):
        return read_avp_csv(path)
    if first[:1] and first[0].split()[:1] == ["point3"]:
        from selfnav.earth import ecef_to_geodetic
        from selfnav.io.smartloc import read_smartloc_truth

        gt = read_smartloc_truth(path)
        lat, lon, h = ecef_to_geodetic(gt.ecef)
        n = len(gt.t)
        return Trajectory(gt.t, lat, lon, h, np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan),
                          source=str(path))
    if str(path).lower().endswith(".pos"):
        g = read_rtklib_pos(path)
        n = len(g.t)
        v = g.velocity_n if g.velocity_n is not None else np.full((n, 3), np.nan)
        return Trajectory(g.t, g.lat, g.lon, g.h, v, np.full((n, 3, 3), np.nan), source=str(path))
    tab = read_table(path, ("t", "lat_deg", "lon_deg"), optional=TRUTH_COLUMNS[3:])
    t = check_time(tab, min_rows=1)
    lat = np.radians(tab["lat_deg"])
    if np.any(np.abs(lat) > np.pi / 2):
        k = int(np.argmax(np.abs(lat) > np.pi / 2))
        raise InputError(path, "latitude outside ±90°: columns swapped or not degrees?",
                         row=int(tab["_lines"][k]), column="lat_deg")
    hint = radians_hint(tab["lat_deg"], tab["lon_deg"])
    if hint:
        warnings.warn(f"{path}: {hint}", SelfnavWarning, stacklevel=2)
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
