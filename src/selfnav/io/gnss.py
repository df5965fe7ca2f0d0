"""GNSS fixes: the native CSV (DESIGN §6: ``t, lat_deg, lon_deg, h_m[, sigma_m]``), RTKLIB ``.pos``
and NMEA GGA (+ RMC velocity) readers. Positions are converted to WGS-84 at load time (``datum``)."""
from __future__ import annotations

import calendar
import datetime as _dt
import warnings
from pathlib import Path

import numpy as np

from selfnav.errors import InputError, SelfnavWarning
from selfnav.io.csvio import open_text
from selfnav.io.fleet import (build_tracks, merged_note, read_columns,  # noqa: F401
                              to_wgs84)
from selfnav.io.nmea_rmc import checksum_ok, nmea_sentences
from selfnav.types import GnssData

#: GPS time origin 1980-01-06 in Unix-like seconds; GPS week seconds are counted from a Sunday.
GPS_EPOCH_UNIX = 315964800
WEEK = 604800.0




def read_gnss_csv(path, datum: str = "wgs84") -> GnssData:
    """Native GNSS CSV: ``t, lat_deg, lon_deg, h_m`` and optional ``sigma_m``, ``ve, vn, vu``.

    ``t`` in seconds or ISO-8601 date-times (then seconds since 1970, UTC); rows out of time
    order are ordered and repeated time stamps merged (positions averaged), each with a one-line
    :class:`~selfnav.errors.SelfnavWarning`. A value that is not a number is an error naming the
    line. One track per file (a ``track_id`` column with several tracks is refused: ``selfnav
    match`` reads fleets).
    """
    cols, lines = read_columns(path, ("t", "lat_deg", "lon_deg", "h_m"),
                               ("sigma_m", "ve", "vn", "vu", "track_id"))
    tracks, form, counts = build_tracks(path, cols, lines, datum=datum, strict=True,
                                        velocity=True)
    if len(tracks) > 1:
        raise InputError(path, f"holds {len(tracks)} tracks (column track_id): navigation takes "
                         "one; split the file (selfnav match reads fleets)")
    tr = tracks[0]
    if tr.error is not None:
        raise InputError(path, f"has {len(np.unique(tr.row_fix))} distinct time stamps; at "
                         "least 2 are needed")
    if counts["reordered"]:
        warnings.warn(f"{path}: rows out of time order ordered by time ({counts['reordered']} "
                      "steps back)", SelfnavWarning, stacklevel=2)
    if counts["merged"]:
        warnings.warn(f"{path}: {merged_note(counts)}", SelfnavWarning, stacklevel=2)
    return tr.gnss


def gps_seconds_of_week(unix_like_gpst):
    """GPS seconds of week from Unix-like GPST seconds."""
    return np.mod(np.asarray(unix_like_gpst, dtype=float) - GPS_EPOCH_UNIX, WEEK)


def read_rtklib_pos(path) -> GnssData:
    """RTKLIB solution file (``.pos``, lat/lon/height format, GPST), time as GPS seconds of week.

    Columns: date, time, lat, lon, h, Q, ns, sdn, sde, sdu, sdne, sdeu, sdun, age, ratio and,
    when present, vn, ve, vu (m/s) and their σ sdvn, sdve, sdvu, ... Returns WGS-84 positions,
    σ = max(sdn, sde), vertical σ sdu, ENU velocity and its σ max(sdvn, sdve), the Q flag.
    """
    path = Path(path)
    text = open_text(path)
    rows, lines = [], []
    body = [(i, ln.strip()) for i, ln in enumerate(text.splitlines())]
    body = [(i, s) for i, s in body if s and not s.startswith("%")]
    if len(body) >= 3 and _partial_pos_row(body[-1][1], body[-2][1]):
        # a solution file copied while RTKLIB was still writing it: the last row is cut short
        warnings.warn(f"{path}: line {body[-1][0] + 1} is a partial row (fewer fields or a "
                      "number cut short: the file was still being written when it was copied), skipped",
                      SelfnavWarning, stacklevel=2)
        body = body[:-1]
    for i, s in body:
        parts = s.split()
        if len(parts) < 15:
            raise InputError(path, f"{len(parts)} fields: not an RTKLIB lat/lon .pos row", row=i + 1)
        try:
            d = _dt.datetime.strptime(parts[0] + " " + parts[1][:15], "%Y/%m/%d %H:%M:%S.%f")
        except ValueError:
            raise InputError(path, f"'{parts[0]} {parts[1]}' is not a GPST date and time "
                             "(expected YYYY/MM/DD HH:MM:SS.SSS; is the file in week/TOW form?)",
                             row=i + 1) from None
        sec = calendar.timegm(d.timetuple())
        frac = d.microsecond * 1e-6
        try:
            vals = [float(x) for x in parts[2:27]]
        except ValueError:
            raise InputError(path, "non-numeric value", row=i + 1) from None
        rows.append([float((sec - GPS_EPOCH_UNIX) % int(WEEK)) + frac] + vals)
        lines.append(i + 1)
    if not rows:
        raise InputError(path, "has no solution rows")
    a = np.array([r + [np.nan] * (26 - len(r)) for r in rows])
    t = a[:, 0]
    if np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise InputError(path, "time not increasing (or a GPS week rollover)", row=lines[k])
    vel = None
    if np.all(np.isfinite(a[:, 14:17])):
        vel = np.column_stack([a[:, 15], a[:, 14], a[:, 16]])  # ve, vn, vu
    sig = np.maximum(a[:, 6], a[:, 7])  # sdn, sde
    sig = np.where(sig > 0, sig, np.nan)  # 0: not estimated (never a σ of zero)
    sig_vel = None
    if vel is not None and np.all(np.isfinite(a[:, 17:19])) and np.all(a[:, 17:19] > 0):
        sig_vel = np.maximum(a[:, 17], a[:, 18])  # sdvn, sdve
    sig_v = a[:, 8] if np.all(a[:, 8] > 0) else None
    return GnssData(t, np.radians(a[:, 1]), np.radians(a[:, 2]), a[:, 3], sig, vel,
                    a[:, 4].astype(int), str(path), sig_v, sig_vel)


