"""Fleet GNSS files: many tracks in CSV or Parquet, as floating-car loggers write them (issue 14).

The documented schema is the native GNSS CSV's, ``t, lat_deg, lon_deg[, h_m, sigma_m]``, plus an
optional ``track_id``; every track is matched on its own and keeps its id. What loggers write is
accepted as it comes:

* column names: common spellings (``latitude``/``lat``, ``longitude``/``lon``/``lng``,
  ``timestamp``/``time``, ``trip_id``/``vehicle_id``/...) are read as the schema's, with a note;
* ``t``: seconds, epoch milliseconds, or ISO-8601 date-times with or without a zone
  (``2019-03-11T08:33:24+00:00``); the output keeps the input's text;
* repeated time stamps in a track (two positions in the same second) are merged into one fix
  (positions averaged; positions that disagree by more than :data:`REPEAT_AGREE_M` -- a
  multipath fix beside a good one -- give the one nearest the neighbouring fixes), rows out of
  time order are ordered, a track's rows may be spread over the file; each of these gives one
  line (a :class:`~selfnav.errors.SelfnavWarning`) with the count;
* a bad row (a value that is not a number, a latitude beyond ±90°) is skipped with one line
  naming the track and the file line; a track left with fewer than two fixes is reported and
  left out — the other tracks are read.

Several files, or a folder of them, make one fleet; a file without a ``track_id`` column is one
track named after the file. Readers return :class:`~selfnav.types.GnssData` per track and never
import an algorithm.
"""
from __future__ import annotations

import csv
import io
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from selfnav import datum as dm
from selfnav.earth import enu_offset
from selfnav.errors import InputError, SelfnavWarning
from selfnav.io.csvio import open_text, parse_numbers, parse_times, refuse_numeric_header
from selfnav.types import GnssData

#: schema column -> accepted spellings, in order of preference (compared lower case, without
#: spaces, underscores or other punctuation: ``Track ID``, ``track_id`` and ``trackId`` agree)
ALIASES = {
    "t": ("t", "timestamp", "time", "datetime", "date_time", "time_utc", "utc_time",
          "timestamp_utc", "datetime_utc", "time_stamp", "ts", "gps_time", "gpstime",
          "pingtimestamp", "recorded_at", "time_s", "epoch", "unix_time", "utc"),
    "lat_deg": ("lat_deg", "lat", "latitude", "lat_wgs84", "latitude_deg", "lat_dd", "rawlat",
                "gps_lat", "y_lat"),
    "lon_deg": ("lon_deg", "lon", "lng", "long", "longitude", "lon_wgs84", "longitude_deg",
                "lon_dd", "rawlng", "rawlon", "gps_lon", "gps_lng", "x_lon"),
    "h_m": ("h_m", "alt", "altitude", "height", "elevation", "alt_m", "altitude_m", "h"),
    "sigma_m": ("sigma_m",),
    "track_id": ("track_id", "trip_id", "trajectory_id", "traj_id", "trj_id", "track", "trip",
                 "trajectory", "vehicle_id", "device_id", "vehicle", "device", "car_id",
                 "taxi_id", "bus_id", "unit_id", "driver_id", "object_id", "imei"),
    "ve": ("ve",), "vn": ("vn",), "vu": ("vu",),
    "date": ("date", "day", "gps_date"),
}
#: a column that is a track id only if its values repeat (otherwise it numbers the rows)
WEAK_TRACK_ID = ("id",)
FLEET_COLUMNS = ("t", "lat_deg", "lon_deg", "h_m", "sigma_m", "track_id")
SUFFIXES = (".csv", ".csv.gz", ".txt", ".parquet", ".pq")
MAX_TRACK_NOTES = 20


