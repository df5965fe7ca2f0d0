"""How sure the matcher is of each matched position (issue 21): ``match_p``.

From the posterior of every candidate road of every fix (forward-backward over the matcher's
model), the probability that the matched position lies on the driven route:

1. the posterior mass of the candidates of the fix whose road passes within ``same_m`` of the
   matched point (both directions of a two-way road, the other ways a junction joins);
2. a point near an end of its segment is moved to that junction where more of that mass lies
   within ``same_m`` of the junction than of the point (the road is unsure there; the point
   moves at most ``same_m`` along its own road);
3. a route is more than one fix's road: the mass of the fix before's (and after's) candidates
   whose road passes by the point, or that are on the point's OpenStreetMap way, counts too
   (the larger of the three);
4. calibration (:func:`calibrate`): a logistic regression of "within 5 m of the driven route"
   on the posterior's log odds, the fix's distance from its matched road in σ, whether the fix
   ends its track and the track's length, fitted on simulated tuning fleets
   (benchmarks/bench_mapmatch.py ``calibrate``, seed 1; :data:`selfnav.roads.hmm.MATCH_P_COEF`).
   The model's posterior of the road *at that fix* is conservative for the question "is the
   point on the driven route", which the neighbouring roads of the route also answer yes; and
   it is the same for the end fix of a two-fix track as for a fix in the middle of a long one,
   where the first is put on a crossing road beyond a junction far more often.
"""
from __future__ import annotations

import numpy as np

from selfnav.roads.graph import project_points_to_segments

#: The posterior is taken within [P_EPS, 1 - P_EPS] for the calibration (what the output's four
#: decimals resolve; the calibration is fitted on them).
P_EPS = 1e-4


def _ranges(off, epochs):
    """Candidate indices of the given epochs (CSR ``off``) and the position in ``epochs`` of
    each."""
    size = off[epochs + 1] - off[epochs]
    pos = np.repeat(np.arange(len(epochs)), size)
    start = np.repeat(off[epochs] - np.concatenate([[0], np.cumsum(size)[:-1]]), size)
    return np.arange(int(size.sum())) + start, pos


def road_mass(points, off, shift, post, seg, foot, dist, xy, graph, track, same_m,
              need=None, way_of=None):
    """Per epoch ``e``: the posterior mass of the candidates of epoch ``e + shift`` (same track)
    whose road passes within ``same_m`` of ``points[e]`` -- or, with ``way_of`` (the way of the
    point of each epoch), that lie on that way -- for the epochs ``need`` (all by default).

    ``off``: CSR offsets of the candidates per epoch; ``post``, ``seg``, ``foot``, ``dist``:
    per candidate (posterior, segment, road point, distance from its fix); ``xy``,
    ``track``: per epoch."""
    n = len(points)
    e = np.arange(n) if need is None else np.flatnonzero(need)
    e = e[(e + shift >= 0) & (e + shift < n)]
    e = e[track[e] == track[e + shift]]
    w, at = _ranges(off, e + shift)
    ew = e[at]
    pt = points[ew]
    # bounds first: the candidate's own road point within same_m of the point (a hit), or its
    # fix farther from the candidate's road than same_m beyond the point (a miss)
    hit = np.hypot(*(pt - foot[w]).T) <= same_m
    far = dist[w] - np.hypot(*(pt - xy[ew + shift]).T) > same_m
    mid = np.flatnonzero(~hit & ~far)
    if len(mid):
        s = seg[w[mid]]
        _, _, d_road, _ = project_points_to_segments(
            pt[mid], graph.xy[graph.seg_u[s]], graph.xy[graph.seg_v[s]])
        hit[mid] = d_road <= same_m
    if way_of is not None:
        hit |= graph.seg_way[seg[w]] == way_of[ew]
    return np.bincount(ew, weights=post[w] * hit, minlength=n)


