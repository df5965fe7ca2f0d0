"""Native CSV files (DESIGN §6): header row, ``#`` comments, extra columns kept and ignored.

Reading validates shape and values and names the line and column of the first problem; writing
goes through :mod:`selfnav.io.output` (a temporary file moved into place, through symlinks, never
over special files), so nothing is left half-written.
"""
from __future__ import annotations

import difflib
import gzip
import io
import re
from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.io.output import atomic_path, atomic_write_bytes, check_output_file  # noqa: F401


def open_text(path: Path) -> str:
    """The text of a file (UTF-8, gzip-compressed or not), or one line saying why not."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except IsADirectoryError:
        raise InputError(path, "is a folder, not a file") from None
    except OSError as e:
        raise InputError(path, f"cannot be read ({e.strerror})") from None
    if path.suffix == ".gz" or raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError):      # EOFError: truncated (the CLI would take it for Ctrl-D)
            raise InputError(path, "looks gzip-compressed but cannot be decompressed") from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(path, "is not a text file (not UTF-8): is it a binary log?") from None


def _is_plain_text(path: Path) -> bool:
    """True when the file on disk is not gzip-compressed (numpy can then read it directly)."""
    if path.suffix == ".gz":
        return False
    try:
        with open(path, "rb") as fh:
            return fh.read(2) != b"\x1f\x8b"
    except OSError:
        return False


class _LineNumbers:
    """1-based file line number of each data row, worked out only when someone asks."""

    def __init__(self, body: str, first_line: int):
        self._body, self._first, self._arr = body, first_line, None

    def _array(self):
        if self._arr is None:
            nums = [self._first + i for i, ln in enumerate(self._body.split("\n"))
                    if ln.strip() and not ln.lstrip().startswith("#")]
            self._arr = np.asarray(nums, dtype=int)
        return self._arr

    def __getitem__(self, k):
        return self._array()[k]

    def __len__(self):
        return len(self._array())

    def __array__(self, dtype=None, copy=None):
        a = self._array()
        return a if dtype is None else a.astype(dtype)


def refuse_numeric_header(path, names, required, row):
    """One line when the first non-comment line of a table holds numbers, not column names."""
    try:
        float(names[0])
    except ValueError:
        return
    raise InputError(path, "the first line holds numbers, not column names: add a header row "
                     f"({', '.join(required)})", row=row)


def read_table(path, required, optional=(), *, numeric=True):
    """Read a CSV table with a header row.

    Parameters
    ----------
    path : str or Path
    required : sequence of str
        Column names that must be present (case-insensitive, surrounding spaces ignored).
    optional : sequence of str
        Column names returned when present.

    Returns
    -------
    dict
        ``{name: float64 array}`` for the required and present optional columns; the key
        ``"_lines"`` gives the 1-based file line number of each data row (indexable).
    """
    path = Path(path)
    text = open_text(path)
    plain = _is_plain_text(path) and not text.startswith("\ufeff") and "\r" not in text[:4096]
    pos, line_no = 0, 0
    header_line = None
    while pos < len(text):
        nl = text.find("\n", pos)
        nl = len(text) if nl < 0 else nl
        s = text[pos:nl].strip()
        line_no += 1
        pos = nl + 1
        if s and not s.startswith("#"):
            header_line = s
            break
    if header_line is None:
        raise InputError(path, "is empty (no header row and no data)")
    header_idx = line_no - 1
    delim = "," if "," in header_line else None
    names = [h.strip().lower() for h in (header_line.split(delim) if delim else header_line.split())]
    refuse_numeric_header(path, names, required, header_idx + 1)
    index = {}
    for k, n in enumerate(names):
        index.setdefault(n, k)
    for col in required:
        if col not in index:
            close = difflib.get_close_matches(col, names, n=1, cutoff=0.6)
            hint = f" (found '{close[0]}': misnamed?)" if close else ""
            raise InputError(path, f"missing column '{col}'{hint}; the header has: "
                             f"{', '.join(names)}", row=header_idx + 1)
    wanted = list(required) + [c for c in optional if c in index]
    body = text[pos:] if pos <= len(text) else ""
    lines = _LineNumbers(body, header_idx + 2)
    if re.search(r"^[ \t]*[^#\s]", body, re.M) is None:
        raise InputError(path, "has a header but no data rows")
    ncol = len(names)
    usecols = [index[c] for c in wanted]
    try:
        if plain:  # numpy reads a file faster than a string buffer (about 1.0 s vs 1.6 s / 720k rows)
            arr = np.loadtxt(path, delimiter=delim, usecols=usecols, ndmin=2, comments="#",
                             dtype=float, skiprows=header_idx + 1, encoding="utf-8-sig")
        else:
            arr = np.loadtxt(io.StringIO(body), delimiter=delim, usecols=usecols, ndmin=2,
                             comments="#", dtype=float)
    except ValueError:
        arr = None
    if arr is None:
        body, arr = _without_partial_ends(path, body, delim, ncol, usecols, lines)
    if arr is None:
        # find the first offending row for a precise message
        data_lines = [ln for ln in body.split("\n") if ln.strip() and not ln.lstrip().startswith("#")]
        for k, line in enumerate(data_lines):
            parts = [p.strip() for p in (line.split(delim) if delim else line.split())]
            if len(parts) < ncol and max(usecols) >= len(parts):
                raise InputError(path, f"has {len(parts)} fields where the header has {ncol}",
                                 row=int(lines[k]))
            for c in wanted:
                v = parts[index[c]]
                try:
                    float(v)
                except ValueError:
                    raise InputError(path, f"value '{v[:20]}' is not a number", row=int(lines[k]),
                                     column=c) from None
        raise InputError(path, "cannot be parsed as a numeric CSV table")
    if arr.shape[0] == 0:
        raise InputError(path, "has a header but no data rows")
    out = {}
    bad_rows = ~np.isfinite(arr)
    for j, c in enumerate(wanted):
        col = arr[:, j]
        if bad_rows[:, j].any():
            k = int(np.argmax(bad_rows[:, j]))
            raise InputError(path, f"value {col[k]} (NaN or infinite): remove or repair the row",
                             row=int(lines[k]), column=c)
        out[c] = np.ascontiguousarray(col)
    out["_lines"] = lines
    out["_path"] = str(path)
    return out


def _row_ok(line, delim, ncol, usecols):
    parts = [p.strip() for p in (line.split(delim) if delim else line.split())]
    if len(parts) < ncol:
        return False
    try:
        [float(parts[c]) for c in usecols]
    except ValueError:
        return False
    return True


def _without_partial_ends(path, body, delim, ncol, usecols, lines):
    """A logger cut off mid-line leaves a partial first or last data row: each is skipped
    (turned into a comment, so the line numbers stay) with one warning, and the table read
    again. Returns ``(body, array or None)``; None when the problem lies elsewhere."""
    from selfnav.errors import warn

    rows = body.split("\n")
    data = [i for i, ln in enumerate(rows) if ln.strip() and not ln.lstrip().startswith("#")]
    if len(data) < 3:
        return body, None
    cut = [i for i in {data[0], data[-1]} if not _row_ok(rows[i], delim, ncol, usecols)]
    if not cut:
        return body, None
    where = sorted(int(lines[data.index(i)]) for i in cut)
    for i in cut:
        rows[i] = "# (partial row skipped)"
    new = "\n".join(rows)
    try:
        arr = np.loadtxt(io.StringIO(new), delimiter=delim, usecols=usecols, ndmin=2,
                         comments="#", dtype=float)
    except ValueError:
        return body, None
    warn(f"{path}: line{'s' if len(where) > 1 else ''} {' and '.join(map(str, where))} "
         f"{'are partial rows' if len(where) > 1 else 'is a partial row'} (fewer fields or a "
         "number cut short: the logger started or stopped mid-line), skipped")
    return new, arr


def check_time(table, column="t", *, min_rows=1):
    """Check that the time column is strictly increasing; name the first offending row."""
    path = table["_path"]
    t = table[column]
    if len(t) < min_rows:
        raise InputError(path, f"has {len(t)} data rows; at least {min_rows} are needed")
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0)) + 1
        kind = "repeated" if d[k - 1] == 0 else "going backwards (unsorted)"
        raise InputError(path, f"time {float(t[k]):.10g} is {kind}: samples must be strictly "
                         "increasing",
                         row=int(table["_lines"][k]), column=column)
    return t


def sidecar_path(path) -> Path:
    """The JSON sidecar of a CSV file: ``sol.csv`` → ``sol.csv.json``."""
    path = Path(path)
    return path.with_name(path.name + ".json")


def read_sidecar(path) -> dict:
    """The JSON sidecar of ``path`` as a dict (empty when there is none or it is unreadable)."""
    import json

    try:
        return json.loads(sidecar_path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def write_csv(path, columns: dict, *, comments=(), fmt="%.10g", sidecar: dict | None = None):
    """Write named columns to ``path`` atomically (temporary file moved into place).

    Parameters
    ----------
    path : str or Path
    columns : dict
        ``{name: 1-D array}`` in output order, all the same length.
    comments : sequence of str
        Lines written first, each prefixed with ``# ``.
    fmt : str or dict
        printf format, or a ``{name: format}`` mapping.
    sidecar : dict, optional
        Metadata written as JSON to ``<path>.json`` (:func:`sidecar_path`), the pair moved into
        place together; the CSV itself then starts with its header row (a plain
        ``pandas.read_csv`` reads it).
    """
    if isinstance(path, str):
        check_output_file(path)       # 'newdir/' names a folder: refused, not written as a file
    path = Path(path)
    if sidecar is not None:
        from selfnav.io.jsonio import dumps
        from selfnav.io.output import atomic_paths

        side = sidecar_path(path)
        with atomic_paths(path, side) as (tmp, tmp_side):
            _write_rows(tmp, columns, comments, fmt)
            Path(tmp_side).write_text(dumps(sidecar, indent=2) + "\n", encoding="utf-8")
        return path
    with atomic_path(path) as tmp:
        _write_rows(tmp, columns, comments, fmt)
    return path


def _write_rows(tmp, columns: dict, comments, fmt) -> None:
    names = list(columns)
    arrs = [np.asarray(columns[n]) for n in names]
    n = {len(a) for a in arrs}
    if len(n) > 1:
        raise ValueError(f"columns of different lengths: {dict(zip(names, map(len, arrs)))}")
    text = [a.dtype.kind in "OUS" for a in arrs]
    fmts = ["%s" if txt else (fmt.get(k, "%.10g") if isinstance(fmt, dict) else fmt)
            for k, txt in zip(names, text)]
    with open(tmp, "w", newline="\n") as fh:
        for c in comments:
            fh.write(f"# {c}\n")
        fh.write(",".join(names) + "\n")
        if arrs and len(arrs[0]):
            if any(text):   # text columns (a status word): an object table keeps each type
                table = np.empty((len(arrs[0]), len(arrs)), dtype=object)
                for j, a in enumerate(arrs):
                    table[:, j] = a
            else:
                table = np.column_stack(arrs)
            np.savetxt(fh, table, delimiter=",", fmt=fmts)


def header_names(path) -> list:
    """The lower-case column names of a CSV (its first line that is not a ``#`` comment)."""
    text = open_text(Path(path))
    for line in text.split("\n"):
        s = line.strip()
        if s and not s.startswith("#"):
            delim = "," if "," in s else None
            return [h.strip().lower() for h in (s.split(delim) if delim else s.split())]
    return []


def read_columns(path, names) -> dict:
    """Columns ``names`` of a CSV with a header row, each as float64 when every value is a
    number, else as text (``object`` array of ``str``); ``#`` lines are skipped. For the few
    per-row status columns of a solution (the numeric bulk goes through :func:`read_table`)."""
    path = Path(path)
    text = open_text(path)
    lines = [ln for ln in text.split("\n") if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        return {}
    head = header_names(path)
    delim = "," if "," in lines[0] else None
    index = {n: k for k, n in reversed(list(enumerate(head)))}
    want = [n for n in names if n in index]
    if not want or len(lines) < 2:
        return {}
    rows = [ln.split(delim) if delim else ln.split() for ln in lines[1:]]
    out = {}
    for n in want:
        k = index[n]
        vals = [r[k].strip() if k < len(r) else "" for r in rows]
        try:
            out[n] = np.asarray(vals, dtype=float)
        except ValueError:
            out[n] = np.asarray(vals, dtype=object)
    return out


def check_positive(table, column):
    """Refuse a column with a value ≤ 0 (a σ, a length) naming the first such row; returns the
    column (or None when the table lacks it)."""
    x = table.get(column)
    if x is None:
        return None
    bad = ~(x > 0)
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(table["_path"], f"{column} {float(x[k]):g} must be positive",
                         row=int(table["_lines"][k]), column=column)
    return x


# ------------------------------------------------------------------ time columns
#: ISO-8601 date-times: ``2019-03-11T08:33:24``, optional fraction and zone (``Z``, ``+02:00``);
#: ``2019/03/11 08:33:24`` is read as the same
_ISO_HINT = re.compile(r"^\s*\d{4}[-/]?\d{2}[-/]?\d{2}[T ]")
_SLASH_DATE = re.compile(r"^(\s*\d{4})/(\d{2})/(\d{2})")


def parse_numbers(texts):
    """Strings to float64; returns ``(values, bad)`` with ``bad`` the indices of entries that
    are not numbers (empty strings count as bad; their values are NaN)."""
    texts = list(texts)
    try:
        vals = np.asarray(texts, dtype=float) if texts else np.zeros(0)
        return vals, np.zeros(0, np.int64)
    except ValueError:
        pass
    vals = np.full(len(texts), np.nan)
    bad = []
    for k, s in enumerate(texts):
        try:
            vals[k] = float(s)
        except (TypeError, ValueError):
            bad.append(k)
    return vals, np.asarray(bad, np.int64)


def parse_times(texts):
    """A time column as seconds: numbers (seconds; epoch milliseconds are recognised by their
    size) or ISO-8601 date-times (with a zone, or without one: then read as UTC).

    Returns
    -------
    t : (N,) float64 s (NaN where unreadable)
    form : {"seconds", "milliseconds", "iso"}
        What the column holds (decided by its first readable entry).
    bad : (K,) int
        Indices of entries that are not of that form.
    """
    import datetime as dt

    texts = list(texts)
    first = next((s for s in texts if s and s.strip()), "")
    if not _ISO_HINT.match(first):
        t, bad = parse_numbers(texts)
        ok = np.isfinite(t)
        if ok.any() and np.median(np.abs(t[ok])) > 1e11:      # after the year 5000 in seconds:
            return t / 1000.0, "milliseconds", bad            # epoch milliseconds
        return t, "seconds", bad
    t = np.full(len(texts), np.nan)
    bad = []
    utc = dt.timezone.utc
    for k, s in enumerate(texts):
        try:
            d = dt.datetime.fromisoformat(_SLASH_DATE.sub(r"\1-\2-\3", s.strip()))
        except (AttributeError, TypeError, ValueError):
            bad.append(k)
            continue
        if d.tzinfo is None:
            d = d.replace(tzinfo=utc)
        t[k] = d.timestamp()
    return t, "iso", np.asarray(bad, np.int64)