@dataclass
class FleetTrack:
    """One track of a fleet file.

    Attributes
    ----------
    track_id : str
    gnss : GnssData or None
        Distinct fixes in time order (repeated stamps merged), WGS-84; None if the track
        cannot be matched (see ``error``).
    row_fix : (R,) int
        For each kept input row, in time order, the fix of ``gnss`` it became.
    t_text : list of str
        The input's time text of each kept row (what the output writes back).
    lines : (R,) int
        File line (CSV) or row number (Parquet) of each kept row.
    h_m : (R,) m
        Height of each kept row.
    source : str
        The file.
    error : str or None
        Why the track is left out (fewer than two fixes, ...).
    """

    track_id: str
    gnss: GnssData | None
    row_fix: np.ndarray
    t_text: list
    lines: np.ndarray
    h_m: np.ndarray
    source: str
    error: str | None = None

    @property
    def first_line(self) -> int:
        return int(self.lines[0]) if len(self.lines) else 0


@dataclass
class Fleet:
    """Tracks read from one or more files, in the order they first appear."""

    tracks: list = field(default_factory=list)
    time_form: str = "seconds"
    has_track_id: bool = False
    rows: int = 0

    def __len__(self) -> int:
        return len(self.tracks)

    @property
    def fixes(self) -> int:
        return int(sum(len(tr.gnss) for tr in self.tracks if tr.gnss is not None))


def _note(msg: str) -> None:
    warnings.warn(msg, SelfnavWarning, stacklevel=3)


# ------------------------------------------------------------------ columns
def _key(name) -> str:
    return re.sub(r"[^a-z0-9]", "", str(name).strip().strip('"').lower())


def _pick_columns(path, names, required, optional):
    """Map schema columns to header positions: ``{schema: (index, header name)}``."""
    index = {}
    for k, n in enumerate(names):
        index.setdefault(_key(n), k)
    found = {}
    for col in (*required, *optional):
        for alias in ALIASES.get(col, (col,)):
            if _key(alias) in index:
                j = index[_key(alias)]
                found[col] = (j, str(names[j]).strip())
                break
    if "track_id" in optional and "track_id" not in found:
        for alias in WEAK_TRACK_ID:
            if alias in index:
                found["track_id"] = (index[alias], f"{names[index[alias]]}?")
    missing = [c for c in required if c not in found]
    if missing:
        import difflib

        close = difflib.get_close_matches(missing[0], [str(n) for n in names], n=1, cutoff=0.6)
        hint = f" (found '{close[0]}': misnamed?)" if close else ""
        raise InputError(path, f"missing column '{missing[0]}'{hint}; the header has: "
                         f"{', '.join(str(n) for n in names)} (the schema: t, lat_deg, lon_deg"
                         "[, h_m, sigma_m, track_id])")
    return found


def _note_renamed(path, found):
    renamed = {c: a for c, (_, a) in found.items() if a != c}
    if renamed:
        _note(f"{path}: columns read as the schema's: " +
              ", ".join(f"'{a.rstrip('?')}' as {c}" for c, a in renamed.items()))


def _weak_track_id(found, cols):
    """A weak track id column (``id``) is kept only if its values repeat."""
    if found.get("track_id", (0, ""))[1].endswith("?"):
        vals = cols["track_id"]
        if len(set(vals)) > len(vals) / 2:
            del cols["track_id"], found["track_id"]
        else:
            j, name = found["track_id"]
            found["track_id"] = (j, name[:-1])


def _sniff_delimiter(header: str):
    counts = {d: header.count(d) for d in (",", ";", "\t", "|")}
    d = max(counts, key=counts.get)
    return d if counts[d] else None


