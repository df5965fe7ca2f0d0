"""What a navigator or matcher returns: a trajectory with its σ, per-row status and a summary.

:class:`Solution` is the one output type of the Python API (:func:`selfnav.navigate`,
:func:`selfnav.match`): radians and SI inside (``trajectory``), degrees at the edges
(``lat_deg``, ``lon_deg``, :meth:`Solution.to_csv`). The CSV is the solution file of DESIGN §6:
``t, lat_deg, lon_deg, h_m`` then, where known, ``ve, vn, vu, roll_deg, pitch_deg,
heading_deg``, the position σ and any extra per-row columns (:data:`COLUMN_DOCS`). The CSV
starts with its header row (a plain ``pandas.read_csv`` reads it); what produced it — the
command, the datum, the run's summary — is in the JSON sidecar ``<file>.json``
(:func:`selfnav.io.csvio.sidecar_path`). :func:`read_solution` reads both back, every column
included, and still reads older files whose metadata are ``#`` lines.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from selfnav import __version__
from selfnav import datum as dm
from selfnav.errors import SelfnavError
from selfnav.io.csvio import header_names, read_columns, read_sidecar, write_csv
from selfnav.io.trajectory import TRUTH_COLUMNS, read_truth, trajectory_columns
from selfnav.types import Trajectory

#: per-row columns of a solution file besides the trajectory's, with their CSV formats
EXTRA_FORMATS = {"sigma_e_m": "%.4f", "sigma_n_m": "%.4f", "sigma_u_m": "%.4f",
                 "sigma_h_m": "%.4f", "protection_level_m": "%.3f", "cross_m": "%.3f"}

#: what each column of a solution file holds, with its unit (written into the sidecar)
COLUMN_DOCS = {
    "t": "time, s (the IMU's clock, after the IMU time offset; GNSS time for match)",
    "lat_deg": "latitude, deg (in the datum of the sidecar's 'datum')",
    "lon_deg": "longitude, deg", "h_m": "ellipsoidal height, m",
    "ve": "velocity East, m/s", "vn": "velocity North, m/s", "vu": "velocity Up, m/s",
    "roll_deg": "roll, deg", "pitch_deg": "pitch, deg",
    "heading_deg": "heading, deg clockwise from North",
    "sigma_e_m": "1σ of the position East, m", "sigma_n_m": "1σ of the position North, m",
    "sigma_u_m": "1σ of the position Up, m",
    "sigma_h_m": "horizontal 1σ, m (root sum of the East and North variances)",
    "status": "the navigator's state at this row (selfnav.ins.NavStatus): gnss (a fix fused "
              "within the hold time), dead-reckoning (none fused: an outage or rejected "
              "fixes), suspect (a fault episode is open: fixes and INS disagree)",
    "protection_level_m": "horizontal protection level at the configured integrity risk "
                          "(1e-5 by default), m",
    "gnss": "status of the latest GNSS fix (files of selfnav 0.2)",
    "cross_m": "distance from the fix to its matched road position, m",
    "way_id": "OpenStreetMap way matched",
    "matched": "1 where the match is plausible (match_p >= 0.7, near its road, not a lone fix)",
    "match_p": "posterior probability that the matched point is on the driven road",
    "piece": "index of the track's piece (the matcher broke and restarted between pieces)",
    "sigma_lat_deg": "1σ of the latitude, deg", "sigma_lon_deg": "1σ of the longitude, deg",
}

#: the sidecar's format name and version (read_solution checks the name)
SIDECAR_FORMAT = "selfnav solution"


@dataclass
class Solution:
    """A navigation or matching result.

    Attributes
    ----------
    trajectory : Trajectory
        Position (WGS-84, rad), velocity (ENU, NaN if unknown), attitude ``C_nb`` (NaN if
        unknown) at each output time.
    sigma_enu : (N, 3) or None
        Position σ, ENU m (None: the method has no covariance).
    columns : dict
        Extra per-row columns ``{name: (N,) array}`` written after the standard ones
        (numbers, or text such as the ``gnss`` status).
    stats : dict
        Summary of the run (counts, offsets estimated, ...): what ``--json`` prints.
    method : str
        What produced it (``"ekf"``, ``"ekf+map"``, ``"seed"``, ``"hmm"``; ``"file"`` when
        read from a file without a sidecar).
    detail : object
        The method's own full result (e.g. :class:`selfnav.ins.FilterResult`), or None.
    """

    trajectory: Trajectory
    sigma_enu: np.ndarray | None = None
    columns: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    method: str = ""
    detail: object = None

    def __len__(self) -> int:
        return len(self.trajectory.t)

    @property
    def t(self) -> np.ndarray:
        return self.trajectory.t

    @property
    def lat_deg(self) -> np.ndarray:
        return np.degrees(self.trajectory.lat)

    @property
    def lon_deg(self) -> np.ndarray:
        return np.degrees(self.trajectory.lon)

    @property
    def h_m(self) -> np.ndarray:
        return self.trajectory.h

    def table(self, datum: str = "wgs84") -> dict:
        """The solution file's columns ``{name: array}`` (positions in ``datum``)."""
        tr = self.trajectory
        lat, lon, h = tr.lat, tr.lon, tr.h
        if dm.datum_key(datum) != "wgs84":
            lat, lon, h = dm.convert(lat, lon, h, "wgs84", datum)
        cols = trajectory_columns(tr, lat, lon, h)
        if self.sigma_enu is not None:
            cols.update(sigma_e_m=self.sigma_enu[:, 0], sigma_n_m=self.sigma_enu[:, 1],
                        sigma_u_m=self.sigma_enu[:, 2])
        cols.update(self.columns)
        return cols

    def to_pandas(self, datum: str = "wgs84"):
        """The solution file's columns as a :class:`pandas.DataFrame` (one row per epoch, the
        columns of :meth:`table`, degrees at the edges); ``df.attrs`` holds ``method`` and
        ``stats``. Needs pandas (``pip install 'selfnav[results]'``)."""
        try:
            import pandas as pd
        except ImportError:
            raise SelfnavError("Solution.to_pandas needs pandas: pip install "
                               "'selfnav[results]' (or pandas)") from None
        df = pd.DataFrame({k: np.asarray(v) for k, v in self.table(datum).items()})
        df.attrs.update(method=self.method, stats=dict(self.stats), datum=dm.datum_key(datum))
        return df

    def sidecar(self, datum: str = "wgs84", notes=()) -> dict:
        """The metadata written beside the CSV (``<file>.json``): what produced it, the datum,
        each column's meaning and unit, and the run's summary (``stats``)."""
        cols = list(self.table(datum))
        return {"format": SIDECAR_FORMAT, "selfnav_version": __version__,
                "method": self.method, "datum": dm.datum_key(datum), "notes": list(notes),
                "columns": {c: COLUMN_DOCS.get(c, "") for c in cols},
                "stats": self.stats}

    def to_csv(self, path, *, datum: str = "wgs84", comments=()) -> Path:
        """Write the solution file atomically (DESIGN §6) with its JSON sidecar
        ``<path>.json`` (``comments`` go there as ``notes``); returns the path."""
        fmt = {"t": "%.6f", "lat_deg": "%.9f", "lon_deg": "%.9f", "h_m": "%.3f",
               **EXTRA_FORMATS}
        return write_csv(path, self.table(datum), fmt=fmt,
                         sidecar=self.sidecar(datum, comments))


