"""Shortest route distances over the directed road graph, bounded and cached (issue 14).

Map matching needs, for every pair of road candidates of two consecutive fixes, the route
distance from the end node of one segment to the start node of the other — but only up to a
bound (a route much longer than the straight line between the fixes is cut anyway). A
:class:`RouteCache` runs a bounded Dijkstra (numba, binary heap, cost proportional to the
neighbourhood it settles, not to the size of the map) from each source node it is asked for,
and keeps the settled nodes as a sparse row in distance order, which a numba kernel scans only
up to the bound it needs. Rows are reused across fixes and across tracks (a fleet on one map
asks for the same sources again and again), a row computed to a bound serves every smaller
bound, and the store is emptied when it reaches its size limit, so memory stays bounded whatever
the number of tracks. This is the role FMM's precomputed UBODT table plays (Yang & Gidófalvi 2018), computed
lazily instead of for every node of the map up front.

:func:`route_nodes` gives the node sequence of a shortest route (for the driven route of a
matched track); :func:`transition_route_distance` the route distance between road candidates
(the scalar form is in the matcher's kernel, :mod:`selfnav.roads.viterbi`).
"""
from __future__ import annotations

import numba
import numpy as np

from selfnav.roads.graph import Candidates, RoadGraph


@numba.njit(cache=True)
def _heap_push(hd, hn, size, d, n):  # pragma: no cover - numba
    k = size
    hd[k] = d
    hn[k] = n
    while k > 0:
        p = (k - 1) >> 1
        if hd[p] <= hd[k]:
            break
        hd[p], hd[k] = hd[k], hd[p]
        hn[p], hn[k] = hn[k], hn[p]
        k = p
    return size + 1


@numba.njit(cache=True)
def _heap_pop(hd, hn, size):  # pragma: no cover - numba
    d, n = hd[0], hn[0]
    size -= 1
    hd[0] = hd[size]
    hn[0] = hn[size]
    k = 0
    while True:
        c = 2 * k + 1
        if c >= size:
            break
        if c + 1 < size and hd[c + 1] < hd[c]:
            c += 1
        if hd[k] <= hd[c]:
            break
        hd[c], hd[k] = hd[k], hd[c]
        hn[c], hn[k] = hn[k], hn[c]
        k = c
    return d, n, size


@numba.njit(cache=True)
def _bounded_rows(indptr, indices, weights, sources, limits, dist, stamp, done, run0,
                  out_node, out_dist, pos, row_start, row_len):  # pragma: no cover - numba
    """Dijkstra from each source up to its limit; settled nodes appended to ``out_*`` in the
    order they are settled (non-decreasing distance). Returns ``(sources done, new pos, last
    run id)``; stops early when ``out`` is full."""
    nnz = len(indices)
    hd = np.empty(nnz + 1)
    hn = np.empty(nnz + 1, np.int64)
    run = run0
    cap = len(out_node)
    for r in range(len(sources)):
        run += 1
        s = sources[r]
        lim = limits[r]
        start = pos
        size = _heap_push(hd, hn, 0, 0.0, s)
        dist[s] = 0.0
        stamp[s] = run
        while size > 0:
            d, u, size = _heap_pop(hd, hn, size)
            if done[u] == run:
                continue
            if d > lim:
                break
            if pos >= cap:
                return r, start, run
            done[u] = run
            out_node[pos] = u
            out_dist[pos] = d
            pos += 1
            for e in range(indptr[u], indptr[u + 1]):
                v = indices[e]
                nd = d + weights[e]
                if nd <= lim and (stamp[v] != run or nd < dist[v]):
                    dist[v] = nd
                    stamp[v] = run
                    size = _heap_push(hd, hn, size, nd, v)
        row_start[r] = start
        row_len[r] = pos - start
    return len(sources), pos, run


@numba.njit(cache=True)
def route_gap(row_of, row_start, row_len, pool_node, pool_dist, src, dst,
              limit=np.inf):  # pragma: no cover - numba
    """Cached route distance ``src -> dst`` (node indices), inf where not in the row or beyond
    ``limit``. Rows are in distance order, so the scan stops at ``limit``."""
    r = row_of[src]
    if r < 0:
        return np.inf
    for e in range(row_start[r], row_start[r] + row_len[r]):
        if pool_dist[e] > limit:
            break
        if pool_node[e] == dst:
            return pool_dist[e]
    return np.inf