def read_csv_columns(path, required, optional=()):
    """The wanted columns of a CSV as strings: ``({schema: [str]}, lines)``.

    ``#`` comment lines and blank lines are skipped; the delimiter (``,``, ``;``, tab, ``|``
    or white space) is taken from the header; quotes are honoured.
    """
    path = Path(path)
    text = open_text(path)
    raw = re.split(r"\r\n|\r|\n", text)     # Unix, Windows and old Mac line ends
    h = 0
    while h < len(raw) and (not raw[h].strip() or raw[h].lstrip().startswith("#")):
        h += 1
    if h == len(raw):
        raise InputError(path, "is empty (no header row and no data)")
    delim = _sniff_delimiter(raw[h])
    names = next(csv.reader([raw[h]], delimiter=delim)) if delim else raw[h].split()
    refuse_numeric_header(path, names, required, h + 1)
    found = _pick_columns(path, names, required, optional)
    keep = [k for k in range(h + 1, len(raw))
            if raw[k].strip() and not raw[k].lstrip().startswith("#")]
    if not keep:
        raise InputError(path, "has a header but no data rows")
    body = "\n".join(raw[k] for k in keep)
    try:
        rows = (list(csv.reader(io.StringIO(body), delimiter=delim)) if delim else
                [ln.split() for ln in body.split("\n")])
    except csv.Error as e:
        raise InputError(path, f"is not a readable CSV ({e}): a quote or a stray control "
                         "character in a field?") from None
    cols = {}
    for c, (j, _) in found.items():
        cols[c] = [r[j].strip() if j < len(r) else "" for r in rows]
    _weak_track_id(found, cols)
    _note_renamed(path, found)
    return cols, np.asarray(keep, np.int64) + 1


def read_parquet_columns(path, required, optional=()):
    """The wanted columns of a Parquet file: ``({schema: [str or float]}, row numbers)``.
    Time-stamp columns come back as ISO-8601 text."""
    path = Path(path)
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise InputError(path, "reading Parquet needs pyarrow: pip install 'selfnav[dask]' "
                         "(or pyarrow), or give a CSV") from None
    try:
        tab = pq.read_table(path)
    except (OSError, ValueError) as e:
        raise InputError(path, f"cannot be read as Parquet: {str(e).splitlines()[0]}") from None
    found = _pick_columns(path, tab.column_names, required, optional)
    cols = {}
    for c, (j, _) in found.items():
        col = tab.column(j)
        vals = col.to_pylist()
        if hasattr(col.type, "unit") and hasattr(col.type, "tz"):      # timestamp[unit, tz]
            vals = ["" if v is None else v.isoformat() for v in vals]
        else:
            vals = ["" if v is None else str(v) for v in vals]
        cols[c] = vals
    _weak_track_id(found, cols)
    _note_renamed(path, found)
    return cols, np.arange(1, tab.num_rows + 1, dtype=np.int64)


def read_columns(path, required, optional=()):
    """CSV or Parquet (by the suffix): ``({schema: [text]}, lines)``. A time column that holds
    clock times only (``08:33:24``) beside a ``date`` column is read as their date-time."""
    name = Path(path).name.lower()
    if name.endswith((".parquet", ".pq")):
        cols, lines = read_parquet_columns(path, required, (*optional, "date"))
    else:
        cols, lines = read_csv_columns(path, required, (*optional, "date"))
    date = cols.pop("date", None)
    if date is not None and "t" in cols:
        first = next((v for v in cols["t"] if v), "")
        if re.match(r"^\s*\d{1,2}:\d{2}", first):
            cols["t"] = [f"{d.strip()} {c.strip()}" for d, c in zip(date, cols["t"])]
            _note(f"{path}: columns 'date' and the time of day read together as t")
    return cols, lines


