"""Raw GNSS measurements and broadcast ephemerides: the two containers every raw reader fills
(RINEX, u-blox UBX, Android GnssLogger, PSINS ``.mat``, smartLoc); the dispatcher is
:func:`selfnav.io.raw_readers.read_gnss_raw`.

Times are **GPS time in seconds since the GPS epoch** (1980-01-06 00:00:00 GPST, float64:
0.3 µs resolution, a millimetre of satellite motion) for every constellation: Galileo system
time is GPST, BeiDou time is GPST − 14 s, GLONASS time is UTC(SU) + 3 h; readers convert once.
System codes are RTKLIB's bit codes (as the smartLoc files use): 1 GPS, 2 SBAS, 4 GLONASS,
8 Galileo, 16 QZSS, 32 BeiDou. Signals are RINEX 3 observation codes without the type letter
(``"1C"`` GPS L1 C/A, ``"5Q"`` L5 Q, ``"6I"`` BeiDou B3I, ...).
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.types import GnssData

GPS, SBAS, GLONASS, GALILEO, QZSS, BEIDOU = 1, 2, 4, 8, 16, 32
#: system code -> RINEX letter
SYSTEM_LETTERS = {GPS: "G", SBAS: "S", GLONASS: "R", GALILEO: "E", QZSS: "J", BEIDOU: "C"}
LETTER_SYSTEMS = {v: k for k, v in SYSTEM_LETTERS.items()}
SYSTEM_NAMES = {GPS: "GPS", SBAS: "SBAS", GLONASS: "GLONASS", GALILEO: "Galileo", QZSS: "QZSS",
                BEIDOU: "BeiDou"}

GPS_WEEK_S = 604800.0
#: BeiDou time = GPST − 14 s; BDT week 0 began at GPS week 1356
BDT_OFFSET_S = 14.0
BDT_WEEK0 = 1356
#: leap seconds GPST − UTC since 2017-01-01 (readers take the file's value where it has one)
LEAP_SECONDS = 18

F_L1, F_L2, F_L5 = 1575.42e6, 1227.60e6, 1176.45e6
F_E5B, F_E6, F_B1I, F_B3I = 1207.14e6, 1278.75e6, 1561.098e6, 1268.52e6

#: carrier frequency (Hz) of each (system, band digit); GLONASS FDMA handled in :func:`frequency`
_BAND_FREQ = {
    GPS: {"1": F_L1, "2": F_L2, "5": F_L5}, QZSS: {"1": F_L1, "2": F_L2, "5": F_L5, "6": F_E6},
    SBAS: {"1": F_L1, "5": F_L5},
    GALILEO: {"1": F_L1, "5": F_L5, "7": F_E5B, "8": 1191.795e6, "6": F_E6},
    BEIDOU: {"2": F_B1I, "1": F_L1, "5": F_L5, "7": F_E5B, "8": 1191.795e6, "6": F_B3I},
    GLONASS: {"4": 1600.995e6, "6": 1248.06e6, "3": 1202.025e6},
}


_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
#: (first day, GPST − UTC) for the leap seconds since 1999
_LEAPS = (("1999-01-01", 13), ("2006-01-01", 14), ("2009-01-01", 15), ("2012-07-01", 16),
          ("2015-07-01", 17), ("2017-01-01", 18))


def datetime_to_gps_seconds(dt64) -> np.ndarray:
    """numpy datetime64 (read as GPST) → seconds since the GPS epoch."""
    d = np.asarray(dt64, "datetime64[ns]")
    return (d - _GPS_EPOCH).astype("timedelta64[ns]").astype(np.int64) / 1e9


def leap_seconds_at(gps_seconds) -> int:
    """GPST − UTC (s) at a GPS time (table since 1999; 18 after 2017)."""
    leap = 13
    for day, n in _LEAPS:
        if gps_seconds >= datetime_to_gps_seconds(np.datetime64(day)) + n:
            leap = n
    return leap


def frequency(system, signal, glo_k=0):
    """Carrier frequency (Hz) of a signal; NaN when unknown. GLONASS G1/G2 FDMA:
    1602 + 0.5625 k MHz, 1246 + 0.4375 k MHz (ICD GLONASS 2008, Table 3.1)."""
    system = np.atleast_1d(np.asarray(system))
    signal = np.atleast_1d(np.asarray(signal, dtype=object))
    k = np.broadcast_to(np.asarray(glo_k, float), system.shape)
    out = np.full(system.shape, np.nan)
    for i, (s, sig) in enumerate(zip(system, signal)):
        band = str(sig)[:1]
        if s == GLONASS and band in "12":
            out[i] = (1602e6 + 0.5625e6 * k[i]) if band == "1" else (1246e6 + 0.4375e6 * k[i])
        else:
            out[i] = _BAND_FREQ.get(int(s), {}).get(band, np.nan)
    return out


def sat_names(system, prn):
    """``"G05"``-style satellite names."""
    return np.array([f"{SYSTEM_LETTERS.get(int(s), '?')}{int(p):02d}"
                     for s, p in zip(np.atleast_1d(system), np.atleast_1d(prn))], dtype=object)


@dataclass
class GnssObservations:
    """Raw measurements, one row per satellite signal per epoch, sorted by time (stable).

    Attributes
    ----------
    t : (M,) s, GPS time of reception (receiver clock), seconds since the GPS epoch
    system, prn : (M,) int
    signal : (M,) str, RINEX 3 code without the type letter (``"1C"``)
    frequency : (M,) Hz (NaN: unknown)
    pseudorange : (M,) m (NaN: none)
    doppler : (M,) Hz, positive when the satellite approaches (NaN: none); the range rate is
        ``−λ · doppler``
    carrier_phase : (M,) cycles (NaN: none)
    cn0 : (M,) dBHz (NaN: none)
    lock_time : (M,) s since the carrier was locked (NaN: unknown; 0 after a slip)
    pr_sigma : (M,) m, the receiver's own σ of the pseudorange (NaN: not given)
    doppler_sigma : (M,) Hz (NaN: not given)
    glo_k : (M,) int, GLONASS frequency channel (0 elsewhere)
    sat_ecef : (M, 3) m or None: satellite positions given by the file (smartLoc, at transmit
        time in the transmit-time Earth frame); then ``corrected`` says what is removed
    corrected : bool, True when the pseudoranges have the satellite clock and the atmosphere
        removed already (smartLoc): no ephemeris is needed
    elevation : (M,) rad or None (given by the file)
    variance : (M,) m² or None (given by the file)
    source : str
    """

    t: np.ndarray
    system: np.ndarray
    prn: np.ndarray
    signal: np.ndarray
    frequency: np.ndarray
    pseudorange: np.ndarray
    doppler: np.ndarray
    carrier_phase: np.ndarray
    cn0: np.ndarray
    lock_time: np.ndarray
    pr_sigma: np.ndarray
    doppler_sigma: np.ndarray
    glo_k: np.ndarray
    sat_ecef: np.ndarray | None = None
    corrected: bool = False
    elevation: np.ndarray | None = None
    variance: np.ndarray | None = None
    source: str = ""

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def build(cls, t, system, prn, signal, *, pseudorange=None, doppler=None, carrier_phase=None,
              cn0=None, lock_time=None, pr_sigma=None, doppler_sigma=None, glo_k=None,
              source="", **kw) -> "GnssObservations":
        """Arrays in any order (sorted by time here); missing ones become NaN / 0."""
        t = np.asarray(t, float)
        M = len(t)

        def arr(x, fill=np.nan, dtype=float):
            return np.full(M, fill, dtype) if x is None else np.asarray(x, dtype).reshape(M)

        system = np.asarray(system, int).reshape(M)
        signal = np.asarray(signal, dtype=object).reshape(M)
        k = arr(glo_k, 0, int)
        o = cls(t, system, np.asarray(prn, int).reshape(M), signal, frequency(system, signal, k),
                arr(pseudorange), arr(doppler), arr(carrier_phase), arr(cn0), arr(lock_time),
                arr(pr_sigma), arr(doppler_sigma), k, source=source, **kw)
        return o.select(np.argsort(t, kind="stable"))

    def select(self, idx) -> "GnssObservations":
        """Rows ``idx`` (a mask or indices)."""
        kw = {}
        for f in fields(self):
            v = getattr(self, f.name)
            kw[f.name] = v[idx] if isinstance(v, np.ndarray) else v
        return GnssObservations(**kw)

    @property
    def epochs(self) -> np.ndarray:
        """Distinct reception times."""
        return np.unique(self.t)

    @property
    def names(self) -> np.ndarray:
        return sat_names(self.system, self.prn)


#: Keplerian and GLONASS fields of :class:`Ephemerides` (NaN where they do not apply)
KEPLER_FIELDS = ("sqrt_a", "e", "i0", "omega0", "omega", "m0", "delta_n", "idot", "omega_dot",
                 "cuc", "cus", "crc", "crs", "cic", "cis", "af0", "af1", "af2", "tgd", "tgd2")
GLONASS_FIELDS = ("x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az", "tau_n", "gamma_n")


@dataclass
class Ephemerides:
    """Broadcast ephemerides, one row per (satellite, issue).

    Keplerian rows (GPS, QZSS, Galileo, BeiDou) use the IS-GPS-200 parameter names: ``sqrt_a``
    (m^½), ``e``, angles in rad and rates in rad/s, harmonic corrections ``c*`` (rad or m),
    clock ``af0`` (s), ``af1`` (s/s), ``af2`` (s/s²) and the group delays ``tgd`` (s: GPS T_GD,
    Galileo BGD(E1,E5b), BeiDou TGD1), ``tgd2`` (Galileo BGD(E1,E5a), BeiDou TGD2). GLONASS
    rows hold the PZ-90 position ``x, y, z`` (m), velocity (m/s), lunisolar acceleration (m/s²)
    at ``toe`` and ``tau_n`` (s), ``gamma_n``; ``glo_k`` the frequency channel. ``toe`` and
    ``toc`` are GPS time since the GPS epoch (BeiDou and GLONASS converted; see the module).

    ``ion`` maps a system code to its broadcast ionosphere parameters: GPS / BeiDou Klobuchar
    ``(α0..α3, β0..β3)`` (s, s/sc, ...), Galileo NeQuick ``(ai0, ai1, ai2)``.
    """

    system: np.ndarray
    prn: np.ndarray
    toe: np.ndarray
    toc: np.ndarray
    iode: np.ndarray
    health: np.ndarray
    ura: np.ndarray
    glo_k: np.ndarray
    params: dict
    ion: dict = field(default_factory=dict)
    leap_seconds: int | None = None
    source: str = ""

    def __len__(self) -> int:
        return len(self.system)

    def __getattr__(self, name):
        p = self.__dict__.get("params")
        if p is not None and name in p:
            return p[name]
        raise AttributeError(name)

    @classmethod
    def from_rows(cls, rows: list, *, ion=None, leap_seconds=None, source="") -> "Ephemerides":
        """From a list of dicts (keys: ``system, prn, toe, toc`` and any parameter); duplicates
        (same satellite, ``toe`` and ``iode``) are kept once."""
        seen, keep = set(), []
        for r in rows:
            key = (int(r["system"]), int(r["prn"]), round(float(r["toe"]), 3),
                   r.get("iode", -1), round(float(r.get("af0", 0.0)) * 1e12))
            if key not in seen:
                seen.add(key)
                keep.append(r)
        n = len(keep)

        def col(name, fill=np.nan, dtype=float):
            return np.array([r.get(name, fill) for r in keep], dtype=dtype).reshape(n)

        params = {k: col(k) for k in KEPLER_FIELDS + GLONASS_FIELDS}
        return cls(col("system", 0, int), col("prn", 0, int), col("toe"), col("toc"),
                   col("iode", -1, float), col("health", 0, float), col("ura"),
                   col("glo_k", 0, int), params, dict(ion or {}), leap_seconds, source)

    def select(self, idx) -> "Ephemerides":
        return Ephemerides(self.system[idx], self.prn[idx], self.toe[idx], self.toc[idx],
                           self.iode[idx], self.health[idx], self.ura[idx], self.glo_k[idx],
                           {k: v[idx] for k, v in self.params.items()}, dict(self.ion),
                           self.leap_seconds, self.source)

    def merged(self, other: "Ephemerides") -> "Ephemerides":
        """Both sets in one (ionosphere parameters of ``other`` fill missing systems)."""
        if other is None or len(other) == 0:
            return self
        if len(self) == 0:
            ion = {**self.ion, **other.ion}
            return Ephemerides(other.system, other.prn, other.toe, other.toc, other.iode,
                               other.health, other.ura, other.glo_k, other.params, ion,
                               other.leap_seconds or self.leap_seconds, other.source)
        cat = np.concatenate
        ion = {**other.ion, **self.ion}
        return Ephemerides(cat([self.system, other.system]), cat([self.prn, other.prn]),
                           cat([self.toe, other.toe]), cat([self.toc, other.toc]),
                           cat([self.iode, other.iode]), cat([self.health, other.health]),
                           cat([self.ura, other.ura]), cat([self.glo_k, other.glo_k]),
                           {k: cat([self.params[k], other.params[k]]) for k in self.params},
                           ion, self.leap_seconds or other.leap_seconds,
                           f"{self.source} + {other.source}")

    @classmethod
    def empty(cls) -> "Ephemerides":
        return cls.from_rows([])


@dataclass
class RawGnss:
    """What a raw reader returns: the measurements, the ephemerides the file carries (may be
    empty: give a navigation file), and the receiver's own solution where the file has one
    (u-blox NAV-PVT, Android ``Fix`` lines) as :class:`~selfnav.types.GnssData` with GPS time
    since the GPS epoch."""

    obs: GnssObservations
    eph: Ephemerides
    receiver: GnssData | None = None
    source: str = ""
    meta: dict = field(default_factory=dict)
