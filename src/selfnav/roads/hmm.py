"""GNSS-only map matching: a hidden Markov model with Viterbi decoding and forward-backward
posteriors (DESIGN §7, issues 5, 14 and 21).

The model follows Newson & Krumm (2009, "Hidden Markov map matching through noise and
sparseness"), with what real fleets need (issue 21):

* **epochs**: the fixes of a track, except that a *stationary run* -- consecutive fixes each
  within 3 σ of the run's mean so far, a car standing still -- is one epoch at the mean of its
  fixes (:func:`selfnav.roads.fixes.stationary_runs`): a standing car has one position, and
  its fixes repeat one correlated error that, counted N times, would outweigh the road it
  drove in on. Each fix gets its run's road position (a run whose fixes move along the road,
  a car crawling in a queue, a fitted constant speed along it);
* **states** at each epoch are road candidates: the closest point of each nearby road (one per
  OSM way and direction) within a search radius, from
  :meth:`selfnav.roads.graph.RoadGraph.candidates` (the nearest always among them); a fix far
  from where its neighbours put it (multipath) also gets the roads near that point
  (:meth:`HmmMatcher._candidates`);
* **emission**: Gaussian in the distance between fix and candidate with a small wide part
  (:meth:`HmmMatcher.emission`), σ the fix's ``sigma_m`` (or the track's);
* **transition**: exponential in the *detour* the route makes between the two road points,
  ``log p = -(d_route - |foot_j - foot_i|) / β`` -- the route distance over the directed
  graph (one-ways respected) against the straight line between the two road points, not
  between the two noisy fixes (Newson & Krumm's ``d_gc``), so that noise between the fixes of
  a slow car is no reason to change roads; a small backwards move on the same road (≤
  ``backtrack`` metres) counts as its length; transitions faster than ``max_speed`` are
  impossible;
* **correlated error**: part of a GNSS error is shared by consecutive fixes (``error_corr``,
  decaying as ``exp(-dt/τ)``); each transition also carries the log ratio of the second fix's
  residual (fix minus road point) given the first's to its residual alone, so a road that
  needs the error to jump between two fixes loses to one that needs the same error twice.
  :meth:`HmmMatcher.estimate_error_corr` estimates it from a fleet's fixes
  (:mod:`selfnav.roads.fleet` does, once per call);
* **breaks**: from any candidate to any candidate of the next epoch, ``log p = LOG_BREAK``:
  where no transition is possible or plausible (candidates the map does not connect, a route
  much longer than the displacement) the chain breaks and restarts, each piece matched on its
  own; a time gap over ``max_gap`` (or a new track) allows only a break;
* **match_p**: the probability that the matched position is on the driven route, from the
  forward-backward posterior, calibrated (:mod:`selfnav.roads.posterior`); **matched**: the
  match is plausible (:class:`MatchResult`).

Route distances come from a :class:`~selfnav.roads.routes.RouteCache` (bounded Dijkstra per
candidate end node, kept and reused across fixes and tracks); the forward pass is one numba
kernel (:mod:`selfnav.roads.viterbi`) that computes each transition on the fly and stores only
the weights it used (for the backward pass), so memory is O(N k) plus those. Long tracks are
processed in windows.

A GNSS-only matcher cannot hold the road through long outlier windows (DESIGN §7): the
inertial prediction is what does (the navigator). :func:`transition_route_distance` and the
candidate search are the parts an INS-driven matcher reuses.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from selfnav.roads import viterbi
from selfnav.roads.fixes import (crawl_positions, error_correlation, neighbour_points,
                                 outliers_on_route, stationary_runs)
from selfnav.roads.graph import RoadGraph
from selfnav.roads.grid import nearest_distance
from selfnav.roads.posterior import calibrate, match_probability, scatter_sigma
from selfnav.roads.routes import (RouteCache, RouteDistances,  # noqa: F401 (API)
                                   transition_route_distance)

#: Lowest GNSS σ a track's fixes are estimated to have, m (:meth:`HmmMatcher.estimate_sigmas`).
SIGMA_MIN_M = 3.0
#: Log probability of a break (the chain restarts: a connection the map lacks, a jump no road
#: explains) at each transition.
LOG_BREAK = -20.0
#: Share of fixes from the wide (multipath) part of the emission, and its σ (m; at least 3σ).
OUTLIER_P = 0.001
OUTLIER_SIGMA_M = 100.0
#: A fix is flagged ``matched`` when its ``match_p`` is at least MATCHED_P, its distance to the
#: road at most MATCHED_GATE σ, and it is not alone in its piece of chain.
MATCHED_P = 0.97
MATCHED_GATE = 3.0
#: ... and never farther than this from its road, m (a track whose fixes lie 100 m from every
#: road gets a σ estimate of 50 m: its match is not plausible, whatever the σ says).
MATCHED_MAX_M = 30.0
#: ... and σ in that test at most SCATTER_K times the scatter of the track's fixes across their
#: roads (:func:`scatter_sigma`; the shared part of the error does not show in it).
SCATTER_K = 2.0
#: Roads near the neighbours' interpolation a far-off fix gets as candidates besides its own.
K_NEIGHBOUR = 4
#: The posterior sums use every log probability divided by this (1: the model's posterior);
#: the Viterbi path does not depend on it.
TEMPERATURE = 1.0
#: A fix farther than OUTLIER_ROUTE_K σ from its matched road is put on the route between its
#: neighbours (:func:`~selfnav.roads.fixes.outliers_on_route`); None: left where it matched.
OUTLIER_ROUTE_K = 5.0
#: A fix within STATIONARY_K σ of the mean of the run before it continues a stationary run.
STATIONARY_K = 3.0
#: Candidates whose road points lie this close (m) count as the same road for ``match_p``.
SAME_ROAD_M = 5.0
#: Correlation time of the shared part of the GNSS error, s.
ERROR_TAU_S = 60.0
#: The shared share the matcher uses is this times :func:`~selfnav.roads.fixes.error_correlation`
#: (which sees only the part across the road; chosen on the tuning fleets), at most
#: ERROR_CORR_MAX.
ERROR_CORR_SCALE = 2.0
ERROR_CORR_MAX = 0.9
#: Calibration of ``match_p`` (:func:`selfnav.roads.posterior.calibrate`): the logistic
#: regression's weights of the posterior's log odds, ``log(1 + moved/σ)``, end of track,
#: ``log(fixes in the track)`` and its intercept, fitted on the tuning fleets
#: (benchmarks/bench_mapmatch.py ``calibrate``: seed 1, both noise bands, both maps and forms).
MATCH_P_COEF = (0.320, -0.592, -0.969, -0.484, 4.786)


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
        :data:`MATCHED_GATE` σ of the road (σ no larger than :data:`SCATTER_K` times the
        scatter of the track's fixes across their roads, and never beyond
        :data:`MATCHED_MAX_M`), and the fix not alone in its piece of chain.
    match_p : (N,) float
        Probability that the matched position is on the driven route: from the posterior
        (forward-backward over the same model, breaks included) of the candidates whose road
        passes within :data:`SAME_ROAD_M` of it, calibrated (:mod:`selfnav.roads.posterior`).
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


@dataclass
class _Epochs:
    """The fixes of a batch of tracks grouped into epochs (a stationary run is one)."""

    run: np.ndarray        # epoch of each fix
    xy: np.ndarray         # (E, 2) mean position of each epoch, m
    sigma: np.ndarray      # (E,) m
    t_in: np.ndarray       # (E,) time of the first fix, s
    t_out: np.ndarray      # (E,) time of the last fix, s
    bounds: np.ndarray     # epochs of each track: starts and the total
    first: np.ndarray      # (E,) first fix of each epoch
    outlier: np.ndarray    # (N,) the fix is an outlier of its run (not in its mean)
    count: np.ndarray      # (E,) fixes in each epoch's mean (its outliers left out)


class HmmMatcher:
    """Hidden-Markov map matching of GNSS fixes to a road graph (Newson & Krumm, with the
    changes of the module docstring).

    Parameters
    ----------
    graph : RoadGraph
    sigma : float
        GNSS horizontal σ (m) where the fixes do not give one (:meth:`estimate_sigma` estimates
        it from a track, :meth:`with_sigma` gives the matcher for it).
    beta : float, optional
        Transition scale (m): a detour of β costs one unit of log probability; default
        ``max(3, sigma/2)``.
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
        Epochs per processing window (candidate search and route distances); memory does not
        grow with it beyond the window.
    cache : RouteCache, optional
        Route distances to share (a fleet on one map reuses them across tracks).
    error_corr : float
        Share of the GNSS error that consecutive fixes have in common (0: independent fixes;
        :meth:`estimate_error_corr`), decaying with ``error_tau`` s.
    calibration : 5 floats or None
        Calibration of ``match_p`` (:func:`selfnav.roads.posterior.calibrate`); None gives the
        posterior itself.

    Notes
    -----
    The route distance between the two road nodes of a transition is searched up to the
    largest straight distance between the road points of the two epochs plus
    ``(|log_break| + 2) β`` (a longer route loses to a break), and never beyond what
    ``max_speed`` allows in the time between them. Memory is O(N k) for N fixes (about 4 kB
    per fix with k = 16: Viterbi scores, forward and backward sums, the stored transition
    weights) plus a bounded route store. ``log_break``, ``outlier_p``, ``outlier_sigma``,
    ``matched_p``, ``matched_gate``, ``temperature`` (of the posterior only),
    ``stationary_k`` and ``outlier_k`` (``OUTLIER_ROUTE_K``): the module's constants of the
    same names.

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
                 stationary_k=STATIONARY_K, error_corr=0.0, error_tau=ERROR_TAU_S,
                 calibration=MATCH_P_COEF, outlier_k=OUTLIER_ROUTE_K):
        self.graph = graph
        self.temperature = float(temperature)
        self.stationary_k = float(stationary_k)
        self.log_break = float(log_break)
        self.cut = abs(self.log_break) + 2.0
        self.outlier_p = float(outlier_p)
        self.outlier_sigma = float(outlier_sigma)
        self.matched_p = float(matched_p)
        self.matched_gate = float(matched_gate)
        self.error_corr = float(error_corr)
        self.error_tau = float(error_tau)
        self.calibration = None if calibration is None else tuple(map(float, calibration))
        self.outlier_k = None if outlier_k is None else float(outlier_k)
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

    def with_error_corr(self, error_corr) -> "HmmMatcher":
        """The same matcher for another shared share of the GNSS error."""
        import copy

        m = copy.copy(self)
        m.error_corr = float(error_corr)
        return m

    def estimate_sigma(self, xy) -> float:
        """GNSS σ of a track from its fixes: ``1.4826 × median`` distance to the nearest road
        (Newson & Krumm 2009, §4.1: the median absolute deviation of a Gaussian), within
        [:data:`SIGMA_MIN_M`, 50] m and rounded to 0.5 m. In a dense network the nearest road
        is not always the driven one, so this leans low."""
        return self.estimate_sigmas([xy])[0]

    def estimate_sigmas(self, tracks_xy) -> list:
        """:meth:`estimate_sigma` of several tracks (local metres) in one search."""
        sizes = [len(np.atleast_2d(x)) for x in tracks_xy]
        xy = np.concatenate([np.atleast_2d(np.asarray(x, float)).reshape(-1, 2)
                             for x in tracks_xy])
        d = nearest_distance(self.graph.grid, xy)
        out = []
        for a, b in zip(np.cumsum([0] + sizes[:-1]), np.cumsum(sizes)):
            s = 1.4826 * float(np.median(d[a:b])) if b > a else self.sigma
            out.append(float(np.clip(np.round(2 * s) / 2, SIGMA_MIN_M, 50.0)))
        return out

    def estimate_error_corr(self, tracks, track_sigma=None) -> float:
        """The shared share of the GNSS error of a set of tracks (``(t, xy, sigma)`` as for
        :meth:`match_many`), from their fixes alone: :data:`ERROR_CORR_SCALE` times
        :func:`~selfnav.roads.fixes.error_correlation` over consecutive fixes (not of one
        stationary run), at most :data:`ERROR_CORR_MAX`. ``track_sigma`` None: each track's σ
        as :meth:`estimate_sigmas` gives it (from the same nearest roads). A fleet's tracks
        share a receiver type and a city: estimate it once over the fleet (a short track alone
        says little: the estimate shrinks to 0)."""
        if not tracks:
            return 0.0
        ts, xy, sig, bounds, _ = self._stack(tracks, track_sigma)
        n = len(xy)
        if n < 2:
            return 0.0
        c = self.graph.candidates(xy, 30.0, k=1, min_candidates=1, per_way=False)
        near = np.searchsorted(c.query, np.arange(n))
        if track_sigma is None:               # σ of the tracks whose fixes give none
            for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
                if tracks[k][2] is None and b > a:
                    s = 1.4826 * float(np.median(c.dist[near[a:b]]))
                    sig[a:b] = float(np.clip(np.round(2 * s) / 2, SIGMA_MIN_M, 50.0))
        run = stationary_runs(xy, bounds, self.stationary_k * sig)
        dt = np.diff(ts)
        forced = (run[1:] == run[:-1]) | ~(dt <= self.max_gap)
        forced[np.asarray(bounds[1:-1], np.int64) - 1] = True      # a new track
        r = error_correlation(xy, c.foot[near], self.graph.seg_heading[c.seg[near]], dt,
                              forced, sig, self.error_tau)
        return float(min(ERROR_CORR_MAX, ERROR_CORR_SCALE * r))

    def _candidates(self, xy, radius, q=None):
        """Candidates of all epochs, searched window by window: ``(off, seg, along, dist, foot,
        pos)`` (``pos``: the position of the fix the candidate stands for).

        With ``q`` (one point per epoch: where its neighbours put it,
        :func:`~selfnav.roads.fixes.neighbour_points`), an epoch that lies more than its search
        radius from its ``q`` also gets the roads near ``q`` (at most :data:`K_NEIGHBOUR`, foot
        points of ``q``, distances from the fix): a multipath outlier then keeps the road its
        neighbours are on as a candidate, instead of only the roads under the outlier."""
        n = len(xy)
        offs, segs, alongs, dists, feet, poss = [np.zeros(1, np.int64)], [], [], [], [], []
        total = 0
        for a in range(0, n, self.window):
            sl = slice(a, a + self.window)
            c = self.graph.candidates(xy[sl], radius[sl], k=self.k, min_candidates=1,
                                      per_way=True)
            qs, ss, als, ds, fs = c.query, c.seg, c.along, c.dist, c.foot
            ps = xy[sl][qs]
            far = np.flatnonzero(np.hypot(*(xy[sl] - q[sl]).T) > radius[sl]) \
                if q is not None else np.zeros(0, np.int64)
            if len(far):
                e = self.graph.candidates(q[sl][far], radius[sl][far], k=K_NEIGHBOUR,
                                          min_candidates=1, per_way=True)
                qe = far[e.query]          # these stand for the fix at q (an outlier)
                qs, ss, als, fs = (np.concatenate([qs, qe]), np.concatenate([ss, e.seg]),
                                   np.concatenate([als, e.along]), np.concatenate([fs, e.foot]))
                ds = np.concatenate([ds, np.hypot(*(xy[sl][qe] - e.foot).T)])
                ps = np.concatenate([ps, q[sl][qe]])
                o = np.lexsort((ds, qs))
                qs, ss, als, ds, fs, ps = qs[o], ss[o], als[o], ds[o], fs[o], ps[o]
            offs.append(np.searchsorted(qs, np.arange(len(xy[sl]) + 1), side="left")[1:] + total)
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

    def _stack(self, tracks, track_sigma):
        """Times, positions and σ of all fixes of ``tracks``, track bounds, the matcher of
        each track (its σ)."""
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
        return ts, xy, sig, bounds, per

    def _epochs(self, ts, xy, sig, bounds) -> _Epochs:
        """Stationary runs of fixes (within :data:`STATIONARY_K` σ of their mean; a single fix
        beyond that between two within it is the standing car's outlier) as epochs."""
        n = len(xy)
        run, out = stationary_runs(xy, bounds, self.stationary_k * sig, outliers=True)
        first = np.flatnonzero(np.diff(run, prepend=-1))
        last = np.concatenate([first[1:] - 1, [n - 1]]) if n else first
        cnt = np.bincount(run).astype(float)
        w = (~out).astype(float)                # an outlier of a standing car: not in the mean
        n_mean = np.bincount(run, w) if n else cnt
        exy = np.column_stack([np.bincount(run, w * xy[:, 0]), np.bincount(run, w * xy[:, 1])]) \
            / n_mean[:, None] if n else xy
        starts = np.asarray(bounds[:-1])
        eb = np.concatenate([run[starts[starts < n]], [len(first)]]).astype(np.int64)
        return _Epochs(run, exy, np.bincount(run, sig) / cnt if n else sig, ts[first],
                       ts[last], eb, first, out, n_mean)

    def _gaps(self, ep: _Epochs):
        """Time from each epoch to the next (inf across tracks) and where only a break is
        allowed (a time gap, a new track)."""
        dt = ep.t_in[1:] - ep.t_out[:-1]
        dt[ep.bounds[1:-1] - 1] = np.inf        # a new track: no transition
        return dt, ~(dt <= self.max_gap)

    def match_many(self, tracks, track_sigma=None) -> list:
        """Match several tracks in one pass (one candidate search, one route-store update, one
        Viterbi run with a restart at each track's first fix): the fixed costs of a call are
        paid once, which is what makes short fleet tracks fast. A track's match does not depend
        on the others of the call.

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
        ts, xy, sig, bounds, per = self._stack(tracks, track_sigma)
        n = len(ts)
        ep = self._epochs(ts, xy, sig, bounds)
        track_of = np.repeat(np.arange(len(per)), np.diff(ep.bounds))
        radius_e, beta_e, back_e = (np.array([getattr(m, a) for m in per])[track_of]
                                    for a in ("radius", "beta", "backtrack"))
        d = self._decode(ep, radius_e, beta_e, back_e)
        point, along, match_p = match_probability(
            d["path"], d["off"], d["post"], d["seg"], d["along"], d["foot"], d["dist"], ep.xy,
            g, ep.bounds, same_m=SAME_ROAD_M)
        restart = d["back"][d["path"]] < 0
        mseg = d["seg"][d["path"]]
        if self.outlier_k is not None:
            point, mseg, along, match_p, restart, _ = outliers_on_route(
                ep.t_in, ep.t_out, ep.xy, point, mseg, along, match_p, ep.sigma, restart,
                ep.bounds, g, k=self.outlier_k, max_speed=self.max_speed,
                reach=self.cut * beta_e, routes=self.cache)
        piece = np.cumsum(restart) - 1
        # alone in its piece of chain (in a track of two epochs or more)
        lone = (np.bincount(piece)[piece] < 2) & np.repeat(np.diff(ep.bounds) >= 2,
                                                            np.diff(ep.bounds))
        # back to the fixes: each fix of a stationary run gets the run's match
        run = ep.run
        start = np.zeros(n, bool)
        start[ep.first] = True
        foot, along = crawl_positions(xy, ts, run, point[run], along[run], mseg[run], g,
                                      ep.sigma, ep.outlier)
        mseg, match_p, in_radius, piece, lone = (v[run] for v in (
            mseg, match_p, d["in_radius"], piece, lone))
        restart = restart[run] & start
        moved = np.hypot(*(xy - foot).T)
        lat, lon = g.to_geodetic(foot[:, 0], foot[:, 1])
        way = g.seg_way[mseg]
        seconds = time.perf_counter() - t0
        scatter = scatter_sigma(xy, mseg, g, bounds)
        out = []
        for m, a, b, s_k in zip(per, bounds[:-1], bounds[1:], scatter):
            sl = slice(a, b)
            # the fix within MATCHED_GATE σ of its road -- with σ no larger than the scatter of
            # the fixes across their roads allows (a track that keeps 25 m beside a road with
            # 2 m of scatter is on a road the map lacks, or carries a bias: not plausible)
            s_gate = sig[sl] if not np.isfinite(s_k) else np.minimum(
                sig[sl], max(SIGMA_MIN_M, SCATTER_K * s_k))
            gate = np.minimum(self.matched_gate * s_gate, MATCHED_MAX_M)
            match_p[sl] = calibrate(match_p[sl], moved[sl] / m.sigma, b - a, self.calibration)
            matched = (moved[sl] <= gate) & (match_p[sl] >= self.matched_p) & ~lone[sl]
            out.append(MatchResult(ts[sl], foot[sl], lat[sl], lon[sl], mseg[sl], along[sl],
                                   moved[sl], in_radius[sl], restart[sl],
                                   seconds * (b - a) / max(n, 1), way[sl], m.sigma,
                                   matched, match_p[sl], piece[sl] - piece[a]))
        return out

    def _decode(self, ep: _Epochs, radius, beta, backtrack) -> dict:
        """Candidates, emissions, Viterbi path and posteriors of the epochs ``ep``: a dict of
        the candidates' arrays (``off``, ``seg``, ``along``, ``dist``, ``foot``, ``query``,
        ``em``), the best path (``path``, ``back``), the posterior of each candidate
        (``post``) and ``in_radius`` per epoch."""
        g = self.graph
        exy, sig = ep.xy, ep.sigma
        n = len(exy)
        q = neighbour_points(exy, ep.bounds, radius)
        off, seg, along, dist, foot, pos = self._candidates(exy, radius, q)
        query = np.repeat(np.arange(n), np.diff(off))
        em = self.emission(dist, sig[query], ep.count[query])
        dt, forced = self._gaps(ep)
        fastest = self.max_speed * np.minimum(dt, self.max_gap) + \
            2 * np.maximum(radius[1:], radius[:-1])
        cut = self.cut
        lim = np.zeros(0)
        if n > 1:
            # the farthest apart two road points of consecutive epochs can be (bounding boxes)
            lo = np.column_stack([np.minimum.reduceat(foot[:, i], off[:-1]) for i in (0, 1)])
            hi = np.column_stack([np.maximum.reduceat(foot[:, i], off[:-1]) for i in (0, 1)])
            span = np.maximum(hi[1:] - lo[:-1], hi[:-1] - lo[1:])
            lim = np.minimum(np.hypot(span[:, 0], span[:, 1]) + cut * beta[:-1], fastest)
        # residuals (the fix's error if the candidate is right), for the shared error; not for
        # the roads of an outlier's neighbours nor beyond 3 σ (the wide part of the emission)
        res = exy[query] - foot
        res[(np.hypot(*(exy[query] - pos).T) > 0) | (dist > 3 * sig[query])] = np.nan
        rho = np.where(forced, 0.0, self.error_corr * np.exp(-np.maximum(dt, 0.0) /
                                                              self.error_tau))
        s2 = np.maximum(sig[1:], sig[:-1]) ** 2
        score = np.empty(len(seg))
        alpha = np.empty(len(seg))
        bet = np.ones(len(seg))
        back = np.full(len(seg), -1, np.int64)
        inv_temp = 1.0 / self.temperature
        if n:
            e0 = slice(off[0], off[1])
            score[e0] = em[e0] - em[e0].max()
            alpha[e0] = np.exp(score[e0] * inv_temp)
            alpha[e0] /= alpha[e0].sum()
        seg_u, seg_v, seg_len = self._g
        kmax = int(np.diff(off).max()) if n else 1
        gap = np.empty((kmax, kmax))
        windows = [(a, min(a + self.window, n - 1)) for a in range(0, n - 1, self.window)]
        stamp = self._stamp[0]
        stored = []                            # transition weights of each window
        for a, b in windows:
            self._ensure_rows(a, b, off, seg, lim, backtrack, forced)
            k_ep = np.diff(off[a:b + 2])
            cap = int(np.sum(k_ep[:-1] * k_ep[1:]))
            pw = np.empty(cap, np.float32)
            pi = np.empty(cap, np.int16)
            pj = np.empty(cap, np.int16)
            pstart = np.empty(b - a + 1, np.int64)
            k = viterbi.forward(a, b, off, seg, along, foot, em, res, forced, lim, fastest,
                                seg_u, seg_v, seg_len, self.cache.arrays, beta, backtrack, rho,
                                s2, self.log_break, cut, score, back, alpha, gap,
                                self._scratch, stamp, inv_temp, pw, pi, pj, pstart)
            stored.append((pw[:k].copy(), pi[:k].copy(), pj[:k].copy(), pstart))
            del pw, pi, pj
        for (a, b), (pw, pi, pj, pstart) in zip(windows[::-1], stored[::-1]):
            viterbi.backward(a, b, off, em, forced, self.log_break, bet, inv_temp, pw, pi, pj,
                             pstart)
        del stored
        self._stamp[0] += n + 1
        post = alpha * bet
        if n:
            post /= np.maximum(np.add.reduceat(post, off[:-1])[query], 1e-300)
        path = viterbi.best_path(off, score, back)
        return {"off": off, "seg": seg, "along": along, "dist": dist, "foot": foot,
                "query": query, "em": em, "path": path, "back": back, "post": post,
                "in_radius": np.bincount(query[dist <= radius[query]], minlength=n) > 0}

    def _ensure_rows(self, a, b, off, seg, lim, backtrack, forced):
        """Route rows for the transitions of epochs ``a .. b-1``: sources the candidates of
        epochs a .. b-1 (forward) and a+1 .. b (backwards jitter)."""
        seg_v = self._g[1]
        lim_w = np.where(forced[a:b], 0.0, lim[a:b])
        self.cache.ensure(
            np.concatenate([seg_v[seg[off[a]:off[b]]], seg_v[seg[off[a + 1]:off[b + 1]]]]),
            np.concatenate([np.repeat(lim_w, np.diff(off[a:b + 1])),
                            np.repeat(backtrack[a + 1:b + 1], np.diff(off[a + 1:b + 2]))]))

    def emission(self, dist, sigma, count=1.0):
        """Log emission of candidates at ``dist`` m from their fix of σ ``sigma`` m: Gaussian,
        with a share ``outlier_p`` of fixes from a wide Gaussian of σ ``outlier_sigma`` (multipath:
        a fix tens of metres off costs a bounded amount, so one bad fix does not pull the match
        onto whatever road lies under it).

        An epoch that is the mean of ``count`` fixes of a standing car, each within 3 σ of the
        others, is an outlier only if all of them are: its wide share is ``outlier_p ** count``
        (else a lone multipath fix and a run of good ones beside it are equally likely to be
        the track's outlier)."""
        so = np.maximum(self.outlier_sigma, 3 * sigma)
        p = self.outlier_p ** np.maximum(count, 1.0)
        return np.logaddexp(np.log1p(-p) - 0.5 * (dist / sigma) ** 2,
                            np.log(p) + np.log(sigma / so) - 0.5 * (dist / so) ** 2)

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