# ------------------------------------------------------------------ tracks
def _row_values(path, cols, lines, *, strict):
    """Numbers of every row; bad rows raise (``strict``) or are returned with their reason.

    A row without a readable time, latitude or longitude is bad. Height and ``sigma_m`` that
    cannot be read are errors when ``strict`` and otherwise unknown (NaN)."""
    n = len(lines)
    t, form, bad_t = parse_times(cols["t"])
    vals = {"t": t}
    reasons = {}
    soft = {}
    for k in bad_t:
        reasons.setdefault(int(k), ("t", f"'{cols['t'][k][:30]}' is not a time "
                                    f"({'an ISO-8601 date-time' if form == 'iso' else 'seconds'}"
                                    " like the first row)"))
    for c in cols:
        if c in ("t", "track_id"):
            continue
        v, bad = parse_numbers(cols[c])
        hard = strict or c in ("lat_deg", "lon_deg")
        for k in bad:
            if hard:
                reasons.setdefault(int(k), (c, f"'{cols[c][k][:30]}' is not a number"))
            soft[int(k), c] = True
        if c != "sigma_m":
            for k in np.flatnonzero(~np.isfinite(v)):
                if hard:
                    reasons.setdefault(int(k), (c, f"'{cols[c][k][:30]}' is not a finite "
                                                "number"))
                soft[int(k), c] = True
        vals[c] = v
    for k in np.flatnonzero(~np.isfinite(t)):
        reasons.setdefault(int(k), ("t", f"'{cols['t'][k][:30]}' is not a finite time"))
    lat, lon = vals["lat_deg"], vals["lon_deg"]
    for k in np.flatnonzero(np.isfinite(lat) & (np.abs(lat) > 90)):
        reasons.setdefault(int(k), ("lat_deg", f"{lat[k]} is not a latitude in degrees "
                                    "(radians? projected metres? swapped columns?)"))
    for k in np.flatnonzero(np.isfinite(lon) & (np.abs(lon) > 360)):
        reasons.setdefault(int(k), ("lon_deg", f"{lon[k]} is not a longitude in degrees"))
    for k in np.flatnonzero((lat == 0) & (lon == 0)):     # a logger's "no fix"
        reasons.setdefault(int(k), ("lat_deg", "latitude and longitude both 0: no fix"))
    if "sigma_m" in vals:
        sig = vals["sigma_m"]
        nonpos = np.flatnonzero(np.isfinite(sig) & ~(sig > 0))
        for k in nonpos:
            if strict:
                reasons.setdefault(int(k), ("sigma_m", f"sigma_m {sig[k]:g} must be positive"))
            soft[int(k), "sigma_m"] = True
        if len(nonpos) and not strict:
            k = int(nonpos[0])
            more = f" ({len(nonpos)} rows)" if len(nonpos) > 1 else ""
            warnings.warn(f"{path}, line {lines[k]}, column 'sigma_m': sigma_m {sig[k]:g} must be "
                          f"positive: taken as not given{more}", SelfnavWarning, stacklevel=3)
    if strict and reasons:
        k = min(reasons)
        c, msg = reasons[k]
        raise InputError(path, msg, row=int(lines[k]), column=c)
    for k, c in soft:                # unreadable height or sigma: unknown
        vals[c][k] = np.nan
    ok = np.ones(n, bool)
    ok[list(reasons)] = False
    return vals, form, ok, reasons


#: Positions in the same second farther than this apart (m; or 5 times their ``sigma_m``) do not
#: both hold: the one nearest its neighbouring fixes is kept instead of their mean.
REPEAT_AGREE_M = 20.0


def _merge_repeated(t, cols):
    """Fixes with the same time stamp merged: ``(t_unique, {col: value}, row -> fix, chosen)``.

    Positions that agree (within :data:`REPEAT_AGREE_M`, or 5 ``sigma_m``, of their median) are
    averaged; where they do not -- a good fix and a multipath one logged in the same second,
    whose mean would lie tens of metres off both --, the row nearest the midpoint of the
    neighbouring fixes (the one neighbour at a track's end) is kept. ``chosen`` counts those."""
    tu, inv = np.unique(t, return_inverse=True)
    if len(tu) == len(t):
        return tu, dict(cols), inv, 0
    out = {}
    for c, v in cols.items():           # unknown values (NaN) left out of the mean
        ok = np.isfinite(v)
        cnt = np.bincount(inv[ok], minlength=len(tu))
        s = np.bincount(inv[ok], weights=v[ok], minlength=len(tu))
        out[c] = np.where(cnt > 0, s / np.maximum(cnt, 1), np.nan)
    if "lat_deg" not in cols or "lon_deg" not in cols or len(tu) < 2:
        return tu, out, inv, 0
    lat, lon = np.radians(cols["lat_deg"]), np.radians(cols["lon_deg"])
    lat0, lon0 = float(lat[0]), float(lon[0])

    def local(la, lo):                  # east, north m from the track's first row
        return enu_offset(lat0, lon0, 0.0, la, lo, 0.0)[..., :2]

    sig = np.asarray(cols.get("sigma_m", np.full(len(t), np.nan)), float)
    lat_mean, lon_mean = np.radians(out["lat_deg"]), np.radians(out["lon_deg"])   # as merged
    chosen = 0
    for j in np.flatnonzero(np.bincount(inv) > 1):
        rows = np.flatnonzero(inv == j)
        en = local(lat[rows], lon[rows])
        s = sig[rows]
        agree = max(REPEAT_AGREE_M, 5 * np.nanmax(s)) if np.isfinite(s).any() else REPEAT_AGREE_M
        if not np.all(np.hypot(*(en - np.median(en, axis=0)).T) <= agree):
            nb = [k for k in (j - 1, j + 1) if 0 <= k < len(tu)]
            nb_en = local(lat_mean[nb], lon_mean[nb])
            keep = rows[np.argmin(np.hypot(*(en - nb_en.mean(axis=0)).T))]
            for c, v in cols.items():
                out[c][j] = v[keep]
            chosen += 1
    return tu, out, inv, chosen


