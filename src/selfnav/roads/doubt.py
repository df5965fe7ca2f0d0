"""The map's doubt: a lower bound on the navigator's error from where its roads are (issue 19).

A receiver dragged from power-on, or a drift the fixes' own tests let through, leaves the
navigator's covariance as sure as ever while the solution runs tens to hundreds of metres from
the truth: nothing the filter sees disagrees with what it follows. The map does. A car that
is not turning drives along a road that runs its way, within the road's half-width and the
centre line's digitising — a few metres. So when the nearest road running the solution's way
lies ``d`` away, over several looks, the solution is off by about ``d`` or more, whatever its
covariance says, and the reported covariance must hold at least that (:meth:`MapDoubt.widen`).
The converse is weak: in a grid a solution dragged along its road stays on one, and a
solution beside the truth may be on the parallel street; only a turn that fits a junction of
the turn (the corner's own evidence, :mod:`selfnav.roads.corners`) answers the doubt.

The doubt is an output term, like the fault bank's own (:meth:`selfnav.ins.hypotheses.
FaultBank.doubt`): the filter's covariance is not opened, the map having named no place to
go. Between looks the offset is carried with the filter's corrections (a fix that pulls the
solution back towards the road moves its error with it); a jump — a restart, a reset to a
reference — is no evidence either way, and the doubt stands until a turn fits.

Measured on the simulated map campaigns (docs/navigator.md, "Stop 61"): drives whose σ keeps
the issue-18 promise (p95 of error/σ_h ≤ 3, ≤ 1 % beyond 5σ) 73 → 77 of 100 on master seed 2
and on seed 103, the solutions unchanged.
"""
from __future__ import annotations

import math

import numpy as np

from selfnav.roads.corners import corner_candidates
from selfnav.roads.graph import RoadGraph
from selfnav.roads.particles import TWO_PI


class MapDoubt:
    """The map's doubt about one filter (module docstring).

    Parameters
    ----------
    graph : RoadGraph
    off, succ : the successor table of ``graph`` (:func:`selfnav.roads.particles.successor_table`)
    radius_m : the nearest road running the filter's way is looked for up to this far, m (no
        such road within it says nothing: a road the map lacks, a map that ends)
    min_m : a doubt is held when that road lies this far or farther, m, and answered by a turn
        whose junction lies within it (a car on a road is within its half-width and the
        digitising of the centre line; the simulated campaigns' clean seconds: at most 6 m)
    heading_tol : a road "runs the filter's way" within this, rad
    looks, window_s : the median of the last ``looks`` looks (3 at least) within ``window_s``
    jump_m : a move of the filter beyond its own velocity larger than this, m, in one epoch is
        a jump (a restart, a reset), not a correction, and is not carried

    Attributes
    ----------
    e : (2,) or None — the filter's offset (ENU m) from the road, carried since
    seconds : seconds a doubt was held
    spans : ``[start_s, end_s or None, largest_m]`` of each time a doubt was held
    first_s, largest_m : when the first was raised (None: never) and the largest look, m
    """

    def __init__(self, graph: RoadGraph, off, succ, *, radius_m=200.0, min_m=15.0,
                 heading_tol=math.radians(20.0), looks=5, window_s=8.0, jump_m=10.0):
        self.g, self.off, self.succ = graph, off, succ
        self.radius_m, self.min_m, self.heading_tol = radius_m, min_m, heading_tol
        self.n_looks, self.window_s, self.jump_m = looks, window_s, jump_m
        self.e = None
        self.seconds = 0.0
        self.spans = []
        self._looks = []            # (t, distance, offset)
        self._last = None           # (t, position, velocity) at the previous epoch

    def carry(self, t, p, v):
        """At every epoch: the filter at ``p`` (local m) with horizontal velocity ``v`` (m/s).
        What moved it beyond its velocity since the last epoch (fixes, constraints) moved its
        error with it; a jump does not (module docstring)."""
        p = np.asarray(p, float)
        v = np.asarray(v, float)[:2]
        if self._last is not None and self.e is not None:
            t_p, p_p, v_p = self._last
            step = p - p_p - 0.5 * (v_p + v) * (t - t_p)
            if math.hypot(*step) <= self.jump_m:
                self.e = self.e + step
            if math.hypot(*self.e) < self.min_m:
                self._answered(t)
            else:
                self.seconds += t - t_p
        self._last = (t, p, v)

    def look(self, t, p, heading):
        """A look on a straight run (not turning): the nearest road running the filter's
        ``heading`` (rad from grid North) from ``p`` (local m); at a median of ``min_m`` or
        more over the recent looks, the offset from it becomes the doubt when it is larger
        than the one held. While a start's heading is split (several ``p`` and ``heading``,
        one per hypothesis), the hypothesis nearest a road running its way answers for all:
        a doubt holds only when every one of them is off."""
        p = np.atleast_2d(np.asarray(p, float))
        c = self.g.candidates(p, self.radius_m, k=1, per_way=False,
                              heading=np.atleast_1d(np.asarray(heading, float)) % TWO_PI,
                              heading_tol=self.heading_tol, min_candidates=0)
        self._looks = [o for o in self._looks if o[0] > t - self.window_s]
        if len(c) == 0:
            return
        i = int(np.argmin(c.dist))
        self._looks.append((t, float(c.dist[i]), p[c.query[i]] - c.foot[i]))
        recent = self._looks[-self.n_looks:]
        if len(recent) < 3:
            return
        _, d, e = recent[int(np.argsort([o[1] for o in recent])[len(recent) // 2])]
        if d < self.min_m:
            return
        if self.e is None:
            self.spans.append([float(t), None, float(d)])
        elif d <= math.hypot(*self.e):
            return
        self.e = np.asarray(e, float)
        self.spans[-1][2] = max(self.spans[-1][2], float(d))

    @property
    def first_s(self):
        return self.spans[0][0] if self.spans else None

    @property
    def largest_m(self) -> float:
        return max((sp[2] for sp in self.spans), default=0.0)

    def turn(self, t, vertex, h_in, h_out):
        """A finished turn (at ``t``) from heading ``h_in`` to ``h_out`` whose legs meet at
        ``vertex``: a junction (or bend) of that turn within ``min_m`` answers the doubt. A
        turn that fits none raises none: a road curving through many short segments has no
        such junction (simulated campaign drive 4811001308232054616 of master seed 2, Kotka: a
        clean 88° turn whose nearest junction of it lay 118 m away), and a filter beside its
        road shows it on the straight that follows."""
        if self.e is None:
            return
        if len(corner_candidates(self.g, self.off, self.succ, vertex, h_in, h_out,
                                 self.min_m)):
            self._answered(t)

    def _answered(self, t):
        self.e = None
        self.spans[-1][1] = float(t)

    def widen(self, C_h) -> np.ndarray:
        """The horizontal covariance ``C_h`` (2×2, ENU) with its variance along the doubt ``e``
        at least ``|e|²`` (``C_h`` itself when no doubt is held or it already does)."""
        if self.e is None:
            return C_h
        d2 = float(self.e @ self.e)
        u = self.e / math.sqrt(d2)
        add = d2 - float(u @ C_h @ u)
        if add <= 0.0:
            return C_h
        return C_h + add * np.outer(u, u)
