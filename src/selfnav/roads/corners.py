"""Corners as along-track fixes (issue 15): where did the vehicle turn, on the map?

Through a corner a car drives from one straight leg onto another; the two legs' lines meet at
the corner's vertex. The INS sees the same geometry to within its short-term drift: the line
it drove in on (position and heading before the turn) and the line it drove out on (after)
meet at *its* estimate of the vertex. The map has the true vertex — the intersection of a road
segment in the entry direction and one reachable from it in the exit direction. Their
difference is the INS's position error (the part common to a few seconds of driving), along
the road as much as across it: a position fix from the map alone, without GNSS.

A car cuts a corner on an arc, and a road with a curved centre line bends through several
OSM vertices; neither moves the intersection of the legs. Lanes move it by a few metres, an
ambiguous map (a grid of equal corners) by a block: :func:`corner_candidates` returns every
candidate and the caller decides.
"""
from __future__ import annotations

import numpy as np

from selfnav.ins.config import CHI2_2_999
from selfnav.roads.graph import RoadGraph
from selfnav.roads.particles import wrap


def line_intersection(p0, h0, p1, h1):
    """Where the line through ``p0`` with heading ``h0`` meets the one through ``p1`` with
    heading ``h1`` (rad clockwise from North); ``(point, s0, s1)`` with the signed distances
    along each line from its point, or None when they are nearly parallel (< 20°)."""
    u0 = np.array([np.sin(h0), np.cos(h0)])
    u1 = np.array([np.sin(h1), np.cos(h1)])
    A = np.column_stack([u0, -u1])
    if abs(np.linalg.det(A)) < np.sin(np.radians(20.0)):
        return None
    s0, s1 = np.linalg.solve(A, np.asarray(p1, float) - np.asarray(p0, float))
    return np.asarray(p0, float) + s0 * u0, float(s0), float(s1)


def corner_candidates(graph: RoadGraph, off, succ, vertex, h_in, h_out, radius, *,
                      heading_tol=np.radians(20.0), hops=4, reach_m=80.0):
    """Map corners that turn from heading ``h_in`` to ``h_out`` near ``vertex`` (local m).

    Candidates are pairs of directed segments ``(a, b)`` within ``radius`` of ``vertex``, ``a``
    heading within ``heading_tol`` of ``h_in``, ``b`` of ``h_out``, ``b`` reachable from ``a``
    in at most ``hops`` segments and ``reach_m`` metres; each gives the intersection of their
    lines. Returns an ``(M, 2)`` array of distinct corner vertices (closer than 3 m merged).
    """
    import shapely

    si = np.asarray(graph.tree.query(shapely.points(np.asarray(vertex, float)),
                                     predicate="dwithin", distance=float(radius)), np.int64)
    if len(si) == 0:
        return np.zeros((0, 2))
    hd = graph.seg_heading[si]
    A = si[np.abs(wrap(hd - h_in)) < heading_tol]
    B = set(si[np.abs(wrap(hd - h_out)) < heading_tol].tolist())
    if len(A) == 0 or not B:
        return np.zeros((0, 2))
    out = []
    for a in A.tolist():
        frontier, seen = [(a, 0.0)], {a}
        for _ in range(hops):
            nxt = []
            for s, d in frontier:
                for q in succ[off[s]:off[s + 1]].tolist():
                    dq = d + float(graph.seg_len[s])
                    if q in seen or dq > reach_m:
                        continue
                    seen.add(q)
                    nxt.append((q, dq))
            frontier = nxt
        for b in seen & B:
            if b == a:
                continue
            pa = graph.xy[graph.seg_u[a]]
            pb = graph.xy[graph.seg_u[b]]
            x = line_intersection(pa, graph.seg_heading[a], pb, graph.seg_heading[b])
            if x is not None and np.hypot(*(x[0] - vertex)) <= radius:
                out.append(x[0])
    if not out:
        return np.zeros((0, 2))
    pts = []
    for p in out:
        if all(np.hypot(*(p - q)) > 3.0 for q in pts):
            pts.append(p)
    return np.asarray(pts)


