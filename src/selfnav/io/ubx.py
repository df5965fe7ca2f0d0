"""u-blox UBX binary logs, parsed with pyubx2: RXM-RAWX (raw measurements), RXM-SFRBX
(navigation subframes → broadcast ephemerides, :mod:`selfnav.io.navbits`), NAV-PVT (the
receiver's own solution).

RXM-RAWX (u-blox interface description, UBX-RXM-RAWX): ``rcvTow`` + ``week`` (receiver
time, GPST), per measurement ``prMes`` (m), ``cpMes`` (cycles), ``doMes`` (Hz, positive when
approaching), ``cno`` (dBHz), ``locktime`` (ms), ``prStd`` (0.01·2ⁿ m), ``doStd``
(0.002·2ⁿ Hz), ``trkStat`` (``prValid``, ``cpValid``); ``gnssId``/``sigId`` mapped to RINEX
signal codes by :data:`SIGNALS`. A pseudorange without ``prValid`` is NaN.

NAV-PVT → :class:`~selfnav.types.GnssData` at GPS time (``iTOW`` with the RAWX week), with
the RTKLIB quality flag (1 fixed RTK, 2 float, 4 differential, 5 single; 0 no fix), ``hAcc``
as the horizontal σ (per axis ``hAcc / √2``), ``vAcc``, NED velocity as ENU.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.io.gnss_raw import (BEIDOU, GALILEO, GLONASS, GPS, GPS_WEEK_S, QZSS, SBAS,
                                 Ephemerides, GnssObservations, RawGnss)
from selfnav.io.navbits import BdsD1Decoder, InavDecoder, LnavDecoder
from selfnav.types import GnssData

GNSS_ID = {0: GPS, 1: SBAS, 2: GALILEO, 3: BEIDOU, 5: QZSS, 6: GLONASS}
#: (gnssId, sigId) -> RINEX signal code
SIGNALS = {
    (0, 0): "1C", (0, 3): "2L", (0, 4): "2S", (0, 6): "5I", (0, 7): "5Q",
    (1, 0): "1C",
    (2, 0): "1C", (2, 1): "1B", (2, 3): "5I", (2, 4): "5Q", (2, 5): "7I", (2, 6): "7Q",
    (2, 8): "6B", (2, 9): "6C", (2, 10): "6A",
    (3, 0): "2I", (3, 1): "2I", (3, 2): "7I", (3, 3): "7I", (3, 4): "6I", (3, 5): "1P",
    (3, 6): "1D", (3, 7): "5P", (3, 8): "5D", (3, 10): "6I",
    (5, 0): "1C", (5, 1): "1Z", (5, 4): "2S", (5, 5): "2L", (5, 8): "5I", (5, 9): "5Q",
    (6, 0): "1C", (6, 2): "2C",
}


def _messages(path):
    from pyubx2 import UBX_PROTOCOL, UBXReader

    wanted = {"RXM-RAWX", "RXM-SFRBX", "NAV-PVT"}
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except OSError as e:
        raise InputError(path, f"cannot read ({e.strerror})") from None
    with fh:
        reader = UBXReader(fh, protfilter=UBX_PROTOCOL, quitonerror=0)
        try:
            for _, msg in reader:
                if msg is not None and getattr(msg, "identity", "") in wanted:
                    yield msg
        except Exception as e:          # pyubx2 raises its own errors on a corrupt stream
            raise InputError(path, f"corrupt UBX stream ({type(e).__name__}: "
                                   f"{' '.join(str(e).split())[:100]})") from None


def read_ubx(path) -> RawGnss:
    """Read a UBX log (see the module docstring)."""
    path = Path(path)
    cols = {k: [] for k in ("t", "gid", "sid", "prn", "pr", "cp", "do", "cno", "lock", "prs",
                            "dos", "fid")}
    sfrbx, pvt = [], []
    week_last = None
    for msg in _messages(path):
        ident = msg.identity
        if ident == "RXM-RAWX":
            week_last = int(msg.week)
            t = week_last * GPS_WEEK_S + float(msg.rcvTow)
            for i in range(1, int(msg.numMeas) + 1):
                sfx = f"_{i:02d}"
                g = getattr(msg, "gnssId" + sfx)
                cols["t"].append(t)
                cols["gid"].append(g)
                cols["sid"].append(getattr(msg, "sigId" + sfx))
                cols["prn"].append(getattr(msg, "svId" + sfx))
                ok_pr = getattr(msg, "prValid" + sfx, 1)
                ok_cp = getattr(msg, "cpValid" + sfx, 1)
                cols["pr"].append(getattr(msg, "prMes" + sfx) if ok_pr else np.nan)
                cols["cp"].append(getattr(msg, "cpMes" + sfx) if ok_cp else np.nan)
                cols["do"].append(getattr(msg, "doMes" + sfx))
                cols["cno"].append(getattr(msg, "cno" + sfx))
                cols["lock"].append(getattr(msg, "locktime" + sfx) * 1e-3)
                cols["prs"].append(0.01 * 2.0 ** getattr(msg, "prStd" + sfx))
                cols["dos"].append(0.002 * 2.0 ** getattr(msg, "doStd" + sfx))
                cols["fid"].append(getattr(msg, "freqId" + sfx))
        elif ident == "RXM-SFRBX":
            words = [getattr(msg, f"dwrd_{j:02d}") for j in range(1, int(msg.numWords) + 1)]
            sfrbx.append((week_last, msg.gnssId, msg.svId, msg.sigId, words))
        elif ident == "NAV-PVT":
            pvt.append(msg)
    if not cols["t"]:
        raise InputError(path, "holds no UBX-RXM-RAWX message (raw measurements are not "
                               "enabled in this log)")
    a = {k: np.asarray(v) for k, v in cols.items()}
    known = np.array([(int(g), int(s)) in SIGNALS and int(g) in GNSS_ID
                      for g, s in zip(a["gid"], a["sid"])])
    a = {k: v[known] for k, v in a.items()}
    system = np.array([GNSS_ID[int(g)] for g in a["gid"]], int)
    signal = np.array([SIGNALS[(int(g), int(s))] for g, s in zip(a["gid"], a["sid"])],
                      dtype=object)
    glo_k = np.where(system == GLONASS, a["fid"].astype(int) - 7, 0)
    obs = GnssObservations.build(a["t"], system, a["prn"], signal, pseudorange=a["pr"],
                                 doppler=a["do"], carrier_phase=a["cp"], cn0=a["cno"],
                                 lock_time=a["lock"], pr_sigma=a["prs"], doppler_sigma=a["dos"],
                                 glo_k=glo_k, source=str(path))
    eph, counts = _ephemerides(sfrbx, obs, path)
    receiver = _pvt(pvt, int(np.median(a["t"]) // GPS_WEEK_S), path)
    return RawGnss(obs, eph, receiver, str(path), {"sfrbx": len(sfrbx), **counts})


def _ephemerides(sfrbx, obs, path):
    """Decode the subframes in order; the time of each is the last RAWX epoch before it."""
    lnav, qlnav, inav, d1 = LnavDecoder(GPS), LnavDecoder(QZSS), InavDecoder(), BdsD1Decoder()
    rows = []
    t0 = float(obs.t[0]) if len(obs) else 0.0
    for week, gid, svid, sigid, words in sfrbx:
        t_ref = t0 if week is None else week * GPS_WEEK_S + GPS_WEEK_S / 2
        t_ref = t0 if week is None else t0 + GPS_WEEK_S * round((t_ref - t0) / GPS_WEEK_S)
        row = None
        if gid == 0 and len(words) == 10 and sigid == 0:      # L1 C/A LNAV (not CNAV)
            row = lnav.add(int(svid), words, t_ref)
        elif gid == 5 and len(words) == 10 and sigid == 0:
            row = qlnav.add(int(svid), words, t_ref)
        elif gid == 2 and len(words) == 8 and sigid in (1, 5):
            row = inav.add(int(svid), words, t_ref)
        elif gid == 3 and len(words) == 10 and sigid in (0, 2, 4):   # D1 on B1I/B2I/B3I
            row = d1.add(int(svid), words, t_ref)
        if row is not None:
            rows.append(row)
    ion = {}
    if lnav.ion is not None:
        ion[GPS] = lnav.ion
    if d1.ion is not None:
        ion[BEIDOU] = d1.ion
    if inav.ion is not None:
        ion[GALILEO] = inav.ion
    eph = Ephemerides.from_rows(rows, ion=ion, source=f"{path} (RXM-SFRBX)")
    counts = {f"ephemerides_{n}": int(np.sum(eph.system == s)) for n, s in
              (("gps", GPS), ("galileo", GALILEO), ("beidou", BEIDOU), ("qzss", QZSS))}
    counts["galileo_crc_errors"] = inav.crc_errors
    return eph, counts


def _pvt(msgs, week, path):
    if not msgs:
        return None
    n = len(msgs)
    t = np.empty(n)
    lat, lon, h = np.empty(n), np.empty(n), np.empty(n)
    hacc, vacc, q = np.empty(n), np.empty(n), np.zeros(n, int)
    vel = np.empty((n, 3))
    for i, m in enumerate(msgs):
        t[i] = week * GPS_WEEK_S + m.iTOW * 1e-3
        lat[i], lon[i], h[i] = np.radians(m.lat), np.radians(m.lon), m.height * 1e-3
        hacc[i], vacc[i] = m.hAcc * 1e-3, m.vAcc * 1e-3
        vel[i] = (m.velE * 1e-3, m.velN * 1e-3, -m.velD * 1e-3)
        if m.fixType < 2 or not m.gnssFixOk:
            q[i] = 0
        elif m.carrSoln == 2:
            q[i] = 1
        elif m.carrSoln == 1:
            q[i] = 2
        elif m.diffSoln:
            q[i] = 4
        else:
            q[i] = 5
    return GnssData(t, lat, lon, h, hacc / np.sqrt(2), vel, q, f"{path} (NAV-PVT)", vacc)