def merged_note(counts) -> str:
    """The words for the repeated stamps of ``counts`` (as :func:`build_tracks` returns)."""
    chosen = (f"; at {counts['chosen']} the positions disagreed by more than "
              f"{REPEAT_AGREE_M:.0f} m and the one nearest its neighbours was kept"
              if counts.get("chosen") else "")
    return f"{counts['merged']} repeated time stamps merged (positions averaged{chosen})"


def to_wgs84(lat, lon, h, datum, path=None):
    """Positions (rad, m) in ``datum`` to WGS-84."""
    d = (datum or "wgs84").lower().replace("-", "").replace(".", "").replace("_", "")
    if d == "wgs84":
        return lat, lon, h
    out = dm.convert(lat, lon, h, d, "wgs84")
    return np.asarray(out[0]), np.asarray(out[1]), np.asarray(out[2])


def build_tracks(path, cols, lines, *, datum="wgs84", strict=False, default_id=None,
                 velocity=False):
    """Rows to tracks: group by ``track_id``, order by time, merge repeated stamps.

    Returns ``(tracks, form, counts)`` with ``counts`` the numbers of merged and reordered rows
    and of skipped rows.
    """
    vals, form, ok, reasons = _row_values(path, cols, lines, strict=strict)
    n = len(lines)
    if "track_id" in cols:
        ids = np.asarray(cols["track_id"], dtype=object)
        uid, first, inv = np.unique(ids.astype(str), return_index=True, return_inverse=True)
        groups = _groups(uid, inv, np.argsort(first, kind="stable"))
    else:
        groups = [(default_id or Path(path).stem, np.arange(n))]
    tracks = []
    counts = {"merged": 0, "reordered": 0, "skipped": 0, "tracks_merged": 0,
              "tracks_reordered": 0, "chosen": 0}
    skipped_notes = []
    for tid, rows in groups:
        bad = rows[~ok[rows]]
        rows = rows[ok[rows]]
        if len(bad):
            counts["skipped"] += len(bad)
            c, msg = reasons[int(bad[0])]
            more = f" ({len(bad)} rows skipped, this is the first)" if len(bad) > 1 else \
                " (row skipped)"
            skipped_notes.append(f"{path}, line {lines[bad[0]]}, track '{tid}', column '{c}': "
                                 f"{msg}{more}")
        t = vals["t"][rows]
        if len(rows) and np.any(np.diff(t) < 0):
            counts["reordered"] += int(np.sum(np.diff(t) < 0))
            counts["tracks_reordered"] += 1
        o = np.argsort(t, kind="stable")
        rows, t = rows[o], t[o]
        num = {c: vals[c][rows] for c in ("lat_deg", "lon_deg", "h_m", "sigma_m", "ve", "vn",
                                          "vu") if c in vals}
        tu, merged, inv, chosen = _merge_repeated(t, num)
        if len(tu) < len(t):
            counts["merged"] += len(t) - len(tu)
            counts["tracks_merged"] += 1
            counts["chosen"] += chosen
        h_rows = num.get("h_m", np.full(len(rows), np.nan))
        t_text = [cols["t"][k] for k in rows]
        error = None
        gnss = None
        if len(tu) < 2:
            error = (f"{path}, line {lines[rows[0]] if len(rows) else lines[bad[0]]}, track "
                     f"'{tid}': {'only one fix' if len(tu) == 1 else 'no readable fix'}: "
                     "nothing to match")
        else:
            lat, lon, h = to_wgs84(np.radians(merged["lat_deg"]), np.radians(merged["lon_deg"]),
                                    merged.get("h_m", np.zeros(len(tu))), datum)
            vel = None
            if velocity and all(c in merged for c in ("ve", "vn", "vu")):
                vel = np.column_stack([merged["ve"], merged["vn"], merged["vu"]])
            gnss = GnssData(tu, lat, lon, np.asarray(h, float), merged.get("sigma_m"), vel, None,
                            f"{path}#{tid}" if "track_id" in cols else str(path))
        tracks.append(FleetTrack(tid, gnss, inv, t_text, lines[rows], h_rows, str(path), error))
    hint = radians_hint(vals["lat_deg"][ok], vals["lon_deg"][ok])
    if hint:
        _note(f"{path}: {hint}")
    for k, msg in enumerate(skipped_notes):
        if k == MAX_TRACK_NOTES:
            _note(f"{path}: {len(skipped_notes) - k} more tracks with skipped rows")
            break
        _note(msg)
    return tracks, form, counts


