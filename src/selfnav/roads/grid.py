"""A uniform grid over straight segments and the candidate search of map matching (numba).

Each segment is listed in every cell its bounding box touches; a query scans the cells within
its radius, measures each segment once (the foot of the perpendicular, clipped to the segment,
as :func:`selfnav.roads.graph.project_points_to_segments`), keeps the nearest segment per key
(OSM way and direction, or the segment itself) and then the ``k`` nearest keys — the same
selection as sorting everything by (distance, segment) and pruning, without building the list
of all pairs. It replaces an R-tree query plus numpy sorting (about ten times the work) in the
hot path of :meth:`selfnav.roads.graph.RoadGraph.candidates`.
"""
from __future__ import annotations

import numba
import numpy as np


class SegmentGrid:
    """Uniform grid index over segments ``a[i] -> b[i]`` (local metres).

    Parameters
    ----------
    a, b : (M, 2)
        Segment ends.
    cell : float
        Cell size, m (enlarged if the grid would have more than ``max_cells`` cells).
    """

    def __init__(self, a, b, cell=50.0, max_cells=4_000_000):
        a = np.asarray(a, float)
        b = np.asarray(b, float)
        lo = np.minimum(a, b)
        hi = np.maximum(a, b)
        self.x0, self.y0 = (lo.min(axis=0) - 1.0) if len(a) else (0.0, 0.0)
        ext = (hi.max(axis=0) + 1.0 - (self.x0, self.y0)) if len(a) else np.ones(2)
        cell = max(float(cell), float(np.sqrt(ext[0] * ext[1] / max_cells)))
        self.cell = cell
        self.nx = int(ext[0] // cell) + 1
        self.ny = int(ext[1] // cell) + 1
        ix0 = ((lo[:, 0] - self.x0) // cell).astype(np.int64)
        iy0 = ((lo[:, 1] - self.y0) // cell).astype(np.int64)
        ix1 = ((hi[:, 0] - self.x0) // cell).astype(np.int64)
        iy1 = ((hi[:, 1] - self.y0) // cell).astype(np.int64)
        self.start, self.items = _fill(ix0, iy0, ix1, iy1, self.nx, self.ny)
        self.a, self.b = a, b
        self._scratch = {}
        self._stamp = 0

    def scratch(self, n_keys):
        """Scratch arrays of the query kernel and the stamp to start from (so that nothing of
        the size of the map is allocated or cleared per query)."""
        s = self._scratch.get(n_keys)
        if s is None:
            s = self._scratch[n_keys] = (np.full(len(self.a), -1, np.int64),
                                         np.full(n_keys, -1, np.int64),
                                         np.full(n_keys, -1, np.int64))
        return (*s, self._stamp)

    def advance(self, n):
        """Move the stamp past ``n`` points just queried."""
        self._stamp += n + 1


@numba.njit(cache=True)
def _fill(ix0, iy0, ix1, iy1, nx, ny):  # pragma: no cover - numba
    count = np.zeros(nx * ny + 1, np.int64)
    for s in range(len(ix0)):
        for ix in range(ix0[s], ix1[s] + 1):
            for iy in range(iy0[s], iy1[s] + 1):
                count[iy * nx + ix + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    items = np.empty(start[-1], np.int64)
    for s in range(len(ix0)):
        for ix in range(ix0[s], ix1[s] + 1):
            for iy in range(iy0[s], iy1[s] + 1):
                c = iy * nx + ix
                items[fill[c]] = s
                fill[c] += 1
    return start, items


@numba.njit(cache=True, inline="always")
def _foot(px, py, ax, ay, bx, by):  # pragma: no cover - numba
    """The foot of the perpendicular from ``(px, py)`` on segment ``a -> b``, clipped to it:
    ``(along, ux, uy, fx, fy)`` — the one measurement both searches make (the same value to
    the last bit in each)."""
    dx, dy = bx - ax, by - ay
    L = np.hypot(dx, dy)
    Ls = L if L > 0 else 1.0
    ux, uy = dx / Ls, dy / Ls
    al = (px - ax) * ux + (py - ay) * uy
    al = min(max(al, 0.0), L)
    return al, ux, uy, ax + ux * al, ay + uy * al


@numba.njit(cache=True)
def _query(xy, p0, radii, k, key, heading, heading_tol, seg_heading, x0, y0, cell,
           nx, ny, start, items, a, b, seen, key_stamp, key_best, stamp0, out_q, out_s,
           out_along, out_cross, out_dist, out_foot, pos):  # pragma: no cover - numba
    """Candidates of points ``p0 ..``: appended to ``out_*`` from ``pos``. Returns
    ``(next point, pos)``; stops early when the output is full. ``seen``, ``key_stamp`` and
    ``key_best`` are scratch arrays (stamped with ``stamp0 + point``, never reset)."""
    n = len(xy)
    buf_s = np.empty(256, np.int64)
    buf_d = np.empty(256)
    buf_al = np.empty(256)
    buf_cr = np.empty(256)
    buf_fx = np.empty(256)
    buf_fy = np.empty(256)
    keys = np.empty(256, np.int64)
    cap = len(out_q)
    for q in range(p0, n):
        stamp = stamp0 + q
        radius = radii[q]
        r2 = radius * radius
        px, py = xy[q, 0], xy[q, 1]
        cx0 = max(0, int(np.floor((px - radius - x0) / cell)))
        cx1 = min(nx - 1, int(np.floor((px + radius - x0) / cell)))
        cy0 = max(0, int(np.floor((py - radius - y0) / cell)))
        cy1 = min(ny - 1, int(np.floor((py + radius - y0) / cell)))
        m = 0
        nk = 0
        use_h = heading_tol >= 0 and not np.isnan(heading[q])
        for cy in range(cy0, cy1 + 1):
            for cx in range(cx0, cx1 + 1):
                c = cy * nx + cx
                for e in range(start[c], start[c + 1]):
                    s = items[e]
                    if seen[s] == stamp:
                        continue
                    seen[s] = stamp
                    al, ux, uy, fx, fy = _foot(px, py, a[s, 0], a[s, 1], b[s, 0], b[s, 1])
                    rx, ry = px - a[s, 0], py - a[s, 1]
                    ddx, ddy = px - fx, py - fy
                    if ddx * ddx + ddy * ddy > r2:
                        continue
                    if use_h:
                        dh = abs((seg_heading[s] - heading[q] + np.pi) % (2 * np.pi) - np.pi)
                        if dh > heading_tol:
                            continue
                    d = np.hypot(ddx, ddy)
                    if m == len(buf_s):
                        buf_s = np.concatenate((buf_s, buf_s))
                        buf_d = np.concatenate((buf_d, buf_d))
                        buf_al = np.concatenate((buf_al, buf_al))
                        buf_cr = np.concatenate((buf_cr, buf_cr))
                        buf_fx = np.concatenate((buf_fx, buf_fx))
                        buf_fy = np.concatenate((buf_fy, buf_fy))
                        keys = np.concatenate((keys, keys))
                    buf_s[m] = s
                    buf_d[m] = d
                    buf_al[m] = al
                    buf_cr[m] = ux * ry - uy * rx
                    buf_fx[m] = fx
                    buf_fy[m] = fy
                    kk = key[s]
                    if key_stamp[kk] != stamp:
                        key_stamp[kk] = stamp
                        key_best[kk] = m
                        keys[nk] = kk
                        nk += 1
                    else:
                        o = key_best[kk]
                        if d < buf_d[o] or (d == buf_d[o] and s < buf_s[o]):
                            key_best[kk] = m
                    m += 1
        # the k nearest keys, ordered by (distance, segment): selection by insertion
        take = min(k, nk)
        if pos + take > cap:
            return q, pos
        cnt = 0
        for t in range(nk):
            e = key_best[keys[t]]
            d, s = buf_d[e], buf_s[e]
            if cnt == take:
                last = out_s[pos + cnt - 1]
                if d > out_dist[pos + cnt - 1] or (d == out_dist[pos + cnt - 1] and s > last):
                    continue
                cnt -= 1
            w = pos + cnt
            while w > pos and (out_dist[w - 1] > d or (out_dist[w - 1] == d and out_s[w - 1] > s)):
                out_s[w] = out_s[w - 1]
                out_dist[w] = out_dist[w - 1]
                out_along[w] = out_along[w - 1]
                out_cross[w] = out_cross[w - 1]
                out_foot[w, 0] = out_foot[w - 1, 0]
                out_foot[w, 1] = out_foot[w - 1, 1]
                w -= 1
            out_s[w] = s
            out_dist[w] = d
            out_along[w] = buf_al[e]
            out_cross[w] = buf_cr[e]
            out_foot[w, 0] = buf_fx[e]
            out_foot[w, 1] = buf_fy[e]
            cnt += 1
        for w in range(pos, pos + cnt):
            out_q[w] = q
        pos += cnt
    return n, pos


def grid_candidates(grid: SegmentGrid, xy, radius, k, key, n_keys, heading=None,
                    heading_tol=None, seg_heading=None):
    """Segments within ``radius`` (scalar or one per point) of each point: the nearest per
    ``key`` and of those the ``k`` nearest, ordered by point then (distance, segment).

    Returns ``(query, seg, along, cross, dist, foot)`` arrays (``cross`` positive to the left of
    the segment's direction).
    """
    xy = np.ascontiguousarray(np.atleast_2d(np.asarray(xy, float)))
    n = len(xy)
    radii = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, float), (n,)))
    k = int(k) if k is not None else len(grid.a)
    if heading is None or heading_tol is None:
        heading = np.full(n, np.nan)
        tol = -1.0
        seg_heading = np.zeros(len(grid.a))
    else:
        heading = np.broadcast_to(np.asarray(heading, float), (n,)).copy()
        tol = float(heading_tol)
    cap = max(16, n * min(k, 16))
    out = [np.empty(cap, np.int64), np.empty(cap, np.int64), np.empty(cap), np.empty(cap),
           np.empty(cap), np.empty((cap, 2))]
    p, pos = 0, 0
    while True:
        scratch = grid.scratch(n_keys)       # fresh stamps for every call (a resumed point
        grid.advance(n)                      # starts over)
        p, pos = _query(xy, p, radii, k, key, heading, tol, seg_heading, grid.x0, grid.y0,
                        grid.cell, grid.nx, grid.ny, grid.start, grid.items, grid.a, grid.b,
                        *scratch, out[0], out[1], out[2], out[3], out[4], out[5], pos)
        if p >= n:
            break
        cap = max(2 * cap, pos + min(k, len(grid.a)))
        out = [np.concatenate([o[:pos], np.empty((cap - pos,) + o.shape[1:], o.dtype)])
               for o in out]
    return tuple(o[:pos] for o in out)


def nearest_distance(grid: SegmentGrid, xy):
    """Distance from each point to its nearest segment (``inf`` for every point of an empty
    grid). The cells are visited in rings about the point's own, and a cell no nearer than the
    best segment found so far is skipped: the nearest segment, measured as the candidate search
    measures it (the same value to the last bit), at under a quarter of the search's cost in a
    city centre (the map's evidence on a track, :func:`selfnav.roads.evidence.on_roads_llr`, asks
    for 1,548 points at a time)."""
    xy = np.ascontiguousarray(np.atleast_2d(np.asarray(xy, float)))
    if len(grid.a) == 0:
        return np.full(len(xy), np.inf)
    return _nearest(xy, grid.x0, grid.y0, grid.cell, grid.nx, grid.ny, grid.start, grid.items,
                    grid.a, grid.b)


@numba.njit(cache=True)
def _nearest(xy, x0, y0, cell, nx, ny, start, items, a, b):  # pragma: no cover - numba
    n = len(xy)
    out = np.empty(n)
    for q in range(n):
        px, py = xy[q, 0], xy[q, 1]
        cx = int(np.floor((px - x0) / cell))
        cy = int(np.floor((py - y0) / cell))
        best = np.inf
        ring = 0
        while True:
            # the cells of this ring (Chebyshev distance ``ring`` from the point's cell)
            for iy in range(cy - ring, cy + ring + 1):
                if iy < 0 or iy >= ny:
                    continue
                step = 1 if (iy == cy - ring or iy == cy + ring) else 2 * ring
                ix = cx - ring
                while ix <= cx + ring:
                    if 0 <= ix < nx:
                        # the cell's nearest point: no segment in it is nearer than that
                        gx = max(x0 + ix * cell - px, 0.0, px - (x0 + (ix + 1) * cell))
                        gy = max(y0 + iy * cell - py, 0.0, py - (y0 + (iy + 1) * cell))
                        if gx * gx + gy * gy < best * best:
                            c = iy * nx + ix
                            for e in range(start[c], start[c + 1]):
                                s = items[e]
                                _, _, _, fx, fy = _foot(px, py, a[s, 0], a[s, 1], b[s, 0],
                                                        b[s, 1])
                                d = np.hypot(px - fx, py - fy)
                                if d < best:
                                    best = d
                    ix += step if step > 0 else 1
            # the next ring lies beyond the block of this one
            gap = min(px - (x0 + (cx - ring) * cell), (x0 + (cx + ring + 1) * cell) - px,
                      py - (y0 + (cy - ring) * cell), (y0 + (cy + ring + 1) * cell) - py)
            if gap >= best or (cx - ring <= 0 and cy - ring <= 0 and cx + ring >= nx - 1
                               and cy + ring >= ny - 1):
                break
            ring += 1
        out[q] = best
    return out
