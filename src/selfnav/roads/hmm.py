"""GNSS-only map matching: a hidden Markov model with Viterbi decoding (DESIGN §7, issue 5).

The model follows Newson & Krumm (2009, "Hidden Markov map matching through noise and
sparseness"):

* **states** at each fix are road candidates: the closest point of each nearby road (one per
  OSM way and direction) within a search radius, from :meth:`selfnav.roads.graph.RoadGraph.candidates`;
  a fix with no road inside the radius gets its nearest road, so that *every* fix is matched;
* **emission**: Gaussian in the distance between fix and candidate,
  ``log p = -½ (d/σ)²`` with σ the fix's ``sigma_m`` (or the default);
* **transition**: exponential in the difference between the route distance over the directed
  graph (one-ways respected) and the straight-line distance between the two fixes,
  ``log p = -|d_route - d_gc| / β``; a small backwards move on the same road (≤ ``backtrack``
  metres, a stopped car in noise) counts as its length; transitions faster than ``max_speed``
  are impossible;
* **breaks**: where no transition is possible (a gap, or a jump no road explains) the chain
  restarts from the emission probabilities alone, and decoding continues.

Route distances come from ``scipy.sparse.csgraph.dijkstra`` run once per distinct candidate
end node (in blocks, with a distance limit), the pair bookkeeping is vectorized numpy, and the
Viterbi recursion is a numba kernel over flat (CSR) arrays.

A GNSS-only matcher cannot hold the road through long outlier windows (DESIGN §7): the
inertial prediction is what does (the navigator). :func:`transition_route_distance` and the
candidate search are the parts an INS-driven matcher reuses.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numba
import numpy as np

from selfnav.roads.graph import Candidates, RoadGraph


@dataclass
class MatchResult:
    """One matched road position per input fix.

    Attributes
    ----------
    t : (N,) s
    xy : (N, 2) m
        Matched position, local metres of the graph.
    lat, lon : (N,) rad
        Matched position, WGS-84.
    seg : (N,) int
        Directed segment of the match.
    along : (N,) m
        Offset along that segment.
    moved : (N,) m
        Distance from the fix to its matched position.
    in_radius : (N,) bool
        The fix had at least one road within the search radius.
    restart : (N,) bool
        The chain restarted at this fix (first fix, or no transition possible).
    seconds : float
        Processing time.
    """

    t: np.ndarray
    xy: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    seg: np.ndarray
    along: np.ndarray
    moved: np.ndarray
    in_radius: np.ndarray
    restart: np.ndarray
    seconds: float = 0.0

    def summary(self) -> dict:
        n = len(self.t)
        return {
            "fixes": n,
            "matched_share": float(np.mean(self.in_radius)) if n else 0.0,
            "mean_correction_m": float(np.mean(self.moved)) if n else 0.0,
            "max_correction_m": float(np.max(self.moved)) if n else 0.0,
            "restarts": int(np.sum(self.restart)),
            "seconds": self.seconds,
            "fixes_per_second": n / self.seconds if self.seconds > 0 else None,
        }


def _pairs(off):
    """All candidate pairs between consecutive fixes, flat: ``(epoch, i, j, pair_off)``."""
    kt = np.diff(off)
    P = kt[:-1] * kt[1:]
    pair_off = np.concatenate([[0], np.cumsum(P)])
    tb = np.repeat(np.arange(len(P)), P)
    q = np.arange(pair_off[-1]) - pair_off[tb]
    kn = kt[tb + 1]
    i = off[tb] + q // kn
    j = off[tb + 1] + q % kn
    return tb, i, j, pair_off


class RouteDistances:
    """Shortest route distances over the directed graph from a set of source nodes.

    One ``scipy.sparse.csgraph.dijkstra`` per distinct source, limited to ``limit`` metres,
    kept as a dense ``(n_sources, n_nodes)`` table when it fits in ``max_bytes`` and otherwise
    computed block by block at lookup.
    """

    def __init__(self, graph: RoadGraph, sources, limit=np.inf, max_bytes=128_000_000):
        self.graph = graph
        self.sources, self._inverse = np.unique(np.asarray(sources, np.int64), return_inverse=True)
        self.limit = float(limit)
        self.block = max(1, int(max_bytes // (8 * max(graph.n_nodes, 1))))
        self._table = self._rows(0, len(self.sources)) if len(self.sources) <= self.block else None

    def _rows(self, r0, r1):
        from scipy.sparse.csgraph import dijkstra

        return dijkstra(self.graph.csr, directed=True, indices=self.sources[r0:r1],
                        limit=self.limit)

    def row_of(self, k):
        """Row of source number ``k`` of the array given at construction."""
        return self._inverse[k]

    def lookup(self, rows, dst):
        """Distance from source row ``rows`` to node ``dst`` (inf beyond the limit)."""
        rows = np.asarray(rows, np.int64)
        dst = np.asarray(dst, np.int64)
        if self._table is not None:
            return self._table[rows, dst]
        out = np.full(len(rows), np.inf)
        for r0 in range(0, len(self.sources), self.block):
            r1 = min(r0 + self.block, len(self.sources))
            sel = np.flatnonzero((rows >= r0) & (rows < r1))
            if len(sel):
                out[sel] = self._rows(r0, r1)[rows[sel] - r0, dst[sel]]
        return out


def node_distances(graph: RoadGraph, src, dst, limit=np.inf):
    """Shortest route distance ``src[k] -> dst[k]`` over the directed graph (inf beyond
    ``limit`` or where no route exists)."""
    rd = RouteDistances(graph, src, limit)
    return rd.lookup(rd.row_of(np.arange(len(src))), dst)


def transition_route_distance(graph: RoadGraph, cand: Candidates, i, j, *, backtrack=15.0,
                              limit=np.inf, distances: RouteDistances | None = None):
    """Route distance from candidate ``i`` to candidate ``j`` (arrays of candidate indices).

    Forward along the directed graph: rest of segment ``i``, shortest path between the
    segments, start of segment ``j``. A move backwards shorter than ``backtrack`` metres
    (noise on a stopped or slow vehicle) counts as its length.

    ``distances`` (a :class:`RouteDistances` built on ``graph.seg_v[cand.seg]``) is reused
    when given.
    """
    if distances is None:
        distances = RouteDistances(graph, graph.seg_v[cand.seg], max(limit, backtrack))
    si, sj = cand.seg[i], cand.seg[j]
    ai, aj = cand.along[i], cand.along[j]
    Li, Lj = graph.seg_len[si], graph.seg_len[sj]
    same = si == sj
    fwd_gap = distances.lookup(distances.row_of(i), graph.seg_u[sj])
    d_fwd = np.where(same & (aj >= ai), aj - ai, (Li - ai) + fwd_gap + aj)
    if backtrack > 0:
        back_gap = distances.lookup(distances.row_of(j), graph.seg_u[si])
        d_back = np.where(same & (aj < ai), ai - aj, (Lj - aj) + back_gap + ai)
        d_fwd = np.where(d_back <= backtrack, np.minimum(d_fwd, d_back), d_fwd)
    return d_fwd


@numba.njit(cache=True)
def _viterbi(em, off, pair_off, pi, pj, logtr, score, back):  # pragma: no cover - numba
    n = len(off) - 1
    restart = np.zeros(n, np.bool_)
    restart[0] = True
    for k in range(off[0], off[1]):
        score[k] = em[k]
        back[k] = -1
    for t in range(n - 1):
        b0, b1 = off[t + 1], off[t + 2]
        for k in range(b0, b1):
            score[k] = -np.inf
            back[k] = -1
        for p in range(pair_off[t], pair_off[t + 1]):
            v = score[pi[p]] + logtr[p]
            if v > score[pj[p]]:
                score[pj[p]] = v
                back[pj[p]] = pi[p]
        best = -np.inf
        for k in range(b0, b1):
            if back[k] >= 0:
                score[k] += em[k]
            if score[k] > best:
                best = score[k]
        if best == -np.inf:          # no transition possible: restart the chain here
            restart[t + 1] = True
            best = -np.inf
            for k in range(b0, b1):
                score[k] = em[k]
                back[k] = -1
                if score[k] > best:
                    best = score[k]
        for k in range(b0, b1):      # keep scores near 0 (no drift over long tracks)
            score[k] -= best
    # backtrack
    path = np.empty(n, np.int64)
    t = n - 1
    while t >= 0:
        b0, b1 = off[t], off[t + 1]
        k = b0
        for m in range(b0, b1):
            if score[m] > score[k]:
                k = m
        path[t] = k
        while t > 0 and back[path[t]] >= 0:
            path[t - 1] = back[path[t]]
            t -= 1
        t -= 1
    return path, restart


class HmmMatcher:
    """Newson & Krumm hidden-Markov map matching of GNSS fixes to a road graph.

    Parameters
    ----------
    graph : RoadGraph
    sigma : float
        GNSS horizontal σ (m) where the fixes do not give one.
    beta : float, optional
        Transition scale (m); default ``max(3, sigma/2)``: with noisy fixes the straight-line
        distance between two fixes is itself uncertain by ~σ√2.
    radius : float, optional
        Candidate search radius (m); default ``clip(4σ, 30, 200)``.
    k : int
        Candidates kept per fix.
    backtrack : float
        Backwards jitter accepted on the road, m; default ``max(15, 3σ)``.
    max_speed : float
        Fastest plausible travel between fixes, m/s.
    max_gap : float
        A time gap longer than this (s) restarts the chain.

    Examples
    --------
    >>> m = HmmMatcher(read_roads("map.osm.pbf"), sigma=10.0)     # doctest: +SKIP
    >>> res = m.match_geodetic(t, lat, lon)                          # doctest: +SKIP
    """

    def __init__(self, graph: RoadGraph, *, sigma=10.0, beta=None, radius=None, k=16,
                 backtrack=None, max_speed=60.0, max_gap=120.0):
        self.graph = graph
        self.sigma = float(sigma)
        self.beta = float(beta) if beta is not None else max(3.0, 0.5 * self.sigma)
        self.radius = float(radius) if radius is not None else float(np.clip(4 * self.sigma,
                                                                              30.0, 200.0))
        self.k = int(k)
        self.backtrack = float(backtrack) if backtrack is not None else max(15.0, 3 * self.sigma)
        self.max_speed = float(max_speed)
        self.max_gap = float(max_gap)

    def match(self, t, xy, sigma=None) -> MatchResult:
        """Match fixes given in local metres of the graph; see :class:`MatchResult`."""
        t0 = time.perf_counter()
        t = np.asarray(t, float)
        xy = np.atleast_2d(np.asarray(xy, float))
        n = len(t)
        g = self.graph
        sig = np.full(n, self.sigma) if sigma is None else np.where(
            np.isfinite(sigma) & (np.asarray(sigma, float) > 0), sigma, self.sigma)
        cand = g.candidates(xy, self.radius, k=self.k, min_candidates=1, per_way=True)
        off = cand.offsets(n)
        em = -0.5 * (cand.dist / sig[cand.query]) ** 2
        tb, pi, pj, pair_off = _pairs(off)
        d_gc = np.hypot(*(xy[1:] - xy[:-1]).T)
        dt = np.diff(t)
        # route distances beyond what the speed limit allows are never needed
        fastest = self.max_speed * np.minimum(dt, self.max_gap) + 2 * self.radius
        limit = min(float(np.max(d_gc, initial=0.0)) + 20 * self.beta + self.radius,
                    float(np.max(fastest, initial=0.0)))
        d_route = transition_route_distance(g, cand, pi, pj, backtrack=self.backtrack,
                                            limit=limit)
        logtr = -np.abs(d_route - d_gc[tb]) / self.beta
        impossible = ~np.isfinite(d_route) | (d_route > fastest[tb]) | (dt[tb] > self.max_gap)
        logtr[impossible] = -np.inf
        score = np.empty(len(cand))
        back = np.empty(len(cand), np.int64)
        path, restart = _viterbi(em, off, pair_off, pi, pj, logtr, score, back)
        foot = cand.foot[path]
        lat, lon = g.to_geodetic(foot[:, 0], foot[:, 1])
        in_radius = np.bincount(cand.query[cand.dist <= self.radius], minlength=n) > 0
        return MatchResult(t, foot, lat, lon, cand.seg[path], cand.along[path],
                           cand.dist[path], in_radius, restart, time.perf_counter() - t0)

    def match_geodetic(self, t, lat, lon, sigma=None) -> MatchResult:
        """Match fixes given as WGS-84 latitude and longitude (rad)."""
        t0 = time.perf_counter()
        x, y = self.graph.to_local(np.asarray(lat, float), np.asarray(lon, float))
        res = self.match(t, np.column_stack([x, y]), sigma)
        res.seconds = time.perf_counter() - t0
        return res


def match_gnss(graph: RoadGraph, t, lat, lon, sigma=None, **kw) -> MatchResult:
    """Match WGS-84 fixes (rad) to ``graph``: ``HmmMatcher(graph, **kw).match_geodetic(...)``."""
    return HmmMatcher(graph, **kw).match_geodetic(t, lat, lon, sigma)


def snap_to_road(graph: RoadGraph, xy, heading=None, *, radius=50.0, heading_tol=np.pi / 2):
    """The nearest road point of each position, with the road direction there.

    For an INS-driven matcher or a road constraint in a filter: with ``heading`` (rad, clockwise
    from grid North) only segments whose direction of travel is within ``heading_tol`` of it
    count, so a two-way road gives the direction the vehicle drives and a one-way road driven
    against its direction is not chosen.

    Returns
    -------
    foot : (N, 2) m, seg : (N,) int, cross : (N,) m (positive: the point is left of the road),
    road_heading : (N,) rad. Points with no road within ``radius`` get NaN and ``seg = -1``.
    """
    xy = np.atleast_2d(np.asarray(xy, float))
    n = len(xy)
    h = None if heading is None else np.broadcast_to(np.asarray(heading, float), (n,))
    c = graph.candidates(xy, radius, k=1, min_candidates=0, per_way=False, heading=h,
                         heading_tol=None if h is None else heading_tol)
    foot = np.full((n, 2), np.nan)
    seg = np.full(n, -1, np.int64)
    cross = np.full(n, np.nan)
    road_heading = np.full(n, np.nan)
    foot[c.query], seg[c.query], cross[c.query] = c.foot, c.seg, c.cross
    road_heading[c.query] = graph.seg_heading[c.seg]
    return foot, seg, cross, road_heading
