"""What the fixes of a track say before they meet the map (issue 21): where its neighbours put
each fix, which fixes are one standing car, how the fixes of a standing or crawling car sit
along its road, where a multipath outlier was (on the route between its neighbours), and how
much of the GNSS error is shared by consecutive fixes.

These are the parts of :class:`selfnav.roads.hmm.HmmMatcher` that look at the fixes alone (and,
for an outlier, at the route its neighbours were matched on), in local metres of the road graph,
SI units.
"""
from __future__ import annotations

import numba
import numpy as np


def track_ends(n, bounds):
    """``(first, last)``: boolean masks of the first and last fix of each track (``bounds``:
    track starts and the total, as from ``np.cumsum``)."""
    first = np.zeros(n, bool)
    last = np.zeros(n, bool)
    starts = np.asarray(bounds[:-1], np.int64)
    first[starts[starts < n]] = True
    last[np.asarray(bounds[1:], np.int64)[np.asarray(bounds[1:]) > 0] - 1] = True
    return first, last


def neighbour_points(xy, bounds, radius=None):
    """Where its neighbours put each fix: the midpoint of the fixes before and after it (the
    one neighbour at a track's ends; the fix itself in a track of one), within each track
    (``bounds``: track starts and the total, as from ``np.cumsum``).

    With ``radius`` (per fix, m): a track's end fix whose one neighbour lies farther from the
    fix after it than the end fix does (the neighbour is the likelier outlier) keeps its own
    position, so an outlier next to the end of a track does not move the end fix's roads."""
    n = len(xy)
    if n < 2:
        return xy.copy()
    first, last = track_ends(n, bounds)
    prev = np.vstack([xy[:1], xy[:-1]])
    nxt = np.vstack([xy[1:], xy[-1:]])
    prev = np.where(first[:, None], nxt, prev)
    nxt = np.where(last[:, None], prev, nxt)
    q = np.where((first & last)[:, None], xy, 0.5 * (prev + nxt))
    if radius is not None and n > 2:
        size = np.diff(np.asarray(bounds))
        long_ = np.repeat(size >= 3, size)
        nxt2 = np.vstack([xy[2:], xy[-2:]])
        prev2 = np.vstack([xy[:2], xy[:-2]])

        def d(a, b):
            return np.hypot(*(a - b).T)

        bad = (first & long_ & (d(nxt, nxt2) > d(xy, nxt2))) | \
            (last & long_ & (d(prev, prev2) > d(xy, prev2)))
        q[bad] = xy[bad]
    return q


@numba.njit(cache=True)
def _runs(xy, starts, reach):  # pragma: no cover - numba
    n = len(xy)
    run = np.empty(n, np.int64)
    lone = np.zeros(n, np.bool_)
    r = -1
    cx = cy = 0.0
    m = 0
    for k in range(n):
        if not starts[k] and m > 0 and \
                np.hypot(xy[k, 0] - cx / m, xy[k, 1] - cy / m) > reach[k]:
            # one fix away and the next one back: a multipath outlier of the standing car
            if k + 1 < n and not starts[k + 1] and \
                    np.hypot(xy[k + 1, 0] - cx / m, xy[k + 1, 1] - cy / m) <= reach[k + 1]:
                run[k] = r
                lone[k] = True
                continue
            m = 0
        if starts[k] or m == 0:
            r += 1
            cx = cy = 0.0
            m = 0
        cx += xy[k, 0]
        cy += xy[k, 1]
        m += 1
        run[k] = r
    return run, lone


def stationary_runs(xy, bounds, reach_m, outliers=False):
    """Run number of each fix (0, 1, ... over all tracks): consecutive fixes of a track each
    within ``reach_m`` (per fix, m) of the mean of the run so far are one run -- a car standing
    still (or crawling), matched as one position. A single fix beyond the reach whose next fix
    is back within it belongs to the run too, as an outlier (multipath while standing): with
    ``outliers``, also returns the mask of those (left out of the run's mean)."""
    first, _ = track_ends(len(xy), bounds)
    run, lone = _runs(np.ascontiguousarray(xy, float), first, np.ascontiguousarray(
        np.broadcast_to(np.asarray(reach_m, float), (len(xy),))))
    return (run, lone) if outliers else run


def crawl_positions(xy, t, run, foot, along, seg, graph, sigma, outlier=None):
    """Road positions of the fixes of runs matched as one (one row per fix; ``foot``,
    ``along`` and ``seg`` are the run's, repeated; ``sigma`` per run, m).

    A run is a car standing still or crawling: its motion along its segment is fitted as a
    constant speed to its fixes (not to its ``outlier`` fixes), and the fitted motion shrunk
    towards standing still by the share of it the noise explains (positive-part James-Stein:
    ``max(0, 1 - σ² / Σ fitted²)``, one degree of freedom), clipped to the segment. A standing
    car's fixes all get (about) the run's point, a slow car's its fitted positions."""
    keep = np.ones(len(run), bool) if outlier is None else ~np.asarray(outlier, bool)
    m = int(run.max()) + 1 if len(run) else 0
    cnt = np.bincount(run[keep], minlength=m)
    many = (cnt[run] >= 2) & keep
    if not many.any():
        return foot, along

    def unit(sg):
        L = graph.seg_len[sg]
        return L, (graph.xy[graph.seg_v[sg]] - graph.xy[graph.seg_u[sg]]) / \
            np.where(L > 0, L, 1.0)[:, None]

    r = run[many]
    _, u = unit(seg[many])
    s = np.einsum("ij,ij->i", xy[many] - foot[many], u)       # along the road from the run's
    tt = t[many]                                              # point
    c = np.maximum(cnt, 1)
    mt = np.bincount(r, tt, m) / c
    ms = np.bincount(r, s, m) / c
    stt = np.bincount(r, (tt - mt[r]) ** 2, m)
    slope = np.bincount(r, (tt - mt[r]) * (s - ms[r]), m) / np.where(stt > 0, stt, np.inf)
    fitted = slope ** 2 * stt                                 # Σ of the fitted motion²
    shrink = np.where(fitted > 0, np.maximum(0.0, 1.0 - sigma[:m] ** 2 /
                                             np.where(fitted > 0, fitted, 1.0)), 0.0)
    every = (cnt >= 2)[run]                                   # (its outliers too)
    r = run[every]
    L, u = unit(seg[every])
    fit = np.clip(along[every] + ms[r] + shrink[r] * slope[r] * (t[every] - mt[r]), 0.0, L)
    along, foot = along.copy(), foot.copy()
    along[every] = fit
    foot[every] = graph.xy[graph.seg_u[seg[every]]] + u * fit[:, None]
    return foot, along


