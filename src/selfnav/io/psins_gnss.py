"""GPS pseudoranges, Dopplers and broadcast ephemerides of the PSINS tightly coupled demo
(``insgpseo_tc.mat``: ``obss`` [tow, prn, C/A pseudorange m, …, Doppler m/s], ``ephs`` one row
per PRN in RINEX order: prn, toc (s of week), af0, af1, af2, IODE, Crs, Δn, M0, Cuc, e, Cus,
√A, toe, Cic, Ω0, Cis, i0, Crc, ω, Ω̇, IDOT, L2 codes, week, L2P, accuracy, health, TGD, IODC,
…). The IMU in the same file (``imu``: 200 Hz increments dθ [rad], dv [m/s], t [s] from
``t0``, the GPS time of week of IMU time 0) is read by :func:`read_psins_tc_imu`, stamped in
GPS time as the observations are. The file has no ionosphere parameters (Klobuchar falls back
to a default set, with a warning).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.io.gnss_raw import GPS, GPS_WEEK_S, Ephemerides, GnssObservations, RawGnss
from selfnav.io.imu import check_imu_units
from selfnav.types import ImuData

_EPH_COLS = ("prn", "toc", "af0", "af1", "af2", "iode", "crs", "delta_n", "m0", "cuc", "e",
             "cus", "sqrt_a", "toe", "cic", "omega0", "cis", "i0", "crc", "omega", "omega_dot",
             "idot", "codes", "week", "l2p", "ura", "health", "tgd")


def _loadmat(path):
    import scipy.io as sio

    try:
        return sio.loadmat(path)
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except Exception as e:
        raise InputError(path, f"not a readable MATLAB file ({type(e).__name__})") from None


def read_psins_tc_imu(path) -> ImuData:
    """The ``imu`` increments of a PSINS tightly coupled ``.mat`` (RFU) as rates, stamped in
    GPS seconds (``week · 604800 + t0 + t``, the week of the file's ephemerides) when the file
    has ``t0`` and ``ephs``, else in the file's own seconds."""
    path = Path(path)
    m = _loadmat(path)
    if "imu" not in m:
        raise InputError(path, "has no 'imu' variable (not the PSINS tightly coupled layout)")
    a = np.asarray(m["imu"], float)
    if a.ndim != 2 or a.shape[1] < 7 or len(a) < 2:
        raise InputError(path, f"imu {a.shape}: expected rows of dθx dθy dθz dvx dvy dvz t")
    t = a[:, 6]
    if not np.all(np.diff(t) > 0):
        raise InputError(path, f"imu column 7 (time) is not increasing at row "
                               f"{int(np.argmin(np.diff(t) > 0)) + 2}")
    dt = np.diff(t, prepend=t[0] - float(np.median(np.diff(t))))
    meta = {"format": "psins-tc-mat", "time": "file"}
    if "t0" in m and "ephs" in m:
        eph = np.asarray(m["ephs"], float)
        filled = eph[:, 12] > 0 if eph.ndim == 2 and eph.shape[1] > 23 else np.zeros(0, bool)
        if np.any(filled):
            week = int(np.median(eph[filled, 23]))
            t = t + week * GPS_WEEK_S + float(np.ravel(m["t0"])[0])
            meta["time"] = "gps"
    imu = ImuData(t, a[:, 0:3] / dt[:, None], a[:, 3:6] / dt[:, None], source=str(path),
                  meta=meta)
    check_imu_units(imu, path)
    return imu


def read_psins_gnss(path) -> RawGnss:
    """``obss`` and ``ephs`` of a PSINS ``.mat`` (GPS L1 C/A, GPS time)."""
    path = Path(path)
    m = _loadmat(path)
    if "obss" not in m or "ephs" not in m:
        raise InputError(path, "has no 'obss' and 'ephs' variables (not the PSINS tightly "
                               "coupled GNSS layout)")
    obs_a, eph_a = np.asarray(m["obss"], float), np.asarray(m["ephs"], float)
    if obs_a.ndim != 2 or obs_a.shape[1] < 3 or eph_a.ndim != 2 or eph_a.shape[1] < 28:
        raise InputError(path, f"obss {obs_a.shape} / ephs {eph_a.shape}: not the PSINS "
                               "layout (obss ≥ 3 columns, ephs ≥ 28)")
    rows = []
    filled = (eph_a[:, 0] > 0) & (eph_a[:, 12] > 0)       # rows with an orbit (√A)
    for r in eph_a[filled]:
        d = dict(zip(_EPH_COLS, r[:len(_EPH_COLS)]))
        week = int(d["week"])
        row = {k: float(d[k]) for k in ("af0", "af1", "af2", "iode", "crs", "delta_n", "m0",
                                        "cuc", "e", "cus", "sqrt_a", "cic", "omega0", "cis",
                                        "i0", "crc", "omega", "omega_dot", "idot", "tgd",
                                        "health", "ura")}
        row.update(system=GPS, prn=int(d["prn"]), toe=week * GPS_WEEK_S + d["toe"],
                   toc=week * GPS_WEEK_S + d["toc"])
        rows.append(row)
    eph = Ephemerides.from_rows(rows, source=f"{path} (ephs)")
    week = int(np.median(eph_a[filled, 23])) if len(eph) else 0
    tow = obs_a[:, 0]
    # the TOW of the observations may precede toe's week boundary: keep within half a week
    t = week * GPS_WEEK_S + tow
    if len(eph):
        t += GPS_WEEK_S * np.round((np.median(eph.toe) - t) / GPS_WEEK_S)
    # column 6 is the Doppler as a velocity, m/s, positive approaching (−ρ̇; it matches the
    # change of the pseudoranges): as Hz on L1
    dop = obs_a[:, 5] * 1575.42e6 / 299_792_458.0 if obs_a.shape[1] > 5 else None
    obs = GnssObservations.build(t, np.full(len(t), GPS), obs_a[:, 1].astype(int),
                                 np.full(len(t), "1C", dtype=object), pseudorange=obs_a[:, 2],
                                 doppler=dop, source=str(path))
    return RawGnss(obs, eph, None, str(path), {"imu_t0_tow": float(np.ravel(m.get("t0", [np.nan]))[0])})
