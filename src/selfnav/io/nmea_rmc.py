"""NMEA 0183 RMC sentences: date, position, speed and course over ground → ENU velocity.

``$--RMC,hhmmss.ss,A,llll.ll,a,yyyyy.yy,a,x.x,x.x,ddmmyy,x.x,a[,m[,s]]*hh`` (any talker: GP, GN,
GL, GA, BD/GB): UTC time, status (A valid, V void), latitude, longitude, speed over ground in
knots, course over ground in degrees true (clockwise from North), UTC date, magnetic variation
(E positive) and, from NMEA 2.3 on, the mode (A autonomous, D differential, E dead reckoning,
N not valid, R/F RTK fixed/float, ...).

Velocity (ENU, m/s): ``v_E = s sin(c)``, ``v_N = s cos(c)`` with ``s = SOG · 1852/3600``;
RMC has no vertical speed, so ``v_U`` is **NaN** (a consumer must not treat it as 0 for a
vehicle that climbs). When the course field is empty (a receiver at rest often leaves it out),
the horizontal velocity is 0 if the speed is 0, NaN otherwise.

Time: ``t`` is UTC seconds of day from the sentences, unwrapped over midnight (the time base
of :func:`selfnav.io.gnss.read_nmea`, so GGA and RMC rows of one log share it); ``unix_utc``
adds the RMC date (UTC, no leap seconds: GPS time is UTC + 18 s since 2017).

Sentences with a checksum that does not match, or status V / mode N, are not used; they are
counted in ``rejected`` (by reason), never dropped silently.
"""
from __future__ import annotations

import calendar
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.io.csvio import open_text
from selfnav.types import GnssData

KNOT = 1852.0 / 3600.0  # m/s


@dataclass
class RmcData:
    """RMC fixes (valid ones only).

    Attributes
    ----------
    t : (N,) UTC seconds of day, unwrapped over midnight
    unix_utc : (N,) seconds since 1970-01-01 UTC (date + time)
    lat, lon : (N,) rad
    speed : (N,) m/s over ground
    course : (N,) rad clockwise from true North (NaN where not given)
    velocity_n : (N, 3) ENU m/s (v_U NaN: not in RMC)
    mag_variation : (N,) rad, East positive (NaN where not given)
    mode : (N,) str ('' before NMEA 2.3)
    rejected : dict reason → count
    """

    t: np.ndarray
    unix_utc: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    speed: np.ndarray
    course: np.ndarray
    velocity_n: np.ndarray
    mag_variation: np.ndarray
    mode: np.ndarray
    source: str = ""
    rejected: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)

    def to_gnss(self, sigma_m: float = np.nan) -> GnssData:
        """As :class:`GnssData` (height NaN: RMC has none; velocity with v_U NaN)."""
        n = len(self.t)
        return GnssData(self.t.copy(), self.lat.copy(), self.lon.copy(), np.full(n, np.nan),
                        np.full(n, sigma_m), self.velocity_n.copy(), None, self.source)


def checksum_ok(s: str) -> bool | None:
    """True/False when a ``*hh`` checksum is present (the XOR of the characters between ``$``
    and ``*``, NMEA 0183), None when absent."""
    if "*" not in s:
        return None
    body, _, cs = s[1:].partition("*")
    cs = cs.strip()[:2]
    try:
        want = int(cs, 16)
    except ValueError:
        return False
    x = 0
    for ch in body:
        x ^= ord(ch)
    return x == want


def nmea_sentences(text: str, kind: str):
    """``(line index, sentence from its $, fields before the checksum)`` of every ``kind``
    sentence (``"RMC"``, ``"GGA"``; any talker) of an NMEA log, a logger's time stamp before
    the ``$`` tolerated."""
    for i, ln in enumerate(text.splitlines()):
        s = ln.strip()
        j = s.find("$")
        if j < 0:
            continue
        s = s[j:]
        f = s[1:].split("*")[0].split(",")
        if len(f[0]) >= 5 and f[0][-3:] == kind:
            yield i, s, f