def match_probability(path, off, post, seg, along, foot, dist, xy, graph, bounds, *,
                      same_m, slide=True, route=True):
    """The matched point of each epoch (its road point, or a junction: step 2 of the module
    docstring), its offset along its segment, and ``match_p``.

    Parameters
    ----------
    path : (N,) int
        Chosen candidate of each epoch.
    off : (N+1,) CSR offsets of the candidates per epoch
    post, seg, along, foot, dist : per candidate
    xy : (N, 2) m, positions of the epochs
    bounds : track starts and the total (epochs)
    same_m : float

    Returns
    -------
    point : (N, 2) m, along : (N,) m, match_p : (N,)
        ``match_p`` not yet calibrated (:func:`calibrate`).
    """
    n = len(path)
    track = np.repeat(np.arange(len(bounds) - 1), np.diff(bounds))
    point, a_s = foot[path].copy(), along[path].copy()
    s = seg[path]
    args = (off, 0, post, seg, foot, dist, xy, graph, track, same_m)
    p = road_mass(point, *args)
    if slide:
        L = graph.seg_len[s]
        for node, end, at in ((graph.seg_u[s], a_s <= same_m, 0.0),
                              (graph.seg_v[s], L - a_s <= same_m, 1.0)):
            if end.any():
                p_end = road_mass(graph.xy[node], *args, need=end)
                better = end & (p_end > p + 1e-9)
                point[better] = graph.xy[node[better]]
                a_s[better] = at * L[better]
                p = np.where(better, p_end, p)
    if route and n > 1:
        need = p < 1.0 - 1e-9
        way = graph.seg_way[s]
        for shift in (1, -1):
            p = np.maximum(p, road_mass(point, off, shift, post, seg, foot, dist, xy, graph,
                                        track, same_m, need=need, way_of=way))
    return point, a_s, np.clip(p, 0.0, 1.0)


def calibration_features(p, moved_sigma, n_fixes):
    """The regressors of :func:`calibrate` for one track: ``(N, 4)`` -- the posterior's log
    odds (within ±9.2: the four decimals of the output), ``log(1 + moved / σ)``, 1 at the
    track's first and last fix, ``log`` of the track's number of fixes."""
    p = np.asarray(p, float)
    z = np.log(np.clip(p, P_EPS, 1.0)) - np.log(np.clip(1.0 - p, P_EPS, 1.0))
    end = np.zeros(len(p))
    if len(p):
        end[[0, -1]] = 1.0
    return np.column_stack([z, np.log1p(np.asarray(moved_sigma, float)), end,
                            np.full(len(p), np.log(max(n_fixes, 1)))])


def calibrate(p, moved_sigma, n_fixes, coef):
    """``match_p`` of one track's fixes from the model's posterior ``p`` (step 4 of the module
    docstring): ``1 / (1 + exp(-(X·coef[:4] + coef[4])))`` with ``X`` the
    :func:`calibration_features`. ``coef`` None: ``p`` itself."""
    if coef is None or not len(p):
        return np.asarray(p, float)
    x = calibration_features(p, moved_sigma, n_fixes) @ np.asarray(coef[:4]) + coef[4]
    return 1.0 / (1.0 + np.exp(-x))


def scatter_sigma(xy, seg, graph, bounds, min_pairs=3):
    """Per track, the scatter of its fixes across their matched roads: ``1.4826 × median``
    of the change of the signed offset from the road between consecutive fixes on parallel
    roads (within 20°), over √2 -- the part of the error that does not repeat from fix to
    fix. NaN for a track with fewer than ``min_pairs`` such pairs."""
    a, b = graph.xy[graph.seg_u[seg]], graph.xy[graph.seg_v[seg]]
    d = b - a
    L = np.where(graph.seg_len[seg] > 0, graph.seg_len[seg], 1.0)
    cross = (d[:, 0] * (xy[:, 1] - a[:, 1]) - d[:, 1] * (xy[:, 0] - a[:, 0])) / L
    h = graph.seg_heading[seg]
    dh = (h[1:] - h[:-1] + np.pi) % (2 * np.pi) - np.pi
    same = np.abs(dh) < np.radians(20.0)
    flip = np.abs(dh) > np.radians(160.0)
    step = np.abs(cross[1:] - np.where(flip, -cross[:-1], cross[:-1]))
    ok = same | flip
    ok[np.asarray(bounds[1:-1], np.int64) - 1] = False        # never across tracks
    track = np.repeat(np.arange(len(bounds) - 1), np.diff(bounds))[:-1][ok]
    v = step[ok]
    out = np.full(len(bounds) - 1, np.nan)
    cnt = np.bincount(track, minlength=len(out))
    if len(v):                                # median per track: sort by (track, value)
        o = np.lexsort((v, track))
        start = np.concatenate([[0], np.cumsum(cnt)[:-1]])
        lo, hi = start + (cnt - 1) // 2, start + cnt // 2
        has = cnt >= min_pairs
        med = 0.5 * (v[o][np.minimum(lo, len(v) - 1)] + v[o][np.minimum(hi, len(v) - 1)])
        out[has] = 1.4826 * med[has] / np.sqrt(2.0)
    return out