def _partial_pos_row(last: str, before: str) -> bool:
    """A ``.pos`` row cut short: fewer fields than the row before it, or a field that is not
    a number where that row has one."""
    a, b = last.split(), before.split()
    if len(a) < len(b):
        return True
    for x, y in zip(a[2:], b[2:]):
        try:
            float(y)
        except ValueError:
            continue
        try:
            float(x)
        except ValueError:
            return True
    return False


def _nmea_deg(v, hemi):
    d = float(v[: v.index(".") - 2])
    m = float(v[v.index(".") - 2:])
    x = d + m / 60.0
    return -x if hemi in ("S", "W") else x


def read_nmea(path) -> GnssData:
    """NMEA 0183 GGA (position, height) with RMC (date, speed, course) where present.

    Time is seconds of day (UTC) from the sentences; h = orthometric + geoid separation.
    Fixes with quality 0 are dropped; σ from HDOP × 2.5 m when no better is known.
    """
    path = Path(path)
    text = open_text(path)
    gga = list(nmea_sentences(text, "GGA"))
    # a sentence cut short where the others carry a checksum: the logger stopped mid-line
    if len(gga) >= 2 and "*" not in gga[-1][1] and "*" in gga[-2][1]:
        warnings.warn(f"{path}: line {gga[-1][0] + 1} is a partial GGA sentence (the logger "
                      "stopped mid-line), skipped", SelfnavWarning, stacklevel=2)
        gga = gga[:-1]
    t, lat, lon, h, sig, q = [], [], [], [], [], []
    bad_sum = []
    for i, s, f in gga:
        if checksum_ok(s) is False:
            bad_sum.append(i + 1)
            continue
        if len(f) < 12:
            raise InputError(path, f"GGA sentence with {len(f)} fields (15 expected)", row=i + 1)
        if not f[6] or f[6] == "0" or not f[2] or not f[4]:
            continue
        try:
            hh, mm, ss = int(f[1][:2]), int(f[1][2:4]), float(f[1][4:])
            t.append(hh * 3600 + mm * 60 + ss)
            lat.append(_nmea_deg(f[2], f[3]))
            lon.append(_nmea_deg(f[4], f[5]))
            h.append(float(f[9]) + (float(f[11]) if f[11] else 0.0))
            sig.append(2.5 * float(f[8]) if f[8] else np.nan)
            q.append(int(f[6]))
        except (ValueError, IndexError):
            raise InputError(path, "malformed GGA sentence (time, position, quality, HDOP or "
                             "height field)", row=i + 1) from None
    if bad_sum and t:
        warnings.warn(f"{path}: {len(bad_sum)} GGA sentence{'s' if len(bad_sum) > 1 else ''} "
                      f"with a wrong checksum skipped (corrupted bytes; first on line "
                      f"{bad_sum[0]})", SelfnavWarning, stacklevel=2)
    if not t:
        why = (f"all {len(bad_sum)} have a wrong checksum (first on line {bad_sum[0]})"
               if bad_sum else "is it NMEA 0183?")
        raise InputError(path, f"no valid GGA fixes ({why})")
    t = np.unwrap(np.asarray(t), period=86400.0)
    sig = np.asarray(sig, dtype=float)
    sig = np.where(sig > 0, sig, np.nan)  # HDOP 0: not given (never a σ of zero)
    return GnssData(t, np.radians(lat), np.radians(lon), np.asarray(h), sig, None,
                    np.asarray(q), str(path))
