"""What a road map says about a track: is it where a car drives, or a car's path displaced?

The fault-hypothesis bank (:mod:`selfnav.ins.hypotheses`, issue 19) has two tracks it must
choose between when the fixes and the dead reckoning disagree by more than either's σ — the
fixes' and the INS's. Their own likelihoods cannot tell an INS that followed a drag (and carries
its rate since) from fixes that drag now: the two are mirror images. The map can: the car is on
a road, so the track that is the car's lies along roads within its σ, while the other is the
car's path moved by an offset, and lies on roads only as often as that path moved by a chance
offset does.

:func:`on_roads_llr` scores a track by ``L = Σ_i ln p_on(d_i)`` over points ``i`` at least
``spacing_m`` apart along it (nearby points see the same road), ``d_i`` the distance to the
nearest road and ``p_on(d) = (1 − ε) · 2 φ(d / s) / s + ε / D`` — half-normal of
``s = √(σ² + σ_road²)`` (the track's σ, the lane and digitising), a share ``ε`` off the map (a
car park, a road the map lacks) spread over ``D``. The points of a track are not independent:
moved together, a straight run lands whole on a parallel street. So ``L`` is taken against the
same shape moved by offsets of 40–300 m in every direction (128 copies):
``L − ln mean(e^L over the track and its copies)`` — about ``−ln q`` when a share ``q`` of the
copies fit the roads as well, at most ``ln 129 = 4.86``; a straight run in a street grid says
little, a run with turns that only its own roads fit says much, and a track whose σ is wider
than the street spacing says nothing.
"""
from __future__ import annotations

import math

import numpy as np

from selfnav.roads.graph import RoadGraph
from selfnav.roads.grid import nearest_distance

_SQRT2PI = math.sqrt(2.0 * math.pi)
_GOLDEN = math.pi * (3.0 - math.sqrt(5.0))


def thin_track(xy, spacing_m: float = 25.0, max_points: int = 12) -> np.ndarray:
    """Indices of points of a track, from the last back, each at least ``spacing_m`` (straight
    line) from the one kept after it; evenly thinned to ``max_points``."""
    xy = np.asarray(xy, float)
    if len(xy) == 0:
        return np.zeros(0, int)
    keep = [len(xy) - 1]
    for i in range(len(xy) - 2, -1, -1):
        if np.hypot(*(xy[i] - xy[keep[-1]])) >= spacing_m:
            keep.append(i)
    keep = np.array(keep[::-1])
    if len(keep) > max_points:
        keep = keep[np.unique(np.round(np.linspace(0, len(keep) - 1, max_points)).astype(int))]
    return keep


def shifts(n: int = 128, min_shift_m: float = 40.0, max_shift_m: float = 300.0) -> np.ndarray:
    """``n`` offsets (m, East/North) spread over the annulus ``min…max`` in every direction: a
    deterministic golden-angle spiral (the evidence is reproducible, the same each run)."""
    k = np.arange(n) + 0.5
    r = np.sqrt(min_shift_m**2 + (max_shift_m**2 - min_shift_m**2) * k / n)
    a = k * _GOLDEN
    return np.column_stack([r * np.sin(a), r * np.cos(a)])


#: m: the lane and the map's digitising — how far a car on a mapped road lies from its line
SIGMA_ROAD_M = 2.5


def on_roads_llr(graph: RoadGraph, xy, sigma_m: float, *, sigma_road_m: float = SIGMA_ROAD_M,
                 eps: float = 0.05, spread_m: float = 100.0, offsets=None) -> float:
    """Log-likelihood ratio of "the track ``xy`` (local East/North m of ``graph``, already thinned:
    :func:`thin_track`) is where the car drove, within ``sigma_m``" against "it is the car's
    path moved by an unknown offset" (module docstring): ``L(track) − ln mean(e^L)`` over the
    track and its moved copies. 0 for an empty track; at most ``ln(1 + copies)``.

    Parameters
    ----------
    graph : RoadGraph
    xy : (n, 2) local East/North, m
    sigma_m : the track's position σ, m
    sigma_road_m : the lane and the map's digitising, m
    eps, spread_m : the share of a car's positions off the mapped roads (a car park, a road
        the map lacks), spread uniformly over ``spread_m``
    offsets : (k, 2) m, the moved copies (default :func:`shifts`)
    """
    xy = np.atleast_2d(np.asarray(xy, float))
    if len(xy) == 0 or graph.n_segments == 0:
        return 0.0
    off = shifts() if offsets is None else np.asarray(offsets, float)
    grid = graph.grid
    pts = np.concatenate([xy[None, :, :], xy[None, :, :] + off[:, None, :]]).reshape(-1, 2)
    d = nearest_distance(grid, pts)
    if not np.all(np.isfinite(d)):
        return 0.0
    d = d.reshape(len(off) + 1, len(xy))
    s = math.hypot(float(sigma_m), sigma_road_m)
    on = (1.0 - eps) * 2.0 * np.exp(-0.5 * (d / s) ** 2) / (s * _SQRT2PI) + eps / spread_m
    L = np.sum(np.log(on), axis=1)                 # the track (row 0) and each moved copy
    m = float(np.max(L))
    return float(L[0] - m - math.log(float(np.mean(np.exp(L - m)))))


__all__ = ["on_roads_llr", "shifts", "thin_track"]
