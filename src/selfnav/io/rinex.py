"""RINEX 2 / 3 observation and navigation files, read with georinex, as
:class:`~selfnav.io.gnss_raw.GnssObservations` and :class:`~selfnav.io.gnss_raw.Ephemerides`.

Navigation records: GPS, QZSS, Galileo, BeiDou (Keplerian; BeiDou times from BDT, Galileo
weeks as RINEX writes them, aligned to GPS weeks) and GLONASS (state vectors, UTC(SU) epochs
turned into GPST with the file's leap seconds). Header Klobuchar parameters (RINEX 2 ``ION
ALPHA / ION BETA``, RINEX 3 ``IONOSPHERIC CORR GPSA/GPSB, BDSA/BDSB``) go to ``Ephemerides.ion``.
Observation files: every code (C/P), phase (L), Doppler (D) and signal-strength (S) column,
one row per satellite and signal. RINEX 2 codes are mapped to RINEX 3 signals (C1 → 1C,
P1 → 1W, P2 → 2W, C2 → 2L, C5 → 5Q).
"""
from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.io.gnss_raw import (BDT_OFFSET_S, BDT_WEEK0, BEIDOU, GALILEO, GLONASS, GPS,
                                 GPS_WEEK_S, LETTER_SYSTEMS, QZSS, Ephemerides,
                                 GnssObservations, RawGnss, datetime_to_gps_seconds,
                                 leap_seconds_at)

def _load(path):
    import georinex as gr

    path = Path(path)
    if not path.exists():
        raise InputError(path, "file not found")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return gr.load(path)
    except Exception as e:   # georinex raises ValueError, KeyError, IndexError ... on bad files
        raise InputError(path, f"not a readable RINEX file ({type(e).__name__}: "
                         f"{' '.join(str(e).split())[:120]})") from None


def _header_leap(path) -> int | None:
    try:
        with open(path, encoding="latin-1") as fh:
            for line in fh:
                if "LEAP SECONDS" in line[60:]:
                    m = re.match(r"\s*(\d+)", line)
                    return int(m.group(1)) if m else None
                if "END OF HEADER" in line:
                    break
    except OSError:
        return None
    return None


_KEP = {"sqrt_a": "sqrtA", "e": "Eccentricity", "i0": "Io", "omega0": "Omega0", "omega": "omega",
        "m0": "M0", "delta_n": "DeltaN", "idot": "IDOT", "omega_dot": "OmegaDot", "cuc": "Cuc",
        "cus": "Cus", "crc": "Crc", "crs": "Crs", "cic": "Cic", "cis": "Cis",
        "af0": "SVclockBias", "af1": "SVclockDrift", "af2": "SVclockDriftRate"}


def read_rinex_nav(path) -> Ephemerides:
    """Broadcast ephemerides of a RINEX 2/3 navigation file (see the module docstring)."""
    path = Path(path)
    nav = _load(path)
    if nav.attrs.get("rinextype") != "nav":
        raise InputError(path, "is a RINEX observation file where a navigation file is needed")
    leap = _header_leap(path)
    rows = []
    times = datetime_to_gps_seconds(nav.time.values)
    names = [str(s) for s in nav.sv.values]
    data = {k: nav[k].values for k in nav.data_vars}
    letter_default = (nav.attrs.get("svtype") or ["G"])[0][:1]
    for j, sv in enumerate(names):
        letter = sv[0] if sv[0].isalpha() else letter_default
        system = LETTER_SYSTEMS.get(letter)
        if system is None:
            continue
        prn = int(sv[1:]) if sv[0].isalpha() else int(sv)

        def get(name, i):
            a = data.get(name)
            return float(a[i, j]) if a is not None else np.nan

        for i in range(len(times)):
            if system == GLONASS:
                x = get("X", i)
                if not np.isfinite(x):
                    continue
                lp = leap if leap is not None else leap_seconds_at(times[i])
                toe = times[i] + lp          # UTC(SU) − 3 h epoch in the file: UTC → GPST
                rows.append(dict(
                    system=GLONASS, prn=prn, toe=toe, toc=toe, iode=np.nan,
                    health=get("health", i), ura=np.nan, glo_k=int(get("FreqNum", i)),
                    x=x * 1e3, y=get("Y", i) * 1e3, z=get("Z", i) * 1e3,
                    vx=get("dX", i) * 1e3, vy=get("dY", i) * 1e3, vz=get("dZ", i) * 1e3,
                    ax=get("dX2", i) * 1e3, ay=get("dY2", i) * 1e3, az=get("dZ2", i) * 1e3,
                    tau_n=-get("SVclockBias", i), gamma_n=get("SVrelFreqBias", i)))
                continue
            if system not in (GPS, QZSS, GALILEO, BEIDOU):
                continue
            sa = get("sqrtA", i)
            if not np.isfinite(sa):
                continue
            r = {k: get(v, i) for k, v in _KEP.items()}
            toe_sow = get("Toe", i)
            if system == BEIDOU:
                week = get("BDTWeek", i) + BDT_WEEK0
                toc = times[i] + BDT_OFFSET_S
                toe = week * GPS_WEEK_S + toe_sow + BDT_OFFSET_S
                r.update(tgd=get("TGD1", i), tgd2=get("TGD2", i), iode=get("AODE", i),
                         health=get("SatH1", i), ura=get("SVacc", i))
            else:
                toc = times[i]
                wk = get("GALWeek", i) if system == GALILEO else get("GPSWeek", i)
                if not np.isfinite(wk):
                    wk = np.floor(toc / GPS_WEEK_S)
                toe = wk * GPS_WEEK_S + toe_sow
                if system == GALILEO:
                    r.update(tgd=get("BGDe5b", i), tgd2=get("BGDe5a", i), iode=get("IODnav", i),
                             health=get("health", i), ura=get("SISA", i))
                else:
                    r.update(tgd=get("TGD", i), iode=get("IODE", i), health=get("health", i),
                             ura=get("SVacc", i))
            # the week of toe is the week of transmission: keep toe within half a week of toc
            toe += GPS_WEEK_S * np.round((toc - toe) / GPS_WEEK_S)
            r.update(system=system, prn=prn, toe=toe, toc=toc)
            rows.append(r)
    ion = {}
    for key, system in (("ionospheric_corr_GPS", GPS), ("ionospheric_corr_BDS", BEIDOU),
                        ("ionospheric_corr_QZS", QZSS), ("ionospheric_corr_GAL", GALILEO)):
        v = nav.attrs.get(key)
        if v is not None and np.size(v) and np.all(np.isfinite(v)):
            ion[system] = np.asarray(v, float)
    eph = Ephemerides.from_rows(rows, ion=ion, leap_seconds=leap, source=str(path))
    if len(eph) == 0:
        raise InputError(path, "holds no GPS, Galileo, BeiDou, QZSS or GLONASS ephemeris")
    return eph


