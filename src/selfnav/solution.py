"""What a navigator or matcher returns: a trajectory with its σ, per-row status and a summary.

:class:`Solution` is the one output type of the Python API (:func:`selfnav.navigate`,
:func:`selfnav.match`): radians and SI inside (``trajectory``), degrees at the edges
(``lat_deg``, ``lon_deg``, :meth:`Solution.to_csv`). The CSV is the solution file of DESIGN §6:
``t, lat_deg, lon_deg, h_m`` then, where known, ``ve, vn, vu, roll_deg, pitch_deg,
heading_deg``, the position σ and any extra per-row columns.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from selfnav import datum as dm
from selfnav.io.csvio import read_table, write_csv
from selfnav.io.psins_mat import header_of
from selfnav.io.trajectory import TRUTH_COLUMNS, read_truth, trajectory_columns
from selfnav.types import Trajectory

#: per-row columns of a solution file besides the trajectory's, with their CSV formats
EXTRA_FORMATS = {"sigma_e_m": "%.4f", "sigma_n_m": "%.4f", "sigma_u_m": "%.4f",
                 "sigma_h_m": "%.4f", "cross_m": "%.3f"}


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
        Extra per-row columns ``{name: (N,) array}`` written after the standard ones.
    stats : dict
        Summary of the run (counts, offsets estimated, ...): what ``--json`` prints.
    method : str
        What produced it (``"ekf"``, ``"ekf+map"``, ``"seed"``, ``"hmm"``).
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

    def to_csv(self, path, *, datum: str = "wgs84", comments=()) -> Path:
        """Write the solution file atomically (DESIGN §6); returns the path."""
        fmt = {"t": "%.6f", "lat_deg": "%.9f", "lon_deg": "%.9f", "h_m": "%.3f",
               **EXTRA_FORMATS}
        return write_csv(path, self.table(datum), comments=[*comments, f"datum {datum}"],
                         fmt=fmt)


def read_solution(path) -> Solution:
    """Read a solution (or truth) CSV; ``sigma_e_m, sigma_n_m, sigma_u_m`` become ``sigma_enu``
    and other known per-row columns go to ``columns``."""
    tr = read_truth(path)
    if str(path).lower().endswith(".pos") or "t" not in header_of(path):
        return Solution(tr, None, {}, {}, "file")     # a reference in another format
    extra = read_table(path, ("t",), optional=tuple(EXTRA_FORMATS))
    sig = None
    if all(k in extra for k in ("sigma_e_m", "sigma_n_m", "sigma_u_m")):
        sig = np.column_stack([extra[k] for k in ("sigma_e_m", "sigma_n_m", "sigma_u_m")])
    cols = {k: extra[k] for k in ("sigma_h_m", "cross_m") if k in extra}
    return Solution(tr, sig, cols, {}, "file")


__all__ = ["Solution", "read_solution", "TRUTH_COLUMNS"]