@numba.njit(cache=True)
def _lookup_many(row_of, row_start, row_len, pool_node, pool_dist, src, dst):  # pragma: no cover
    out = np.empty(len(src))
    for k in range(len(src)):
        out[k] = route_gap(row_of, row_start, row_len, pool_node, pool_dist, src[k], dst[k])
    return out


class RouteCache:
    """Bounded shortest route distances from source nodes, computed on demand and kept.

    Parameters
    ----------
    graph : RoadGraph
    max_entries : int
        Size limit of the store (settled nodes over all rows; 12 bytes each). When a request
        would pass it, the store is emptied first.

    Notes
    -----
    A row holds every node whose route distance from the source is at most the row's bound;
    a request with a smaller bound is served from it (the caller applies its own bound, so
    results never depend on what was cached before).
    """

    def __init__(self, graph: RoadGraph, max_entries: int = 4_000_000):
        data, indices, indptr = graph.csr_arrays()       # (scipy not imported: start-up)
        self.graph = graph
        self.indptr = np.asarray(indptr, np.int64)
        self.indices = np.asarray(indices, np.int64)
        self.weights = np.asarray(data, np.float64)
        n = graph.n_nodes
        self.max_entries = int(max_entries)
        self._dist = np.empty(n)
        self._stamp = np.zeros(n, np.int64)
        self._done = np.zeros(n, np.int64)
        self._run = 0
        self.row_of = np.full(n, -1, np.int64)
        self.rows_computed = 0
        self.clears = 0
        self._reset()

    def _reset(self):
        self.row_start = np.zeros(1024, np.int64)
        self.row_len = np.zeros(1024, np.int64)
        self.row_limit = np.zeros(1024)
        self.n_rows = 0
        cap = min(self.max_entries, 1 << 16)
        self.pool_node = np.empty(cap, np.int64)
        self.pool_dist = np.empty(cap)
        self.used = 0
        self.row_of[:] = -1

    def clear(self):
        """Empty the store."""
        self._reset()
        self.clears += 1

    @property
    def arrays(self):
        """``(row_of, row_start, row_len, pool_node, pool_dist)`` for :func:`route_gap`."""
        return self.row_of, self.row_start, self.row_len, self.pool_node, self.pool_dist

    def ensure(self, nodes, limits):
        """Make sure each source ``nodes[k]`` has a row reaching at least ``limits[k]`` m."""
        nodes = np.asarray(nodes, np.int64)
        limits = np.broadcast_to(np.asarray(limits, float), nodes.shape)
        if not len(nodes):
            return
        order = np.lexsort((-limits, nodes))
        nodes, limits = nodes[order], limits[order]
        first = np.ones(len(nodes), bool)
        first[1:] = nodes[1:] != nodes[:-1]
        nodes, limits = nodes[first], limits[first]
        while True:
            r = self.row_of[nodes]
            have = np.where(r >= 0, self.row_limit[np.maximum(r, 0)], -1.0)
            need = have < limits
            if not need.any():
                return
            was_empty = self.used == 0
            # a little more than asked, so that a slightly larger bound later reuses the row
            complete = self._compute(nodes[need],
                                     np.maximum(1.25 * limits[need], limits[need] + 50.0))
            if not complete and was_empty:   # one request larger than the whole store:
                self.max_entries *= 2        # served anyway (the limit is soft)

    def _grow_rows(self, extra):
        need = self.n_rows + extra
        if need > len(self.row_start):
            size = max(need, 2 * len(self.row_start))
            for name in ("row_start", "row_len", "row_limit"):
                a = getattr(self, name)
                b = np.zeros(size, a.dtype)
                b[: len(a)] = a
                setattr(self, name, b)

    def _compute(self, nodes, limits):
        k = 0
        while k < len(nodes):
            self._grow_rows(len(nodes) - k)
            if self.used == len(self.pool_node) and len(self.pool_node) < self.max_entries:
                self._grow_pool()
            starts = np.zeros(len(nodes) - k, np.int64)
            lens = np.zeros(len(nodes) - k, np.int64)
            done, pos, self._run = _bounded_rows(
                self.indptr, self.indices, self.weights, nodes[k:], limits[k:], self._dist,
                self._stamp, self._done, self._run, self.pool_node, self.pool_dist, self.used,
                starts, lens)
            if done:
                rows = self.n_rows + np.arange(done)
                self.row_start[rows] = starts[:done]
                self.row_len[rows] = lens[:done]
                self.row_limit[rows] = limits[k:k + done]
                self.row_of[nodes[k:k + done]] = rows
                self.n_rows += done
                self.rows_computed += done
            self.used = pos
            k += done
            if k < len(nodes):               # the pool is full: grow it, or empty the store
                if len(self.pool_node) < self.max_entries:
                    self._grow_pool()
                    continue
                self.clear()                 # (the caller then asks again for all its rows)
                return False
        return True

    def _grow_pool(self):
        size = min(self.max_entries, 2 * len(self.pool_node))
        for name in ("pool_node", "pool_dist"):
            a = getattr(self, name)
            b = np.empty(size, a.dtype)
            b[: self.used] = a[: self.used]
            setattr(self, name, b)

    def lookup(self, src, dst, limit=np.inf):
        """Route distances ``src[k] -> dst[k]`` (inf beyond ``limit`` or without a route)."""
        src = np.atleast_1d(np.asarray(src, np.int64))
        dst = np.atleast_1d(np.asarray(dst, np.int64))
        if np.isfinite(limit):
            self.ensure(src, limit)
            d = _lookup_many(*self.arrays, src, dst)
            return np.where(d <= limit, d, np.inf)
        # unbounded: whole-graph rows, in batches so that the store never overflows
        out = np.empty(len(src))
        per_row = max(1, self.graph.n_nodes)
        batch = max(1, self.max_entries // per_row)
        for a in range(0, len(src), batch):
            sl = slice(a, a + batch)
            self.ensure(src[sl], np.inf)
            out[sl] = _lookup_many(*self.arrays, src[sl], dst[sl])
        return out


def node_distances(graph: RoadGraph, src, dst, limit=np.inf):
    """Shortest route distance ``src[k] -> dst[k]`` over the directed graph (inf beyond
    ``limit`` or where no route exists)."""
    return RouteCache(graph).lookup(src, dst, limit)


def route_nodes(graph: RoadGraph, src, dst, limit=np.inf):
    """Node sequences of the shortest routes ``src[k] -> dst[k]`` (lists of node indices; an
    empty list where no route exists within ``limit``). One ``scipy`` Dijkstra per distinct
    source, in blocks."""
    from scipy.sparse.csgraph import dijkstra

    src = np.asarray(src, np.int64)
    dst = np.asarray(dst, np.int64)
    out: list[list[int]] = [[] for _ in range(len(src))]
    uniq, inv = np.unique(src, return_inverse=True)
    block = max(1, int(64_000_000 // (16 * max(graph.n_nodes, 1))))
    for b0 in range(0, len(uniq), block):
        idx = uniq[b0:b0 + block]
        dist, pred = dijkstra(graph.csr, directed=True, indices=idx, limit=limit,
                              return_predecessors=True)
        for k in np.flatnonzero((inv >= b0) & (inv < b0 + len(idx))):
            row = inv[k] - b0
            v = int(dst[k])
            if not np.isfinite(dist[row, v]):
                continue
            path = [v]
            while v != idx[row]:
                v = int(pred[row, v])
                path.append(v)
            out[k] = path[::-1]
    return out


def segment_lookup(graph: RoadGraph):
    """``f(u, v) -> segment index`` for node pairs that are directed segments (the shortest
    when two segments join the same nodes, as in :attr:`RoadGraph.csr`); -1 otherwise."""
    n = graph.n_nodes
    order = np.lexsort((graph.seg_len, graph.seg_v, graph.seg_u))
    key = graph.seg_u[order] * n + graph.seg_v[order]
    first = np.ones(len(key), bool)
    first[1:] = key[1:] != key[:-1]
    key, seg = key[first], order[first]

    def lookup(u, v):
        q = np.asarray(u, np.int64) * n + np.asarray(v, np.int64)
        k = np.clip(np.searchsorted(key, q), 0, max(len(key) - 1, 0))
        return np.where(key[k] == q, seg[k], -1)

    return lookup


def driven_route(graph: RoadGraph, seg, along, foot, restart, *, backtrack=15.0):
    """The route a matched track drove, through the road graph between consecutive matches.

    Parameters
    ----------
    seg, along, foot : (N,), (N,), (N, 2)
        Matched segment, offset along it and position (local metres) of each fix.
    restart : (N,) bool
        Where the chain restarted (the route is broken there).
    backtrack : float
        A move backwards up to this length (m) is noise on a slow or stopped vehicle, not a
        drive round the block (as in the matcher).

    Returns
    -------
    list of (xy (M, 2) m, segments (S,) int)
        One piece per unbroken run of the chain: its polyline and the directed segments it
        drives, in order.
    """
    seg = np.asarray(seg, np.int64)
    n = len(seg)
    forward, src, dst = [], [], []
    for k in range(1, n):
        if restart[k]:
            continue
        si, sj = seg[k - 1], seg[k]
        if si == sj:
            continue
        if (graph.seg_len[sj] - along[k]) + along[k - 1] <= backtrack:
            back = node_distances(graph, [graph.seg_v[sj]], [graph.seg_u[si]], backtrack)[0]
            if (graph.seg_len[sj] - along[k]) + back + along[k - 1] <= backtrack:
                continue                     # jitter backwards: the vehicle did not drive on
        forward.append(k)
        src.append(graph.seg_v[si])
        dst.append(graph.seg_u[sj])
    paths = dict(zip(forward, route_nodes(graph, src, dst))) if forward else {}
    seg_of = segment_lookup(graph)
    pieces = []
    pts, segs = [], []
    for k in range(n):
        if restart[k] or k == 0:
            if len(pts) > 1:
                pieces.append((np.asarray(pts), np.asarray(segs, np.int64)))
            pts, segs = [foot[k]], [seg[k]]
            continue
        if seg[k] == seg[k - 1]:
            if along[k] >= along[k - 1]:
                pts.append(foot[k])
            continue
        if k not in paths:
            continue
        nodes = paths[k]
        if not nodes:                        # no route: break the piece here
            if len(pts) > 1:
                pieces.append((np.asarray(pts), np.asarray(segs, np.int64)))
            pts, segs = [foot[k]], [seg[k]]
            continue
        pts += list(graph.xy[nodes])
        pts.append(foot[k])
        segs += list(seg_of(nodes[:-1], nodes[1:]))
        segs.append(seg[k])
    if len(pts) > 1:
        pieces.append((np.asarray(pts), np.asarray(segs, np.int64)))
    return pieces


class RouteDistances:
    """Route distances from a fixed set of source nodes (a thin view of a :class:`RouteCache`
    that the vectorized :func:`transition_route_distance` uses)."""

    def __init__(self, graph: RoadGraph, sources, limit=np.inf, cache: RouteCache | None = None):
        self.sources = np.asarray(sources, np.int64)
        self.limit = float(limit)
        self.cache = cache or RouteCache(graph)

    def row_of(self, k):
        """Row of source number ``k`` of the array given at construction."""
        return np.asarray(k, np.int64)

    def lookup(self, rows, dst):
        """Distance from source row ``rows`` to node ``dst`` (inf beyond the limit)."""
        return self.cache.lookup(self.sources[rows], dst, self.limit)


def transition_route_distance(graph: RoadGraph, cand: Candidates, i, j, *, backtrack=15.0,
                              limit=np.inf, distances: RouteDistances | None = None):
    """Route distance from candidate ``i`` to candidate ``j`` (arrays of candidate indices).

    Forward along the directed graph: rest of segment ``i``, shortest path between the
    segments, start of segment ``j``. A move backwards shorter than ``backtrack`` metres
    (noise on a stopped or slow vehicle) counts as its length.

    This is the vectorized (numpy) form of the transition the matcher's numba kernel computes
    (the tests hold one against the other); an INS-driven matcher can reuse it. ``distances``
    (a :class:`RouteDistances` built on ``graph.seg_v[cand.seg]``) is reused when given.
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
        back_gap = RouteDistances(graph, graph.seg_v[sj], backtrack, distances.cache).lookup(
            np.arange(len(sj)), graph.seg_u[si])
        d_back = np.where(same & (aj < ai), ai - aj, (Lj - aj) + back_gap + ai)
        d_fwd = np.where(d_back <= backtrack, np.minimum(d_fwd, d_back), d_fwd)
    return d_fwd


def _path(indptr, indices, weights, src: int, dst: int, limit: float) -> list:
    """Nodes of the shortest route ``src -> dst`` within ``limit`` m (Dijkstra on a heap,
    settling only the neighbourhood the bound allows); [] where there is none. For the few
    outliers of a match: :func:`route_nodes` would import scipy on the matcher's path (its
    start-up), and :class:`RouteCache` keeps distances, not predecessors."""
    import heapq

    dist, pred, done = {src: 0.0}, {src: -1}, set()
    heap = [(0.0, src)]
    while heap:
        d, u = heapq.heappop(heap)
        if u in done:
            continue
        if u == dst:
            path = [u]
            while pred[path[-1]] >= 0:
                path.append(pred[path[-1]])
            return path[::-1]
        done.add(u)
        for j in range(indptr[u], indptr[u + 1]):
            v, nd = int(indices[j]), d + float(weights[j])
            if nd <= limit and nd < dist.get(v, np.inf):
                dist[v], pred[v] = nd, u
                heapq.heappush(heap, (nd, v))
    return []


def points_along_route(graph: RoadGraph, seg_a, along_a, seg_b, along_b, fractions, *,
                       limit=np.inf, routes=None, lookup=None):
    """Road positions at ``fractions`` (0 … 1) of the shortest route's length from the road
    position ``(seg_a, along_a)`` to ``(seg_b, along_b)``: ``(xy (K, 2), seg (K,), along
    (K,))``, or None where no route exists within ``limit`` m (from the end node of
    ``seg_a`` to the start node of ``seg_b``, as the matcher bounds a transition's route).
    ``routes``: a :class:`RouteCache` of the graph (its adjacency arrays are used) and
    ``lookup``: :func:`segment_lookup` of the graph, for many calls (built when not given)."""
    seg_a, seg_b = int(seg_a), int(seg_b)
    fr = np.clip(np.asarray(fractions, float), 0.0, 1.0)
    if seg_a == seg_b and along_b >= along_a:
        segs, starts = np.array([seg_a]), np.array([along_a])
        lens = np.array([along_b - along_a])
    else:
        if routes is not None:
            ptr, idx, w = routes.indptr, routes.indices, routes.weights
        else:
            w, idx, ptr = graph.csr_arrays()
        nodes = _path(ptr, idx, w, int(graph.seg_v[seg_a]), int(graph.seg_u[seg_b]),
                      float(limit))
        if not nodes:
            return None
        lookup = lookup if lookup is not None else segment_lookup(graph)
        mid = lookup(nodes[:-1], nodes[1:]) if len(nodes) > 1 else np.zeros(0, np.int64)
        segs = np.concatenate([[seg_a], mid, [seg_b]]).astype(np.int64)
        lens = np.concatenate([[graph.seg_len[seg_a] - along_a], graph.seg_len[mid],
                               [along_b]])
        starts = np.concatenate([[along_a], np.zeros(len(mid) + 1)])
    lens = np.maximum(lens, 0.0)
    total = float(lens.sum())
    cum = np.concatenate([[0.0], np.cumsum(lens)])
    s = fr * total
    k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(segs) - 1)
    sg = segs[k]
    al = np.clip(starts[k] + s - cum[k], 0.0, graph.seg_len[sg])
    L = np.where(graph.seg_len[sg] > 0, graph.seg_len[sg], 1.0)
    a, b = graph.xy[graph.seg_u[sg]], graph.xy[graph.seg_v[sg]]
    return a + (b - a) * (al / L)[:, None], sg, al