def error_correlation(xy, near, heading, dt, forced, sigma, tau, prior=20.0):
    """The share of the GNSS error that consecutive fixes have in common, from the fixes
    themselves (no match needed): the correlation of the offsets of consecutive fixes from
    their nearest roads, over the pairs whose two nearest roads are parallel (within 20°) and
    within 3 σ, each pair's lag divided out as ``exp(-dt/tau)``, shrunk towards 0 by ``prior``
    pseudo-pairs (a few fixes say little). White noise gives about 0, a Gauss-Markov error
    with half the variance gives 0.2-0.45 (the offsets to the nearest road see only the part
    across the road, and a fix nearer another road than its own points away): the matcher
    scales it (:data:`selfnav.roads.hmm.ERROR_CORR_SCALE`).

    Parameters
    ----------
    xy, near : (N, 2) m
        Fixes (or runs) and their nearest road points.
    heading : (N,) rad
        Direction of the nearest road.
    dt : (N-1,) s
        Time from each fix to the next.
    forced : (N-1,) bool
        No transition there (a new track, a gap).
    sigma : (N,) m
    tau : float
        Correlation time of the shared part, s.
    """
    if len(xy) < 2:
        return 0.0
    r = xy - near
    dist = np.hypot(*r.T)
    d_h = np.abs((heading[1:] - heading[:-1] + np.pi / 2) % np.pi - np.pi / 2)
    ok = (~forced) & (d_h < np.radians(20.0)) & (dist[1:] < 3 * sigma[1:]) & \
        (dist[:-1] < 3 * sigma[:-1])
    if not ok.any():
        return 0.0
    a, b = r[:-1][ok], r[1:][ok]
    w = np.exp(-np.maximum(dt[ok], 0.0) / tau)
    num = np.sum(np.einsum("ij,ij->i", a, b) * w)
    den = np.sum(w * w * 0.5 * (np.einsum("ij,ij->i", a, a) + np.einsum("ij,ij->i", b, b)))
    return float(np.clip(num / (den + prior * np.median(sigma) ** 2), 0.0, 1.0))


def outliers_on_route(t_in, t_out, xy, point, seg, along, match_p, sigma, restart, bounds,
                      graph, *, k=5.0, max_speed=60.0, reach=None, routes=None):
    """Road positions of the outliers: an epoch whose fix lies more than ``k`` σ from its
    matched point (the matcher took it as multipath: its emission came from the wide part),
    between good epochs of the same track, is put on the shortest route between its
    neighbours' matched positions, at the share of that route's length its time gives (a run
    of outliers, each at its own time). The road nearest where the neighbours put it
    (:func:`neighbour_points`) can be a side street the route never takes — or one the fix
    before cannot reach or the next one cannot be reached from, and the chain broke at it:
    such a break is closed. Its ``match_p`` is then its less sure neighbour's (the point
    stands on their route).

    The route is searched as the matcher searches a transition: up to the straight distance
    between the neighbours' points plus ``reach`` (per epoch, m: the matcher's (|log break| +
    2) β), never beyond ``max_speed`` × the time between them (``routes``: the matcher's
    :class:`~selfnav.roads.routes.RouteCache`, for its adjacency arrays). Returns ``(point,
    seg, along, match_p, restart, placed)`` (copies; ``placed`` marks the epochs moved); an
    outlier at a track's end, or without such a route, keeps its match."""
    from selfnav.roads.routes import points_along_route, segment_lookup

    point, seg, along = point.copy(), seg.copy(), along.copy()
    match_p, restart = match_p.copy(), restart.copy()
    n = len(point)
    out = np.hypot(*(xy - point).T) > k * sigma
    placed = np.zeros(n, bool)
    if not out.any():
        return point, seg, along, match_p, restart, placed
    lookup = segment_lookup(graph)
    track = np.repeat(np.arange(len(bounds) - 1), np.diff(bounds))
    i = 0
    while i < n:
        if not out[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and out[j + 1] and track[j + 1] == track[i]:
            j += 1
        a, b = i - 1, j + 1
        if a >= 0 and b < n and track[a] == track[i] == track[b] and not out[a] \
                and not out[b]:
            span = float(t_in[b] - t_out[a])
            if span > 0:
                fr = (t_in[i:b] - t_out[a]) / span
                limit = max_speed * span
                if reach is not None:
                    limit = min(limit, float(np.hypot(*(point[b] - point[a]))) + reach[a])
                r = points_along_route(graph, seg[a], along[a], seg[b], along[b], fr,
                                       limit=limit, routes=routes, lookup=lookup)
                if r is not None:
                    point[i:b], seg[i:b], along[i:b] = r
                    match_p[i:b] = min(match_p[a], match_p[b])
                    placed[i:b] = True
                    restart[i:b + 1] = False
        i = j + 1
    return point, seg, along, match_p, restart, placed