#: rad: the sharpest turn the map places a car by (a corner fix, an arc): beyond it the
#: legs are near antiparallel — a U-turn on one road, a hairpin — and the lines through
#: them meet, and a circle tangent to both lies, hundreds of metres away
MAX_CORNER_TURN = np.radians(150.0)
#: a filter turning faster than this (rad/s, over the last 0.6 s or one step) is in a turn
TURN_RATE = np.radians(3.0)


class TurnWatch:
    """One filter's turns, as they end: its heading and position over the last 25 s, and the
    turn being driven (from the first epoch it turns to ``calm_s`` after it stops).

    :meth:`step` returns, at the end of a turn of 35–150° within 20 s driven above 2 m/s whose
    entry line (the filter 1 s before the turn) and exit line (now) meet ahead of the entry and
    behind the exit (within 10 m), the filter's vertex of the turn and its entry heading — what
    :func:`corner_offset` looks up on the map. The road aid keeps one for the navigator's filter
    (every aiding epoch), the fault bank one per dead reckoning (every reference step)."""

    def __init__(self, calm_s: float = 1.0):
        self.calm_s = calm_s
        self.track = []            # (t, heading, position) of the filter, recent seconds
        self.turn = None           # the turn being driven: {"t0", "t_calm"}
        self.last = None           # (t, heading) of the previous step (:meth:`rate`)

    def rate(self, t, hdg) -> float:
        """The heading rate since the previous step, rad/s (0 at the first)."""
        last, self.last = self.last, (t, hdg)
        if last is None or t <= last[0]:
            return 0.0
        return float(wrap(hdg - last[1])) / (t - last[0])

    def step(self, t, hdg, p, turning: bool, speed: float):
        """The filter at ``t`` (heading rad clockwise from North, position local m, turning or
        not, speed m/s): ``(vertex, entry heading)`` of a turn that has just ended, or None."""
        self.track = [x for x in self.track if x[0] > t - 25.0] + [(t, hdg, np.array(p, float))]
        if turning:
            if self.turn is None:
                self.turn = {"t0": t, "t_calm": None}
            self.turn["t_calm"] = None
            if t - self.turn["t0"] > 20.0:
                self.turn = None
            return None
        if self.turn is None:
            return None
        if self.turn["t_calm"] is None:
            self.turn["t_calm"] = t
        if t - self.turn["t_calm"] < self.calm_s - 1e-9:
            return None
        t0 = self.turn["t0"]
        self.turn = None
        before = [x for x in self.track if x[0] <= t0 - 1.0]
        if not before or speed < 2.0:
            return None
        _, h0, p0 = before[-1]
        th = float(wrap(hdg - h0))
        if not np.radians(35.0) <= abs(th) <= MAX_CORNER_TURN:
            return None
        x = line_intersection(p0, h0, p, hdg)
        if x is None or x[1] < -10.0 or x[2] > 10.0:
            return None
        return x[0], h0


def corner_offset(graph: RoadGraph, off, succ, vertex, h_in, h_out, P2, sigma_corner):
    """The filter's position error at a corner (local m, E/N): its ``vertex`` of a turn from
    ``h_in`` to ``h_out`` less the map's, where one map corner of that turn — looked for within
    ``max(30 m, 3σ + 10 m)``, at most 80 m, σ the filter's largest horizontal (``P2``) —
    fits the filter's uncertainty with ``sigma_corner`` (χ² 2 dof, 0.999) and the next fits
    clearly worse (by 9: a grid of equal corners); None otherwise or below 2 m."""
    radius = min(80.0, max(30.0, 3.0 * float(np.sqrt(np.linalg.eigvalsh(P2)[-1])) + 10.0))
    S = P2 + np.eye(2) * sigma_corner**2
    cand = corner_candidates(graph, off, succ, vertex, h_in, h_out, radius)
    if len(cand) == 0:
        return None
    E = vertex - cand
    q = np.einsum("ij,ij->i", E, np.linalg.solve(S, E.T).T)
    i = int(np.argmin(q))
    if q[i] > CHI2_2_999 or (len(cand) > 1 and np.partition(q, 1)[1] < q[i] + 9.0):
        return None
    e = E[i]
    return None if np.hypot(*e) < 2.0 else e