def radians_hint(lat_deg, lon_deg) -> str | None:
    """A note when positions given as degrees look like radians: every latitude within ±π/2,
    every longitude within ±π, and all of them within 0.01 of each other (as degrees, a 1 km
    square near 0° N 0° E; as radians, a 60 km area anywhere). None otherwise."""
    lat, lon = np.asarray(lat_deg, float), np.asarray(lon_deg, float)
    lat, lon = lat[np.isfinite(lat)], lon[np.isfinite(lon)]
    if len(lat) < 2 or len(lon) < 2:
        return None
    if np.max(np.abs(lat)) > np.pi / 2 or np.max(np.abs(lon)) > np.pi:
        return None
    span = max(np.ptp(lat), np.ptp(lon))
    if span >= 0.01:
        return None
    return (f"every lat_deg lies within ±π/2 and every lon_deg within ±π, {span:.2g} apart at "
            f"most: they look like radians (lat {lat[0]:.6g} rad is {np.degrees(lat[0]):.5g}°), "
            "the file needs degrees")


def _groups(uid, inv, order):
    srt = np.argsort(inv, kind="stable")
    bounds = np.searchsorted(inv[srt], np.arange(len(uid) + 1))
    return [(str(uid[g]), srt[bounds[g]:bounds[g + 1]]) for g in order]


def fleet_files(paths):
    """The files of ``paths`` (files, or folders: their CSV / Parquet files, sorted)."""
    out = []
    for p in paths if isinstance(paths, (list, tuple)) else [paths]:
        p = Path(p)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.is_file() and q.name.lower().endswith(
                SUFFIXES))
            if not found:
                raise InputError(p, f"folder holds no track file ({', '.join(SUFFIXES)})")
            out += found
        elif not p.exists():
            raise InputError(p, "no such file")
        else:
            out.append(p)
    return out


def read_fleet(paths, *, datum: str = "wgs84") -> Fleet:
    """Read fleet GNSS files (CSV or Parquet; files or folders) into tracks.

    Parameters
    ----------
    paths : path or list of paths
    datum : str
        Datum of the positions (converted to WGS-84).

    Returns
    -------
    Fleet
        Tracks in order of first appearance; tracks that cannot be matched carry ``error``.
    """
    fleet = Fleet()
    forms = set()
    total = {"merged": 0, "reordered": 0, "tracks_merged": 0, "tracks_reordered": 0,
             "chosen": 0}
    for f in fleet_files(paths):
        cols, lines = read_columns(f, ("t", "lat_deg", "lon_deg"),
                                   ("h_m", "sigma_m", "track_id"))
        tracks, form, counts = build_tracks(f, cols, lines, datum=datum)
        fleet.has_track_id |= "track_id" in cols
        fleet.tracks += tracks
        fleet.rows += len(lines)
        forms.add(form)
        for k in total:
            total[k] += counts[k]
    fleet.time_form = "iso" if forms == {"iso"} else ("seconds" if "iso" not in forms else
                                                         "mixed")
    if total["merged"]:
        _note(f"{merged_note(total)} in {total['tracks_merged']} tracks")
    if total["reordered"]:
        _note(f"rows out of time order in {total['tracks_reordered']} tracks ordered by time "
              f"({total['reordered']} steps back)")
    return fleet