def _deg(v: str, hemi: str, ndeg: int) -> float:
    """``ddmm.mmmm`` / ``dddmm.mmmm`` → signed degrees."""
    k = v.index(".") if "." in v else len(v)
    if k - 2 < 1 or k - 2 > ndeg:
        raise ValueError(v)
    x = float(v[: k - 2]) + float(v[k - 2:]) / 60.0
    if hemi not in ("N", "S", "E", "W"):
        raise ValueError(hemi)
    return -x if hemi in ("S", "W") else x


def _parse(f):
    """Fields of one RMC sentence → tuple, or raise ValueError/IndexError."""
    hh, mm, ss = int(f[1][:2]), int(f[1][2:4]), float(f[1][4:])
    if hh > 23 or mm > 59 or ss >= 61:
        raise ValueError(f[1])
    tod = hh * 3600 + mm * 60 + ss
    lat = _deg(f[3], f[4], 2)
    lon = _deg(f[5], f[6], 3)
    sog = float(f[7]) * KNOT if f[7] else np.nan
    cog = np.radians(float(f[8])) if f[8] else np.nan
    d = f[9]
    day, mon, yy = int(d[:2]), int(d[2:4]), int(d[4:6])
    year = 1900 + yy if yy >= 80 else 2000 + yy
    unix = calendar.timegm((year, mon, day, 0, 0, 0)) + tod
    var = np.nan
    if len(f) > 11 and f[10]:
        var = np.radians(float(f[10])) * (-1.0 if f[11].startswith("W") else 1.0)
    mode = f[12][:1] if len(f) > 12 else ""
    return tod, unix, lat, lon, sog, cog, var, mode


def read_nmea_rmc(path) -> RmcData:
    """Read the RMC sentences of an NMEA 0183 log (see the module docstring).

    Raises :class:`InputError` naming the line for a malformed RMC sentence whose checksum is
    right (or absent), and when no valid RMC fix is found.
    """
    path = Path(path)
    text = open_text(path)
    rows, rejected = [], {}
    for i, s, f in nmea_sentences(text, "RMC"):
        ok = checksum_ok(s)
        if ok is False:
            rejected["checksum"] = rejected.get("checksum", 0) + 1
            continue
        if len(f) < 10:
            raise InputError(path, f"RMC sentence with {len(f)} fields (at least 10 expected)",
                             row=i + 1)
        if f[2] != "A":
            rejected["status V (void)"] = rejected.get("status V (void)", 0) + 1
            continue
        try:
            r = _parse(f)
        except (ValueError, IndexError):
            raise InputError(path, "malformed RMC sentence (time, position, speed, course or "
                             "date field)", row=i + 1) from None
        if r[7] == "N":
            rejected["mode N (not valid)"] = rejected.get("mode N (not valid)", 0) + 1
            continue
        rows.append(r + (i + 1,))
    if not rows:
        raise InputError(path, f"no valid RMC fixes (is it NMEA 0183? rejected: {rejected or 'none'})")
    tod = np.array([r[0] for r in rows])
    unix = np.array([r[1] for r in rows], dtype=float)
    d = np.diff(unix)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0)) + 1
        raise InputError(path, "RMC time repeated or going backwards (merged or unsorted log?)",
                         row=rows[k][8])
    t = tod[0] + (unix - unix[0])  # seconds of day of the first fix, unwrapped by the date
    lat = np.radians([r[2] for r in rows])
    lon = np.radians([r[3] for r in rows])
    sog = np.array([r[4] for r in rows])
    cog = np.array([r[5] for r in rows])
    ve = np.where(np.isfinite(cog), sog * np.sin(cog), np.where(sog == 0, 0.0, np.nan))
    vn = np.where(np.isfinite(cog), sog * np.cos(cog), np.where(sog == 0, 0.0, np.nan))
    vel = np.column_stack([ve, vn, np.full(len(t), np.nan)])
    return RmcData(t, unix, lat, lon, sog, cog, vel, np.array([r[6] for r in rows]),
                   np.array([r[7] for r in rows]), str(path), rejected)