def _datum_of(path, side: dict) -> str:
    """The datum a solution file's positions are in: its sidecar's, else an old file's
    ``# datum X`` comment line, else WGS-84."""
    if side.get("datum"):
        return dm.datum_key(side["datum"])
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if not line.startswith("#"):
                    break
                words = line[1:].split()
                if len(words) == 2 and words[0] == "datum":
                    return dm.datum_key(words[1])
    except (OSError, ValueError):
        pass
    return "wgs84"


def read_solution(path) -> Solution:
    """Read a solution (or truth) CSV with every column it has.

    ``t, lat_deg, lon_deg, h_m`` (and velocity, attitude where present) become the
    trajectory, in WGS-84 (positions written in another datum are converted back);
    ``sigma_e_m, sigma_n_m, sigma_u_m`` become ``sigma_enu``; every other column (``sigma_h_m``,
    the ``gnss`` status, ``cross_m``, any extra) goes to ``columns``, as numbers or text. The
    JSON sidecar ``<path>.json``, when present, gives ``method`` and ``stats``. Older files
    with ``#`` comment lines are read too; an RTKLIB ``.pos`` or PSINS avp file is read as a
    trajectory only.
    """
    tr = read_truth(path)
    names = header_names(path) if not str(path).lower().endswith(".pos") else []
    if "t" not in names:
        return Solution(tr, None, {}, {}, "file")     # a reference in another format
    side = read_sidecar(path)
    if side.get("format") != SIDECAR_FORMAT:
        side = {}
    datum = _datum_of(path, side)
    if datum != "wgs84":
        lat, lon, h = dm.convert(tr.lat, tr.lon, tr.h, datum, "wgs84")
        tr = Trajectory(tr.t, lat, lon, h, tr.velocity_n, tr.C_nb, source=tr.source)
    extra = read_columns(path, [n for n in names if n not in TRUTH_COLUMNS])
    sig = None
    if all(k in extra for k in ("sigma_e_m", "sigma_n_m", "sigma_u_m")):
        sig = np.column_stack([np.asarray(extra.pop(k), float)
                               for k in ("sigma_e_m", "sigma_n_m", "sigma_u_m")])
    return Solution(tr, sig, extra, dict(side.get("stats", {})), side.get("method", "file"))


__all__ = ["Solution", "read_solution", "TRUTH_COLUMNS", "COLUMN_DOCS"]