# ------------------------------------------------------------------ output
def _fmt(values, spec, empty=""):
    v = np.asarray(values, float)
    ok = np.isfinite(v)
    if ok.all():                          # Python floats format several times faster
        return [spec % x for x in v.tolist()]
    return [spec % x if o else empty for x, o in zip(v.tolist(), ok.tolist())]


class FleetWriter:
    """Matched fixes to CSV (header row, no ``#`` lines) or Parquet, streamed track by track
    and moved into place only when complete (nothing half-written on failure), with a JSON
    sidecar ``<path>.json`` (what produced the file: ``notes``, ``columns``).

    Columns: ``[track_id,] t, lat_deg, lon_deg, h_m, cross_m, way_id, matched, match_p,
    piece``; ``t`` is the input's text (seconds or ISO-8601, as it came).
    """

    def __init__(self, path, *, track_id: bool, comments=()):
        self.path = Path(path)
        self.track_id = track_id
        self.comments = list(comments)
        self.rows = 0
        name = self.path.name.lower()
        self.parquet = name.endswith((".parquet", ".pq"))
        if not (self.parquet or name.endswith((".csv", ".csv.gz", ".txt"))):
            raise InputError(self.path, "output must end in .csv or .parquet")
        if self.parquet:
            try:
                import pyarrow  # noqa: F401
            except ImportError:
                raise InputError(self.path, "writing Parquet needs pyarrow: pip install "
                                 "'selfnav[dask]', or write a .csv") from None

    def __enter__(self):
        import contextlib

        from selfnav.io.csvio import sidecar_path
        from selfnav.io.jsonio import dumps
        from selfnav.io.output import atomic_paths

        self._stack = contextlib.ExitStack()
        self._tmp, tmp_side = self._stack.enter_context(
            atomic_paths(self.path, sidecar_path(self.path)))
        names = (["track_id"] if self.track_id else []) + ["t", "lat_deg", "lon_deg", "h_m",
                                                           "cross_m", "way_id", "matched",
                                                           "match_p", "piece"]
        # what produced the file goes into the JSON sidecar <out>.json: the CSV starts with
        # its header row (a plain pandas.read_csv reads it)
        Path(tmp_side).write_text(dumps({"format": "selfnav match", "notes": self.comments,
                                         "columns": names}) + "\n", encoding="utf-8")
        if self.parquet:
            self._batch = []
            self._pq = None
        else:
            self._fh = self._stack.enter_context(open(self._tmp, "w", newline="\n"))
            self._fh.write(",".join(names) + "\n")
        return self

    def write(self, track_id, t_text, lat_deg, lon_deg, h_m, cross_m, way_id, matched,
              match_p=None, piece=None):
        """Rows of one track (arrays of equal length)."""
        n = len(t_text)
        self.rows += n
        match_p = np.full(n, np.nan) if match_p is None else np.asarray(match_p, float)
        piece = np.zeros(n, np.int64) if piece is None else np.asarray(piece, np.int64)
        if self.parquet:
            self._batch.append((track_id, t_text, lat_deg, lon_deg, h_m, cross_m, way_id,
                                matched, match_p, piece))
            if sum(len(b[1]) for b in self._batch) >= 65536:
                self._flush()
            return
        cols = [list(t_text), _fmt(lat_deg, "%.9f"), _fmt(lon_deg, "%.9f"), _fmt(h_m, "%.3f"),
                _fmt(cross_m, "%.3f"), [str(w) for w in np.asarray(way_id, np.int64).tolist()],
                ["1" if m else "0" for m in np.asarray(matched, bool).tolist()],
                _fmt(match_p, "%.4f"), [str(p) for p in piece.tolist()]]
        if self.track_id:
            tid = _csv_field(str(track_id))
            cols.insert(0, [tid] * n)
        self._fh.write("".join(",".join(r) + "\n" for r in zip(*cols)))

    def _flush(self):
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not self._batch:
            return
        num = ("lat_deg", "lon_deg", "h_m", "cross_m", "way_id", "matched", "match_p", "piece")
        cat = {k: [] for k in ("track_id", "t", *num)}
        for tid, *cols in self._batch:
            cat["track_id"] += [str(tid)] * len(cols[0])
            cat["t"] += list(cols[0])
            for k, v in zip(num, cols[1:]):
                cat[k].append(np.asarray(v))
        arrays = {k: (pa.array(v) if k in ("track_id", "t") else pa.array(np.concatenate(v)))
                  for k, v in cat.items()}
        if not self.track_id:
            arrays.pop("track_id")
        tab = pa.table(arrays)
        if self._pq is None:
            tab = tab.replace_schema_metadata({b"selfnav": "\n".join(self.comments).encode()})
            self._pq = pq.ParquetWriter(self._tmp, tab.schema)
        self._pq.write_table(tab.cast(self._pq.schema))
        self._batch = []

    def __exit__(self, kind, value, tb):
        try:
            if self.parquet and kind is None:
                self._flush()
                if self._pq is None:            # no rows: an empty file with the schema
                    self._batch = [("", [], np.zeros(0), np.zeros(0), np.zeros(0),
                                    np.zeros(0), np.zeros(0, np.int64), np.zeros(0, bool))]
                    self._flush()
            if self.parquet and self._pq is not None:
                self._pq.close()
        finally:
            return self._stack.__exit__(kind, value, tb)


