"""GNSS-only map matching: a hidden Markov model with Viterbi decoding and forward-backward
posteriors (DESIGN §7, issues 5, 14 and 21).

The model follows Newson & Krumm (2009, "Hidden Markov map matching through noise and
sparseness"), with what real fleets need (issue 21):

* **states** at each fix are road candidates: the closest point of each nearby road (one per
  OSM way and direction) within a search radius, from
  :meth:`selfnav.roads.graph.RoadGraph.candidates` (the nearest always among them); a fix with no road inside the radius gets its nearest road,
  so that *every* fix is matched; a fix far from where its neighbours put it (multipath) also
  gets the roads near that point (:meth:`HmmMatcher._candidates`);
* **emission**: Gaussian in the distance between fix and candidate with a small wide part
  (:meth:`HmmMatcher.emission`), σ the fix's ``sigma_m`` (or the track's); a stationary run's
  fixes weigh 1/N (:func:`stationary_weight`);
* **transition**: exponential in the difference between the route distance over the directed
  graph (one-ways respected) and the straight-line distance between the two fixes,
  ``log p = -|d_route - d_gc| / β``; a small backwards move on the same road (≤ ``backtrack``
  metres, a stopped car in noise) counts as its length; transitions faster than ``max_speed``
  are impossible;
* **breaks**: from any candidate to any candidate of the next fix, ``log p = LOG_BREAK``:
  where no transition is possible or plausible (candidates the map does not connect, a route
  much longer than the displacement) the chain breaks and restarts, each piece matched on its
  own; a time gap over ``max_gap`` (or a new track) allows only a break;
* **match_p**: the forward-backward posterior that the chosen road point is on the driven
  road; **matched**: the match is plausible (:class:`MatchResult`).

Route distances come from a :class:`~selfnav.roads.routes.RouteCache` (bounded Dijkstra per
candidate end node, kept and reused across fixes and tracks); the forward pass is one numba
kernel that computes each transition on the fly and stores only the weights it used (for the
backward pass), so memory is O(N k) plus those. Long tracks are processed in windows.

A GNSS-only matcher cannot hold the road through long outlier windows (DESIGN §7): the
inertial prediction is what does (the navigator). :func:`transition_route_distance` and the
candidate search are the parts an INS-driven matcher reuses.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numba
import numpy as np

from selfnav.roads.graph import Candidates, RoadGraph, project_points_to_segments
from selfnav.roads.routes import RouteCache, route_gap


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
        The chain restarted at this fix: the first fix, or a break (no transition possible
        or plausible: a time gap, candidates the map does not connect, a route much longer
        than the fixes' displacement). Each piece between breaks is matched on its own.
    seconds : float
        Processing time.
    way : (N,) int64
        OpenStreetMap way id of the matched segment.
    sigma : float
        The GNSS σ the track was matched with where its fixes give none, m.
    matched : (N,) bool
        The match is plausible: ``match_p`` at least :data:`MATCHED_P`, the fix within
        :data:`MATCHED_GATE` σ of the road, and the fix not alone in its piece of chain.
    match_p : (N,) float
        Posterior probability (forward-backward over the same model, breaks included) that the
        chosen road position is on the driven road: the posterior mass of the candidates whose
        road segment passes within :data:`SAME_ROAD_M` of it.
    piece : (N,) int
        Piece of chain (0, 1, ... at each break).
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
    way: np.ndarray | None = None
    sigma: float = float("nan")
    matched: np.ndarray | None = None
    match_p: np.ndarray | None = None
    piece: np.ndarray | None = None

    @property
    def breaks(self) -> int:
        """Places where the chain was broken and restarted (the first fix not counted)."""
        return int(np.sum(self.restart)) - 1 if len(self.t) else 0

    def quality(self) -> dict:
        """The track's quality summary: share of fixes flagged matched, breaks, median distance
        from fix to road, mean ``match_p``."""
        n = len(self.t)
        ok = self.matched if self.matched is not None else self.in_radius
        return {
            "fixes": n,
            "matched_share": float(np.mean(ok)) if n else 0.0,
            "breaks": self.breaks,
            "median_cross_m": float(np.median(self.moved)) if n else 0.0,
            "mean_match_p": float(np.mean(self.match_p)) if n and self.match_p is not None
            else None,
        }

    def summary(self) -> dict:
        n = len(self.t)
        return {
            **self.quality(),
            "in_radius_share": float(np.mean(self.in_radius)) if n else 0.0,
            "mean_correction_m": float(np.mean(self.moved)) if n else 0.0,
            "max_correction_m": float(np.max(self.moved)) if n else 0.0,
            "restarts": int(np.sum(self.restart)),
            "seconds": self.seconds,
            "fixes_per_second": n / self.seconds if self.seconds > 0 else None,
        }


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


@numba.njit(cache=True)
def _epoch_step(t, off, seg, along, foot, pos, lim, fastest, seg_u, seg_v, seg_len,
                cache_arrays, beta, backtrack, cut, gap, scratch, stamp, score, back, alpha,
                log_break, pb, inv_temp, pw, pi, pj, k):  # pragma: no cover - numba
    """One step of :func:`_forward`, epoch ``t`` to ``t+1``: the transitions computed on the
    fly, the Viterbi scores and back-pointers and the forward sums of epoch ``t+1`` (before
    its emissions) updated, the transition weights stored from ``pw[k]`` on; returns the new
    ``k``.

    The route distance of a transition (the scalar form of :func:`transition_route_distance`,
    forward gap cut at ``lim``): the end node of each candidate segment of epoch ``t`` is a
    source, the start nodes of epoch ``t+1`` the targets; each source's cached row (in distance
    order) is scanned once up to ``lim`` into a small source × target table. A route is never
    shorter than the straight line between its ends, so a pair whose bound
    ``max(0, |foot_j - foot_i| - d_gc)/β`` passes ``cut`` is no transition without a look-up
    (it would lose to a break by more than ``cut - |log p_break|``); so is a pair whose bound
    can beat neither the best Viterbi score of ``j`` so far nor add to its sum more than
    1e-4 of the break's share. ``d_gc`` is the distance
    between the positions ``pos`` of the fix as each candidate sees it: the fix itself, or for
    a neighbour candidate (:meth:`HmmMatcher._candidates`) where its neighbours put it."""
    row_of, row_start, row_len, pool_node, pool_dist = cache_arrays
    tgt_stamp, tgt_slot, src_stamp, src_slot = scratch   # node-sized, stamped, never reset
    i0, i1 = off[t], off[t + 1]
    j0, j1 = off[t + 1], off[t + 2]
    b_t = beta[t]
    bt = backtrack[t + 1]
    n_tgt = 0
    for j in range(j0, j1):
        u = seg_u[seg[j]]
        if tgt_stamp[u] != stamp:
            tgt_stamp[u] = stamp
            tgt_slot[u] = n_tgt
            n_tgt += 1
    for j in range(j0, j1):
        score[j] = log_break                 # break from the best (score max is 0)
        back[j] = -1
        alpha[j] = pb                        # break: from all of epoch t (alpha sums to 1)
    la_min = np.log(1e-2 * pb)
    n_src = 0
    for i in range(i0, i1):
        s_i = score[i]
        a_i = alpha[i]
        la_i = np.log(a_i) if a_i > 0 else -np.inf
        if s_i < log_break and la_i < la_min:   # loses to a break, adds nothing
            continue
        si, ai = seg[i], along[i]
        rest_i = seg_len[si] - ai
        v_i = seg_v[si]
        if src_stamp[v_i] != stamp:      # scan this source's row once per epoch
            src_stamp[v_i] = stamp
            src_slot[v_i] = n_src
            for m in range(n_tgt):
                gap[n_src, m] = np.inf
            r = row_of[v_i]
            found = 0
            if r >= 0:
                for e in range(row_start[r], row_start[r] + row_len[r]):
                    if pool_dist[e] > lim[t] or found == n_tgt:
                        break
                    w = pool_node[e]
                    if tgt_stamp[w] == stamp:
                        gap[n_src, tgt_slot[w]] = pool_dist[e]
                        found += 1
            n_src += 1
        row = src_slot[v_i]
        for j in range(j0, j1):
            dg = np.hypot(pos[j, 0] - pos[i, 0], pos[j, 1] - pos[i, 1])
            excess = np.hypot(foot[j, 0] - foot[i, 0], foot[j, 1] - foot[i, 1]) - dg
            if excess > cut * b_t:
                continue
            if excess > 0:
                bound = -excess / b_t
                if s_i + bound <= score[j] and la_i + bound * inv_temp < la_min:
                    continue
            sj, aj = seg[j], along[j]
            if si == sj and aj >= ai:
                d = aj - ai
            else:
                d = rest_i + gap[row, tgt_slot[seg_u[sj]]] + aj
            if bt > 0:                   # backwards jitter on a slow or stopped car
                if si == sj and aj < ai:
                    db = ai - aj
                else:
                    rest = (seg_len[sj] - aj) + ai
                    db = np.inf
                    if rest <= bt and rest < d:
                        db = rest + route_gap(row_of, row_start, row_len, pool_node,
                                              pool_dist, seg_v[sj], seg_u[si], bt - rest)
                if db <= bt and db < d:
                    d = db
            if not d <= fastest[t]:
                continue
            v = -abs(d - dg) / b_t
            if v < -cut:
                continue
            if s_i + v > score[j]:
                score[j] = s_i + v
                back[j] = i
            wv = np.exp(v * inv_temp)
            alpha[j] += a_i * wv
            pw[k] = wv
            pi[k] = i - i0
            pj[k] = j - j0
            k += 1
    return k


@numba.njit(cache=True)
def _forward(a, b, off, seg, along, foot, em, pos, forced, lim, fastest, seg_u, seg_v,
             seg_len, cache_arrays, beta, backtrack, log_break, cut, score, back, alpha,
             gap, scratch, stamp0, inv_temp, pw, pi, pj, pstart):  # pragma: no cover
    """Viterbi (``score``, ``back``) and forward sums (``alpha``, linear, each epoch summing
    to 1) over the transitions ``a -> a+1 ... b-1 -> b`` (epoch ``a`` already done). Besides
    the road transitions, every candidate can be reached by a **break** from any candidate of
    the epoch before, with log probability ``log_break`` (the chain restarts there: a map that
    lacks a connection, a jump no road explains); ``forced[t]`` (a time gap, a new track)
    allows only the break. ``back[j] = -1`` marks a break. Scores are kept near 0 (the best of
    each epoch is subtracted).

    The sums use every log probability times ``inv_temp``; the weights ``exp(inv_temp · log
    p)`` of the road transitions are stored (``pw`` with local indices ``pi``, ``pj``; epoch
    ``t``'s from ``pstart[t - a]``) for :func:`_backward`, which so needs no route look-up.
    Returns the number of weights stored."""
    pb = np.exp(log_break * inv_temp)
    k = 0
    for t in range(a, b):
        i0, i1 = off[t], off[t + 1]
        j0, j1 = off[t + 1], off[t + 2]
        pstart[t - a] = k
        em_max = -np.inf
        for j in range(j0, j1):
            em_max = max(em_max, em[j])
        if forced[t]:
            best_s = -np.inf
            tot = 0.0
            for j in range(j0, j1):
                score[j] = em[j]
                back[j] = -1
                alpha[j] = np.exp((em[j] - em_max) * inv_temp)
                tot += alpha[j]
                best_s = max(best_s, score[j])
            for j in range(j0, j1):
                score[j] -= best_s
                alpha[j] /= tot
            continue
        k = _epoch_step(t, off, seg, along, foot, pos, lim, fastest, seg_u, seg_v, seg_len,
                        cache_arrays, beta, backtrack, cut, gap, scratch, stamp0 + t, score,
                        back, alpha, log_break, pb, inv_temp, pw, pi, pj, k)
        best_s = -np.inf
        tot = 0.0
        for j in range(j0, j1):
            score[j] += em[j]
            best_s = max(best_s, score[j])
            alpha[j] *= np.exp((em[j] - em_max) * inv_temp)
            tot += alpha[j]
        for j in range(j0, j1):      # keep scores near 0 (no drift over long tracks)
            score[j] -= best_s
            alpha[j] /= tot
    pstart[b - a] = k
    return k


@numba.njit(cache=True)
def _backward(a, b, off, em, forced, log_break, bet, inv_temp, pw, pi, pj,
              pstart):  # pragma: no cover - numba
    """Backward sums (``bet``, linear, each epoch's maximum 1) over the transitions
    ``b-1 -> b ... a -> a+1`` (epoch ``b`` already done), from the weights :func:`_forward`
    stored: the same model."""
    pb = np.exp(log_break * inv_temp)
    ww = np.empty(max(1, np.max(off[a + 1:b + 2] - off[a:b + 1])))
    for t in range(b - 1, a - 1, -1):
        i0, i1 = off[t], off[t + 1]
        j0, j1 = off[t + 1], off[t + 2]
        em_max = -np.inf
        for j in range(j0, j1):
            em_max = max(em_max, em[j])
        tot = 0.0
        for j in range(j0, j1):
            ww[j - j0] = np.exp((em[j] - em_max) * inv_temp) * bet[j]
            tot += ww[j - j0]
        if forced[t]:
            for i in range(i0, i1):
                bet[i] = 1.0
            continue
        for i in range(i0, i1):
            bet[i] = pb * tot
        for k in range(pstart[t - a], pstart[t - a + 1]):
            bet[i0 + pi[k]] += pw[k] * ww[pj[k]]
        mx = 0.0
        for i in range(i0, i1):
            mx = max(mx, bet[i])
        for i in range(i0, i1):
            bet[i] = bet[i] / mx if mx > 0 else 1.0


@numba.njit(cache=True)
def _backtrack(off, score, back):  # pragma: no cover - numba
    """Best path: from the best candidate of the last epoch (and of the epoch before each
    break) along the back-pointers."""
    n = len(off) - 1
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
    return path


#: Lowest GNSS σ a track's fixes are estimated to have, m (:meth:`HmmMatcher.estimate_sigmas`).
SIGMA_MIN_M = 3.0
#: Log probability of a break (the chain restarts: a connection the map lacks, a jump no road
#: explains) at each transition.
LOG_BREAK = -20.0
#: Share of fixes from the wide (multipath) part of the emission, and its σ (m; at least 3σ).
OUTLIER_P = 0.001
OUTLIER_SIGMA_M = 100.0
#: A fix is flagged ``matched`` when the posterior of its road is at least MATCHED_P, its
#: distance to the road at most MATCHED_GATE σ, and it is not alone in its piece of chain.
MATCHED_P = 0.7
MATCHED_GATE = 3.0
#: ... and never farther than this from its road, m (a track whose fixes lie 100 m from every
#: road gets a σ estimate of 50 m: its match is not plausible, whatever the σ says).
MATCHED_MAX_M = 30.0
#: Roads near the neighbours' interpolation a far-off fix gets as candidates besides its own.
K_NEIGHBOUR = 4
#: The posterior (``match_p``) is computed with every log probability divided by this: the model
#: treats fixes as independent, real errors are correlated over tens of seconds, so the plain
#: posterior is overconfident. The Viterbi path does not depend on it.
TEMPERATURE = 1.0
#: A fix within STATIONARY_K σ of the one before continues a stationary run, whose fixes' emissions
#: are weighted N ** -STATIONARY_A (:func:`stationary_weight`).
STATIONARY_K = 2.0
STATIONARY_A = 1.0
#: Candidates whose road points lie this close (m) count as the same road for ``match_p``.
SAME_ROAD_M = 5.0


def neighbour_points(xy, bounds):
    """Where its neighbours put each fix: the midpoint of the fixes before and after it (the
    one neighbour at a track's ends; the fix itself in a track of one), within each track
    (``bounds``: track starts and the total, as from ``np.cumsum``)."""
    n = len(xy)
    q = xy.copy()
    if n < 2:
        return q
    first = np.zeros(n, bool)
    last = np.zeros(n, bool)
    first[np.asarray(bounds[:-1], np.int64)[np.asarray(bounds[:-1]) < n]] = True
    last[np.asarray(bounds[1:], np.int64) - 1] = True
    prev = np.vstack([xy[:1], xy[:-1]])
    nxt = np.vstack([xy[1:], xy[-1:]])
    prev = np.where(first[:, None], nxt, prev)
    nxt = np.where(last[:, None], prev, nxt)
    alone = first & last
    q = np.where(alone[:, None], xy, 0.5 * (prev + nxt))
    return q


def stationary_weight(xy, bounds, step_m, power=1.0):
    """Weight of each fix's emission: ``N ** -power`` for a fix in a stationary run of N fixes
    (consecutive fixes of a track each within ``step_m`` m of the one before), 1 elsewhere. A
    standing car's fixes repeat the same (correlated) error: counted as N independent looks
    they would outweigh the road the car drove in on."""
    n = len(xy)
    if n < 2:
        return np.ones(n)
    step = np.hypot(*(xy[1:] - xy[:-1]).T) <= np.minimum(step_m[1:], step_m[:-1])
    step[np.asarray(bounds[1:-1], np.int64) - 1] = False     # never across tracks
    run = np.concatenate([[0], np.cumsum(~step)])            # run id of each fix
    size = np.bincount(run)[run]
    return size.astype(float) ** -power


class HmmMatcher:
    """Newson & Krumm hidden-Markov map matching of GNSS fixes to a road graph.

    Parameters
    ----------
    graph : RoadGraph
    sigma : float
        GNSS horizontal σ (m) where the fixes do not give one (:meth:`estimate_sigma` estimates
        it from a track, :meth:`with_sigma` gives the matcher for it).
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
    window : int
        Fixes per processing window (candidate search and route distances); memory does not
        grow with it beyond the window.
    cache : RouteCache, optional
        Route distances to share (a fleet on one map reuses them across tracks).

    Notes
    -----
    The route distance between the two road nodes of a transition is searched up to
    ``d_gc + (|log_break| + 2) β`` (``d_gc``: straight-line distance between the fixes; a
    longer route loses to a break), and never beyond what ``max_speed`` allows in the time
    between the fixes. Memory is O(N k) for N fixes (about 4 kB per fix with k = 16: Viterbi
    scores, forward and backward sums, the stored transition weights) plus a bounded route
    store. ``log_break``, ``outlier_p``, ``outlier_sigma``, ``matched_p``, ``matched_gate``,
    ``temperature`` (of the posterior only), ``stationary_k`` and ``stationary_a``: the
    module's constants of the same names.

    Examples
    --------
    >>> m = HmmMatcher(read_roads("map.osm.pbf"), sigma=10.0)     # doctest: +SKIP
    >>> res = m.match_geodetic(t, lat, lon)                          # doctest: +SKIP
    """

    def __init__(self, graph: RoadGraph, *, sigma=10.0, beta=None, radius=None, k=16,
                 backtrack=None, max_speed=60.0, max_gap=120.0, window=4096,
                 cache: RouteCache | None = None, log_break=LOG_BREAK, outlier_p=OUTLIER_P,
                 outlier_sigma=OUTLIER_SIGMA_M, matched_p=MATCHED_P,
                 matched_gate=MATCHED_GATE, temperature=TEMPERATURE,
                 stationary_k=STATIONARY_K, stationary_a=STATIONARY_A):
        self.graph = graph
        self.temperature = float(temperature)
        self.stationary_k = float(stationary_k)
        self.stationary_a = float(stationary_a)
        self.log_break = float(log_break)
        self.cut = abs(self.log_break) + 2.0
        self.outlier_p = float(outlier_p)
        self.outlier_sigma = float(outlier_sigma)
        self.matched_p = float(matched_p)
        self.matched_gate = float(matched_gate)
        self._given = {"beta": beta, "radius": radius, "backtrack": backtrack}
        self._set_sigma(sigma)
        self.k = int(k)
        self.max_speed = float(max_speed)
        self.max_gap = float(max_gap)
        self.window = int(window)
        self.cache = cache if cache is not None else RouteCache(graph)
        nn = graph.n_nodes
        self._scratch = (np.full(nn, -1, np.int64), np.zeros(nn, np.int64),
                         np.full(nn, -1, np.int64), np.zeros(nn, np.int64))
        self._stamp = [0]                   # shared with the copies of with_sigma
        self._g = (np.asarray(graph.seg_u, np.int64), np.asarray(graph.seg_v, np.int64),
                   np.asarray(graph.seg_len, float))

    def _set_sigma(self, sigma):
        self.sigma = float(sigma)
        beta, radius, backtrack = (self._given[k] for k in ("beta", "radius", "backtrack"))
        self.beta = float(beta) if beta is not None else max(3.0, 0.5 * self.sigma)
        self.radius = float(radius) if radius is not None else float(np.clip(4 * self.sigma,
                                                                              30.0, 200.0))
        self.backtrack = float(backtrack) if backtrack is not None else max(15.0, 3 * self.sigma)

    def with_sigma(self, sigma) -> "HmmMatcher":
        """The same matcher (graph, route store, settings given explicitly) for another GNSS σ:
        the defaults that follow σ (β, radius, backtrack) follow it."""
        import copy

        m = copy.copy(self)
        m._set_sigma(sigma)
        return m

    def estimate_sigma(self, xy) -> float:
        """GNSS σ of a track from its fixes: ``1.4826 × median`` distance to the nearest road
        (Newson & Krumm 2009, §4.1: the median absolute deviation of a Gaussian), within
        [5, 50] m and rounded to 0.5 m. In a dense network the nearest road is not always the
        driven one, so this leans low."""
        return self.estimate_sigmas([xy])[0]

    def estimate_sigmas(self, tracks_xy) -> list:
        """:meth:`estimate_sigma` of several tracks (local metres) in one search."""
        sizes = [len(np.atleast_2d(x)) for x in tracks_xy]
        xy = np.concatenate([np.atleast_2d(np.asarray(x, float)).reshape(-1, 2)
                             for x in tracks_xy])
        c = self.graph.candidates(xy, 100.0, k=1, min_candidates=1, per_way=False)
        d = np.full(len(xy), np.nan)
        d[c.query] = c.dist
        out = []
        for a, b in zip(np.cumsum([0] + sizes[:-1]), np.cumsum(sizes)):
            s = 1.4826 * float(np.nanmedian(d[a:b])) if b > a else self.sigma
            out.append(float(np.clip(np.round(2 * s) / 2, SIGMA_MIN_M, 50.0)))
        return out

    def _candidates(self, xy, radius, q=None):
        """Candidates of all fixes, searched window by window: ``(off, seg, along, dist, foot,
        pos)`` (``pos``: the position of the fix the candidate stands for).

        With ``q`` (one point per fix: where its neighbours put it, :func:`neighbour_points`),
        a fix that lies more than its search radius from its ``q`` also gets the roads near
        ``q`` (at most :data:`K_NEIGHBOUR`, foot points of ``q``, distances from the fix): a
        multipath outlier then keeps the road its neighbours are on as a candidate, instead of
        only the roads under the outlier."""
        n = len(xy)
        offs, segs, alongs, dists, feet, poss = [np.zeros(1, np.int64)], [], [], [], [], []
        total = 0
        for a in range(0, n, self.window):
            sl = slice(a, a + self.window)
            c = self.graph.candidates(xy[sl], radius[sl], k=self.k, min_candidates=1,
                                      per_way=True)
            qs, ss, als, ds, fs = c.query, c.seg, c.along, c.dist, c.foot
            ps = xy[sl][qs]
            if q is not None:
                far = np.flatnonzero(np.hypot(*(xy[sl] - q[sl]).T) > radius[sl])
                if len(far):
                    e = self.graph.candidates(q[sl][far], radius[sl][far], k=K_NEIGHBOUR,
                                              min_candidates=1, per_way=True)
                    qe = far[e.query]          # these stand for the fix at q (an outlier)
                    de = np.hypot(*(xy[sl][qe] - e.foot).T)
                    qs, ss, als, ds, fs = (np.concatenate([qs, qe]), np.concatenate([ss, e.seg]),
                                           np.concatenate([als, e.along]),
                                           np.concatenate([ds, de]),
                                           np.concatenate([fs, e.foot]))
                    ps = np.concatenate([ps, q[sl][qe]])
                    o = np.lexsort((ds, qs))
                    qs, ss, als, ds, fs, ps = qs[o], ss[o], als[o], ds[o], fs[o], ps[o]
            m = len(xy[sl])
            offs.append(np.searchsorted(qs, np.arange(m + 1), side="left")[1:] + total)
            total += len(qs)
            segs.append(ss)
            alongs.append(als)
            dists.append(ds)
            feet.append(fs)
            poss.append(ps)
        return (np.concatenate(offs), np.concatenate(segs), np.concatenate(alongs),
                np.concatenate(dists), np.concatenate(feet), np.concatenate(poss))

    def match(self, t, xy, sigma=None) -> MatchResult:
        """Match fixes given in local metres of the graph; see :class:`MatchResult`."""
        return self.match_many([(t, xy, sigma)])[0]

    def match_many(self, tracks, track_sigma=None) -> list:
        """Match several tracks in one pass (one candidate search, one route-store update, one
        Viterbi run with a restart at each track's first fix): the fixed costs of a call are
        paid once, which is what makes short fleet tracks fast.

        Parameters
        ----------
        tracks : list of (t, xy, sigma)
            Times (s), local positions (m) and per-fix σ (or None) of each track.
        track_sigma : list of float, optional
            σ of each track where its fixes give none (default the matcher's); β, the search
            radius and the backtrack follow it unless given explicitly.

        Returns
        -------
        list of MatchResult
        """
        t0 = time.perf_counter()
        g = self.graph
        sizes = [len(np.asarray(tr[0])) for tr in tracks]
        n = int(sum(sizes))
        bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        ts = np.concatenate([np.asarray(tr[0], float) for tr in tracks])
        xy = np.concatenate([np.atleast_2d(np.asarray(tr[1], float)).reshape(-1, 2)
                             for tr in tracks])
        track_sigma = [self.sigma] * len(tracks) if track_sigma is None else track_sigma
        per = [self.with_sigma(s) if s != self.sigma else self for s in track_sigma]
        sig = np.empty(n)
        for m, (a, b), tr in zip(per, zip(bounds[:-1], bounds[1:]), tracks):
            given = None if tr[2] is None else np.asarray(tr[2], float)
            sig[a:b] = m.sigma if given is None else np.where(
                np.isfinite(given) & (given > 0), given, m.sigma)
        radius = np.repeat([m.radius for m in per], sizes)
        beta = np.repeat([m.beta for m in per], sizes)
        backtrack = np.repeat([m.backtrack for m in per], sizes)
        q = neighbour_points(xy, bounds)
        off, seg, along, dist, foot, pos = self._candidates(xy, radius, q)
        query = np.repeat(np.arange(n), np.diff(off))
        em = self.emission(dist, sig[query]) * stationary_weight(
            xy, bounds, self.stationary_k * sig, self.stationary_a)[query]
        d_gc = np.hypot(*(xy[1:] - xy[:-1]).T)
        dt = np.diff(ts)
        dt[bounds[1:-1] - 1] = np.inf          # a new track: no transition, the chain restarts
        forced = ~(dt <= self.max_gap)          # a time gap (or a new track): only a break
        r_ep = np.maximum(radius[1:], radius[:-1]) if n > 1 else np.zeros(0)
        fastest = self.max_speed * np.minimum(dt, self.max_gap) + 2 * r_ep
        cut = self.cut
        # the farthest apart two positions of consecutive fixes can be (fix or neighbours')
        far = np.where(np.hypot(*(xy - q).T) > radius, np.hypot(*(xy - q).T), 0.0)
        lim = np.minimum(d_gc + far[1:] + far[:-1] + cut * beta[:-1], fastest)
        score = np.empty(len(seg))
        alpha = np.empty(len(seg))
        bet = np.ones(len(seg))
        back = np.full(len(seg), -1, np.int64)
        e0 = slice(off[0], off[1])
        score[e0] = em[e0] - em[e0].max()
        alpha[e0] = np.exp(score[e0] / self.temperature)
        alpha[e0] /= alpha[e0].sum()
        seg_u, seg_v, seg_len = self._g
        kmax = int(np.diff(off).max()) if n else 1
        gap = np.empty((kmax, kmax))
        windows = [(a, min(a + self.window, n - 1)) for a in range(0, n - 1, self.window)]
        stamp = self._stamp[0]
        inv_temp = 1.0 / self.temperature
        stored = []                            # transition weights of each window
        for a, b in windows:
            self._ensure_rows(a, b, off, seg, lim, backtrack, forced)
            k_ep = np.diff(off[a:b + 2])
            cap = int(np.sum(k_ep[:-1] * k_ep[1:]))
            pw = np.empty(cap, np.float32)
            pi = np.empty(cap, np.int16)
            pj = np.empty(cap, np.int16)
            pstart = np.empty(b - a + 1, np.int64)
            k = _forward(a, b, off, seg, along, foot, em, pos, forced, lim, fastest, seg_u,
                         seg_v, seg_len, self.cache.arrays, beta, backtrack, self.log_break,
                         cut, score, back, alpha, gap, self._scratch, stamp, inv_temp, pw,
                         pi, pj, pstart)
            stored.append((pw[:k].copy(), pi[:k].copy(), pj[:k].copy(), pstart))
            del pw, pi, pj
        for (a, b), (pw, pi, pj, pstart) in zip(windows[::-1], stored[::-1]):
            _backward(a, b, off, em, forced, self.log_break, bet, inv_temp, pw, pi, pj,
                      pstart)
        del stored
        self._stamp[0] += n + 1
        path = _backtrack(off, score, back)
        restart = back[path] < 0
        # posterior of each candidate, and of the chosen road position (candidates whose road
        # point lies within SAME_ROAD_M of the chosen one: both directions of a two-way road)
        post = alpha * bet
        post /= np.maximum(np.add.reduceat(post, off[:-1])[query], 1e-300)
        g_xy = g.xy
        _, _, d_road, _ = project_points_to_segments(foot[path][query], g_xy[seg_u[seg]],
                                                     g_xy[seg_v[seg]])
        near = d_road <= SAME_ROAD_M
        match_p = np.bincount(query, weights=post * near, minlength=n)
        mseg, malong = seg[path], along[path]
        foot = foot[path]
        lat, lon = g.to_geodetic(foot[:, 0], foot[:, 1])
        in_radius = np.bincount(query[dist <= radius[query]], minlength=n) > 0
        way = g.seg_way[mseg]
        moved = dist[path]
        piece = np.cumsum(restart) - 1
        seconds = time.perf_counter() - t0
        out = []
        for m, a, b in zip(per, bounds[:-1], bounds[1:]):
            sl = slice(a, b)
            pc = piece[sl] - piece[a]
            size = np.bincount(pc)[pc]
            gate = np.minimum(self.matched_gate * sig[sl], MATCHED_MAX_M)
            matched = ((moved[sl] <= gate)
                       & (match_p[sl] >= self.matched_p)
                       & ((size >= 2) | (b - a < 2)))
            out.append(MatchResult(ts[sl], foot[sl], lat[sl], lon[sl], mseg[sl], malong[sl],
                                   moved[sl], in_radius[sl], restart[sl],
                                   seconds * (b - a) / max(n, 1), way[sl], m.sigma,
                                   matched, np.clip(match_p[sl], 0.0, 1.0), pc))
        return out

    def _ensure_rows(self, a, b, off, seg, lim, backtrack, forced):
        """Route rows for the transitions of epochs ``a .. b-1``: sources the candidates of
        epochs a .. b-1 (forward) and a+1 .. b (backwards jitter)."""
        seg_v = self._g[1]
        lim_w = np.where(forced[a:b], 0.0, lim[a:b])
        self.cache.ensure(
            np.concatenate([seg_v[seg[off[a]:off[b]]], seg_v[seg[off[a + 1]:off[b + 1]]]]),
            np.concatenate([np.repeat(lim_w, np.diff(off[a:b + 1])),
                            np.repeat(backtrack[a + 1:b + 1], np.diff(off[a + 1:b + 2]))]))

    def emission(self, dist, sigma):
        """Log emission of candidates at ``dist`` m from their fix of σ ``sigma`` m: Gaussian,
        with a share ``outlier_p`` of fixes from a wide Gaussian of σ ``outlier_sigma`` (multipath:
        a fix tens of metres off costs a bounded amount, so one bad fix does not pull the match
        onto whatever road lies under it)."""
        so = np.maximum(self.outlier_sigma, 3 * sigma)
        return np.logaddexp(np.log1p(-self.outlier_p) - 0.5 * (dist / sigma) ** 2,
                            np.log(self.outlier_p) + np.log(sigma / so) - 0.5 * (dist / so) ** 2)

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