_RINEX2_CODES = {"C1": "1C", "P1": "1W", "L1": "1C", "D1": "1C", "S1": "1C",
                 "C2": "2L", "P2": "2W", "L2": "2W", "D2": "2W", "S2": "2W",
                 "C5": "5Q", "L5": "5Q", "D5": "5Q", "S5": "5Q",
                 "C7": "7Q", "L7": "7Q", "D7": "7Q", "S7": "7Q"}


def read_rinex_obs(path) -> GnssObservations:
    """Measurements of a RINEX 2/3 observation file (GPST epochs), one row per satellite and
    signal with pseudorange, carrier phase, Doppler and C/N0 where the file has them."""
    path = Path(path)
    obs = _load(path)
    if obs.attrs.get("rinextype") != "obs":
        raise InputError(path, "is a RINEX navigation file where an observation file is needed "
                               "(give it with --nav)")
    t = datetime_to_gps_seconds(obs.time.values)
    svs = [str(s) for s in obs.sv.values]
    version = float(obs.attrs.get("version", 3))
    groups: dict = {}
    for var in obs.data_vars:
        name = str(var)
        if len(name) < 2 or name[0] not in "CPLDS":
            continue
        sig = name[1:3] if version >= 3 else _RINEX2_CODES.get(name)
        if sig is None or len(sig) != 2:
            continue
        kind = "C" if name[0] in "CP" else name[0]
        groups.setdefault(sig, {})[kind] = (name, obs[var].values)
    cols = {k: [] for k in ("t", "system", "prn", "signal", "C", "L", "D", "S")}
    for sig, kinds in groups.items():
        if "C" not in kinds:
            continue
        pr = kinds["C"][1]
        for j, sv in enumerate(svs):
            system = LETTER_SYSTEMS.get(sv[0])
            if system is None:
                continue
            ok = np.isfinite(pr[:, j])
            if not ok.any():
                continue
            n = int(ok.sum())
            cols["t"].append(t[ok])
            cols["system"].append(np.full(n, system))
            cols["prn"].append(np.full(n, int(sv[1:])))
            cols["signal"].append(np.full(n, sig, dtype=object))
            for k in "CLDS":
                cols[k].append(kinds[k][1][ok, j] if k in kinds else np.full(n, np.nan))
    if not cols["t"]:
        raise InputError(path, "holds no pseudorange (C or P) observations")
    cat = {k: np.concatenate(v) for k, v in cols.items()}
    glo_k = np.zeros(len(cat["t"]), int)
    return GnssObservations.build(cat["t"], cat["system"], cat["prn"], cat["signal"],
                                  pseudorange=cat["C"], carrier_phase=cat["L"], doppler=cat["D"],
                                  cn0=cat["S"], glo_k=glo_k, source=str(path))


def read_rinex(path) -> RawGnss:
    """A RINEX observation file (ephemerides come from ``--nav``); a navigation file alone is
    refused with a hint."""
    obs = read_rinex_obs(path)
    return RawGnss(obs, Ephemerides.empty(), None, str(path))