def _csv_field(s: str) -> str:
    return '"' + s.replace('"', '""') + '"' if any(c in s for c in ',"\n') else s


class RouteWriter:
    """Driven routes to GeoJSON (a FeatureCollection, one Feature per track), streamed and
    moved into place when complete. A track whose matched chain breaks gets a MultiLineString.
    """

    def __init__(self, path, *, comment=""):
        self.path = Path(path)
        self.comment = comment
        self.count = 0

    def __enter__(self):
        import contextlib

        from selfnav.io.csvio import atomic_path

        self._stack = contextlib.ExitStack()
        tmp = self._stack.enter_context(atomic_path(self.path))
        self._fh = self._stack.enter_context(open(tmp, "w", newline="\n"))
        import json

        self._json = json
        self._fh.write('{"type": "FeatureCollection", ')
        if self.comment:
            self._fh.write(f'"selfnav": {json.dumps(self.comment)}, ')
        self._fh.write('"features": [\n')
        return self

    def write(self, track_id, pieces, properties=None):
        """``pieces``: list of (lat (M,), lon (M,) rad, way ids) — the driven route."""
        lines, ways = [], []
        for lat, lon, way in pieces:
            coords = np.column_stack([np.degrees(lon), np.degrees(lat)]).round(8).tolist()
            if len(coords) >= 2:
                lines.append(coords)
            w = np.asarray(way, np.int64)
            keep = np.ones(len(w), bool)
            keep[1:] = w[1:] != w[:-1]
            ways += w[keep].tolist()
        if not lines:
            geom = None
        elif len(lines) == 1:
            geom = {"type": "LineString", "coordinates": lines[0]}
        else:
            geom = {"type": "MultiLineString", "coordinates": lines}
        w = np.asarray(ways, np.int64)
        keep = np.ones(len(w), bool)
        keep[1:] = w[1:] != w[:-1]
        props = {"track_id": str(track_id), "way_ids": w[keep].tolist(), **(properties or {})}
        feat = {"type": "Feature", "geometry": geom, "properties": props}
        self._fh.write(("" if self.count == 0 else ",\n") + self._json.dumps(feat))
        self.count += 1

    def __exit__(self, kind, value, tb):
        if kind is None:
            self._fh.write("\n]}\n")
        return self._stack.__exit__(kind, value, tb)
