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
