"""The EKF's road aid (issue 5, ``--method ekf --map``): :class:`EkfRoadAid`.

A :class:`~selfnav.roads.particles.RoadParticles` cloud driven by the INS tells which road line the
vehicle is on; this class turns it into constraints for
:meth:`selfnav.ins.ekf.InsGnssFilter.update_road` — cross-track and road heading on straight roads,
the driven arc through corners — and a level-road prior. docs/navigator.md has the
measurements.
"""
from __future__ import annotations

import math

import numpy as np

from selfnav.earth import offset_to_geodetic
from selfnav.errors import SelfnavError
from selfnav.ins.align import healthy_until, robust_init
from selfnav.ins.config import chi2_999
from selfnav.ins.measurements import LevelRoad, RoadLine
from selfnav.quantiles import binom_isf
from selfnav.roads.corners import MAX_CORNER_TURN, TURN_RATE, TurnWatch, corner_offset
from selfnav.roads.doubt import MapDoubt
from selfnav.roads.evidence import SIGMA_ROAD_M, on_roads_llr, thin_track
from selfnav.roads.graph import RoadGraph
from selfnav.roads.particles import TWO_PI, MatcherConfig, RoadParticles, wrap


#: the share of clean fixes farther than 2 σ from every road running their way (the course
#: tested within 3 of its own σ, :func:`_off_roads`): 2.8–10 % per drive, 5.8 % pooled
#: (16 simulated Helsinki and Kotka drives, 3 900 clean fixes; the normal's 2σ tail alone
#: is 4.6 %)
P_FAR_NOMINAL = 0.06
#: the start's check refuses its fixes at this false-alarm rate of that share (a refusal
#: costs a start 30 s later): 5 of 40 allowed — at 1 %, 6 and 7 of 40, two drifts from
#: power-on were started on (tests/test_roads_aid.py); the old fixed 15 % share allowed 6
ALPHA_START_CHECK = 0.05


def far_allowed(n: int, p_far: float = P_FAR_NOMINAL, alpha: float = ALPHA_START_CHECK) -> int:
    """How many of ``n`` clean fixes may lie far from the roads before the start's check
    refuses them: the binomial ``(n, p_far)`` count exceeded with probability ≤ ``alpha``
    (n = 12: 2, n = 20: 3, n = 40: 5)."""
    return binom_isf(alpha, n, p_far)


def start_on_roads(imu, gnss, graph: RoadGraph, cfg=None, *, span=30.0, far_sigmas=2.0,
                   sigma=10.0, complete: bool = False, give_up_s=120.0,
                   cover_m=250.0, start=None):
    """The navigator's start (:func:`selfnav.ins.align.robust_init`) checked against the map.

    ``robust_init`` waits for a run of fixes that look healthy by themselves; a receiver that
    drifts smoothly from power-on passes that test (its second differences are small) and the
    in-motion alignment takes its drift rate for velocity — tens of degrees of heading at
    walking speed. The map sees it: the fixes from 10 s before the start to ``span`` s after
    (or to where their healthy run ends, :func:`selfnav.ins.align.healthy_until`: an outlier
    window after a good start is not the start's to answer for — simulated drive
    3823853625665908027, whose white window began 12 s after its start, never started) must
    lie on roads that run the way they move (:func:`_off_roads`), no more of them farther
    than ``far_sigmas`` fix σ from every such road than :func:`far_allowed` — a binomial
    test at ``ALPHA_START_CHECK`` of the clean share ``P_FAR_NOMINAL``. If not, the start is
    tried again after that span (up to 20 times); with no start that passes, the first one
    is kept.

    ``complete`` (the causal navigator's start-up): only a start whose whole span lies in the
    data and that follows a healthy run of fixes counts; None until there is one — or, when
    ``give_up_s`` have passed since the first candidate without one on the roads *and* the
    last ``span`` s of fixes lie beyond the map (most with no road at all within ``cover_m``:
    a map that does not cover the drive, a track through fields), the latest. Fixes among
    roads that they do not follow are what is wrong, not the map: a receiver dragged from
    power-on passes the line test, and a start made on it after a fixed wait put the car
    hundreds of metres off at a σ of 5 m (14 of the 45 off-route drives of the simulated
    map campaign, docs/navigator.md); the start waits for fixes on the roads instead. ``cover_m``:
    farther than any point among a town's roads lies from its nearest one (the packaged
    Helsinki centre and Kotka maps: 99 % of points within their roads' hull ≤ 170 m, all
    ≤ 240 m).
    ``start(imu, gnss) -> init`` (raising :class:`SelfnavError` when there is none yet): the
    start to check, default ``robust_init`` — the start-up passes its own, with the fallback
    start of a platform that never gives the car's straight fast run (a car in a city centre:
    without it, the map's check waited 300 s for one that the plain navigator did not need).
    """
    if start is None:
        def start(imu_, sub_):
            return robust_init(imu_, sub_, cfg=cfg, require_healthy=complete)
    sig = np.asarray(gnss.sigma_m, float) if gnss.sigma_m is not None else \
        np.full(len(gnss.t), np.nan)
    sig = np.where(np.isfinite(sig), sig, sigma)
    x, y = graph.to_local(gnss.lat, gnss.lon)
    xy = np.column_stack([x, y])
    first = last = None
    t_from = -np.inf
    for _ in range(20):
        sub = gnss.select(gnss.t >= t_from)
        if len(sub) < 25:
            break
        try:
            init = start(imu, sub)
        except SelfnavError:
            if complete:
                break            # no later start yet: the give-up below still applies
            raise
        first = first or init
        t0 = float(init["t"])
        # the fixes from 10 s before the start to ``span`` after it — but not before its
        # healthy run: fixes already judged unhealthy (an outlier window ending 1–10 s before)
        # are not the start's to answer for. A start anywhere (``start_kind``) may be made on
        # the newest fixes, so the span after it never completes: it answers for every fix
        # from ``span`` before it to now, once they span ``span``
        now_start = "start_kind" in init
        t_check = max(t0 - (span if now_start else 10.0), float(init.get("t_healthy", -np.inf)))
        t_end = float(gnss.t[-1]) if now_start else t0 + span
        broken = False
        if not now_start:
            # the healthy run ends before t_end: the check answers for the fixes up to there
            k0 = int(np.searchsorted(gnss.t, t0))
            k1 = healthy_until(xy, sig, k0, stop=int(np.searchsorted(gnss.t, t_end, "right")),
                               since=int(np.searchsorted(gnss.t, t_check)))
            if k1 < len(gnss.t) and gnss.t[k1] <= t_end:
                t_end, broken = float(gnss.t[k1]) - 1e-6, True
        if complete and (t_end - t_check < span if now_start
                         else not broken and gnss.t[-1] < t_end):
            break
        last = init
        idx = np.flatnonzero((gnss.t >= t_check) & (gnss.t <= t_end))
        if len(idx) < 5 or np.count_nonzero(_off_roads(graph, gnss.t, xy, idx, sig, far_sigmas)) \
                <= far_allowed(len(idx)):
            return init
        if now_start:
            break            # the next one is tried at the next attempt, on newer fixes
        t_from = t0 + span
    if complete:
        # fixes that never lie on the map's roads for this long, and lie where it has none
        # (a map that does not cover the drive): the latest start, not none
        if last is not None and gnss.t[-1] - float(first["t"]) > give_up_s:
            recent = np.flatnonzero(gnss.t >= gnss.t[-1] - span)
            if _beyond_map(graph, xy[recent], cover_m):
                return dict(last, off_map=True)
        return None
    return first if first is not None else robust_init(imu, gnss, cfg=cfg)


def _off_roads(graph, t, xy, idx, sigma, far_sigmas=2.0):
    """For fixes ``idx`` (σ ``sigma`` each, m): is no road running their way within
    ``far_sigmas`` σ (see :func:`start_on_roads`)?

    The way a fix runs is the course of a line through the fixes within ±4 s (where faster
    than 3 m/s); it must lie within 30° of the road's direction, or within 3 of the course's
    own σ (the line's velocity σ over its speed: 18° at 4 m/s on 10 m fixes) where that is
    wider: a 30° test on a slow car's course put a fifth of the clean fixes of a simulated
    drive off the roads (1705009503212533057: 4 of its 12 fixes between an outage and an
    outlier window, 7 of 41 later; it never started), while a drag's fixes run 48° off
    their road at 6 m/s (4922493927024925402)."""
    import shapely

    course = np.full(len(idx), np.nan)
    gate = np.full(len(idx), np.radians(30.0))
    for j, k in enumerate(idx):
        m = np.abs(t - t[k]) <= 4.0
        if m.sum() >= 5:
            tt = t[m] - t[k]
            v = np.polyfit(tt, xy[m], 1)[0]
            speed = float(np.hypot(*v))
            if speed > 3.0:
                course[j] = np.arctan2(v[0], v[1])
                s_course = float(sigma[k]) / math.sqrt(float(np.sum((tt - tt.mean()) ** 2))) \
                    / speed
                gate[j] = max(gate[j], 3.0 * s_course)
    q, si = graph.tree.query(shapely.points(xy[idx]), predicate="dwithin",
                             distance=far_sigmas * np.asarray(sigma, float)[idx])
    ok = np.isnan(course[q]) | (np.abs(wrap(graph.seg_heading[si] - course[q])) < gate[q])
    on = np.zeros(len(idx), bool)
    on[q[ok]] = True
    return ~on


def _near_a_road(graph, xy, distance) -> np.ndarray:
    """Has each point ``xy`` (local m) a road within ``distance`` m?"""
    import shapely

    near = np.zeros(len(xy), bool)
    if len(xy):
        q, _ = graph.tree.query(shapely.points(xy), predicate="dwithin", distance=distance)
        near[q] = True
    return near


def _beyond_map(graph, xy, cover_m) -> bool:
    """Do most of the points ``xy`` (local m) have no road at all within ``cover_m``?"""
    return len(xy) > 0 and _near_a_road(graph, xy, cover_m).sum() < 0.5 * len(xy)


def _sigma_along(P2, u) -> float:
    """The σ of horizontal covariance ``P2`` (2×2, m²) along unit vector ``u``, m."""
    return float(np.sqrt(max(u @ P2 @ u, 0.0)))


def _heading_of(C_nb):
    """True heading (rad, clockwise from North) of the forward axis of ``C_nb`` (DESIGN §2)."""
    fwd = C_nb[1]
    return float(np.arctan2(fwd[0], fwd[1]) % TWO_PI)


class EkfRoadAid:
    """``road_aid`` of :class:`selfnav.Navigator` (``--method ekf --map``).

    At every aiding epoch the cloud travels the INS distance with the INS heading and takes the
    GNSS fixes that have arrived. Once per ``interval`` it returns a constraint for
    :meth:`InsGnssFilter.update_road` when the cloud is confident about the *line* the vehicle
    is on (≥ 0.8 of the weight within 2 m of it, heading within 20°: its spread *along* a
    straight road does not matter, a parallel road or another leg does) and the filter agrees
    across that line within ``max(agree_m, 3σ)`` (else one of the two is on another road):

    * on a straight road, cross-track and road heading;
    * within ``bend_zone`` m of a vertex turning > 20°: against the leg the INS heading matches
      while not turning; while turning, against **the arc** a car drives through the corner —
      the circle tangent to both legs with the radius being driven, ``R = v/ω`` (INS speed over
      the bias-corrected yaw rate, median over the turn after its first 0.4 s), normal towards
      the centre, within ``max(arc_agree_m, 2σ)`` — within ``2·sigma_arc`` while the filter's
      2σ is beyond the arc's length (:meth:`_arc_placed`). The normal sweeps through the turn:
      a corner pins the along-track position too.

    While dead-reckoning a line is no constraint where the filter is nearer, across, to
    another road beside it (:meth:`_nearer_road`): the cloud then has only the map to tell
    parallel roads apart. No constraint either while the cloud's mean is further from the
    filter, in any direction, than ``max(agree_m, 3σ)`` (σ of the filter along that direction
    with the cloud's spread, :meth:`_cloud_agrees`): a cloud left behind at a junction holds
    the line of a road the vehicle has passed.

    ``grade_sigma`` adds a level-road prior ``v_U = 0`` (σ ``grade_sigma·|v| + 0.1`` m/s, once
    per ``interval``): the map has no heights, and without it the filter's pitch error, hardly
    observable from the NHC and σ 15 m GNSS heights, leaked gravity into the speed (1–2 m/s for
    tens of seconds on the simulated drives). σ 0.08 admits ordinary grades (8 %: 0.8 m/s at
    30 km/h); the simulated roads are level. ``None`` switches it off. docs/navigator.md has the
    measurements.

    Parameters
    ----------
    graph : RoadGraph
    gnss : GnssData (WGS-84)
    cfg : MatcherConfig
    sigma_cross : σ of the cross-track constraint, m (lane position and digitising error)
    sigma_arc : σ of the arc constraint, m (the radius estimate, the driver's line)
    sigma_heading : σ of the road-heading constraint, rad (None: no heading constraint)
    interval : s between constraints (the cloud's errors are correlated over seconds)
    agree_m, arc_agree_m : floors of the agreement tests, m
    bend_zone : distance from a bend's vertex within which the corner logic applies, m
    grade_sigma : σ of the road grade (level-road prior; None: off)
    seed : random stream
    lock_m : the filter is on the road when its last constraint found it within this, m
    sigma_corner : σ of a corner fix along and across the road, m (:meth:`_corner_fix`)
    While the navigator takes no fixes (``dead_reckoning``: a fault episode, an outage) the
    cloud follows the dead reckoning: no constraint is given but the level-road prior once the
    filter's horizontal σ is above ``dr_sigma_m``.
    evidence_min_m : :meth:`track_evidence` — the fixes' and the INS's tracks must be this
        far apart (m, and three times their σ) for the map to speak
    line_agree : a corner's leg — and, while dead-reckoning, a road line — is a constraint
        only while the INS heading runs along it within this or three of the filter's heading
        σ, rad (a car not turning drives along its road; the lane changes and the map's
        digitising are within it)
    max_sigma_m : no road constraint while the filter's horizontal position σ (its largest
        axis) is above this, m: a fact of road maps — junctions 50–100 m apart — beyond which
        the cloud cannot tell the road the car is on from the one its dead reckoning drifted
        to (simulated drives: a map-aided dead reckoning 900 m off at σ 10 m)
    dr_sigma_m : while dead-reckoning with an INS no dead reckoning of which has yet stood the
        fixes' test (``ins_vouched`` False), road constraints that may move the filter only
        below this horizontal σ, m (a cloud that follows the dead reckoning can still tell the
        road while the filter is sure to a tenth of the junction spacing; beyond, it takes the
        junction the drift picks: simulated drives 300 m off at σ 10 m — the σ then a lie,
        issue 18); above it, up to ``max_sigma_m``, the road lines only *hold* the filter on
        the road it runs along (:meth:`_holds`). A vouched INS keeps them all up to
        ``max_sigma_m``, its heading checked against the road's. A corner fix stands up to
        ``max_sigma_m`` either way: its own test finds the one junction of the turn within the
        filter's σ
    q_along : (m/s)²/s, along-track speed variance added while the cloud judges GNSS
        unhealthy (:meth:`_widen_along`; None: off)
    doubt_radius_m, doubt_min_m : the map's doubt (:meth:`doubt`,
        :class:`~selfnav.roads.doubt.MapDoubt`'s ``radius_m`` and ``min_m``): the nearest road
        running the filter's way is looked for up to this far, m, and a doubt held when it lies
        this far or farther, m; ``doubt_radius_m`` 0 switches it off
    curve_sigma : σ of the cross-track constraint while turning through a gentle curve (no
        vertex above 20° near), m (None: none, the default: at 2 m it was worse on the 40
        tuning drives, pooled along/cross 60.6 / 48.6 m against 56.3 / 44.5 m, 12 drives more
        than 20 s off the route against 8; with the causal navigator, stop 54: better on the
        tuning seed, 17 → 14 drives, 51.4 / 55.1 → 44.9 / 46.1 m, but on master seed 2 36 → 35
        drives, 17 better and 13 worse by more than 1 m — not a default)
    """

    def __init__(self, graph: RoadGraph, cfg: MatcherConfig | None = None, *,
                 sigma_cross=1.0, sigma_arc=1.0, sigma_heading=np.radians(5.0), interval=1.0,
                 agree_m=10.0, arc_agree_m=4.0, bend_zone=25.0, grade_sigma=0.08, seed=0,
                 lock_m=5.0,
                 sigma_corner=2.5, q_along=0.01, curve_sigma=None, max_sigma_m=30.0,
                 dr_sigma_m=10.0, line_agree=np.radians(8.0), evidence_min_m=20.0,
                 doubt_radius_m=200.0, doubt_min_m=15.0):
        self.g = graph
        self.pf = RoadParticles(graph, cfg, seed)
        self.fix_t, self.fix_xy, self.sig = [], [], []     # the fixes as they arrive
        self.k = 0
        self.t_last = None
        self.sigma_cross = sigma_cross
        self.sigma_arc = sigma_arc
        self.sigma_heading = sigma_heading
        self.interval = interval
        self.agree_m = agree_m
        self.arc_agree_m = arc_agree_m
        self.bend_zone = bend_zone
        self.grade_sigma = grade_sigma
        self.t_grade = -np.inf
        self.t_constraint = -np.inf
        self.hdg_last = None
        self.rates = []        # recent (t, yaw rate)
        self.radii = []        # (heading, v/ω) of the current turn
        self.seg_prev = -1     # the estimate's previous segment (the leg before a vertex)
        self.seg_cur = -1
        self.history = []      # (t, x, y, seg, spread, line share)
        self.corner = self._corner_nodes()
        self.counts = {"line": 0, "leg": 0, "arc": 0, "curve": 0, "grade": 0,
                       "corner": 0, "dr_corner": 0}
        self.curve_sigma = curve_sigma
        self.sigma_corner = sigma_corner
        self.q_along = q_along
        self.watch = TurnWatch()   # the filter's turns (the corner fixes)
        self.corner_log = []       # (t, correction E, N) of each corner fix
        self.lock_m = lock_m
        self.max_sigma_m = max_sigma_m
        self.dr_sigma_m = dr_sigma_m
        self.line_agree = line_agree
        #: set by the navigator while the fixes are not taken (a fault episode, an outage):
        #: the map then only holds an unvouched filter on its road once its σ is above
        #: ``dr_sigma_m`` (:meth:`constraints`)
        self.dead_reckoning = False
        #: set by the navigator: since the start the fault bank has held a reference — a dead
        #: reckoning of the INS that has stood the fixes' test; before, its heading may be off
        #: by more than its σ says, and the road lines are what correct it (:meth:`constraints`)
        self.ins_vouched = True
        self.lock = None           # (t, normal) of the last constraint that found the filter on it
        self.evidence_min_m = evidence_min_m
        #: the map's doubt (:class:`selfnav.roads.doubt.MapDoubt`; None: off)
        self.map_doubt = (MapDoubt(graph, self.pf.off, self.pf.succ, radius_m=doubt_radius_m,
                                   min_m=doubt_min_m) if doubt_radius_m else None)
        #: set by the navigator while a start's heading hypotheses are open: their filters —
        #: the filter's heading may be any of them, and the map's doubt looks from all
        #: (:meth:`~selfnav.roads.doubt.MapDoubt.look`); None when it is one
        self.hypotheses = None
        self._t_look = -np.inf

    # ------------------------------------------------------------------ the stream
    def add_fix(self, t, lat, lon, sigma):
        """A GNSS fix as it arrives (rad, σ per axis m): the cloud takes it when the filter's
        epochs reach its time."""
        x, y = self.g.to_local(lat, lon)
        self.fix_t.append(float(t))
        self.fix_xy.append((float(x), float(y)))
        self.sig.append(float(sigma) if np.isfinite(sigma) else self.pf.cfg.sigma_gnss)

    def track_evidence(self, origin, p_fix, p_ins, sigma_fix, sigma_ins):
        """The map's word on two tracks of the same seconds (the fault bank's run test, while the
        fixes and the INS disagree): ``(e_fix, e_ins)``, each track's
        :func:`selfnav.roads.evidence.on_roads_llr` — how much better it lies on the roads
        within its σ than the same shape put elsewhere — or None while the two are within
        ``evidence_min_m`` and three times their σ of each other (they put the car in the same
        place). ``origin`` (lat, lon rad); tracks East/North m from it, thinned along the
        fixes' track (25 m)."""
        p_fix = np.asarray(p_fix, float)
        p_ins = np.asarray(p_ins, float)
        if len(p_fix) < 2:
            return None

        def local(p):
            # the inverse of the ENU offsets the bank took (selfnav.earth.enu_offset)
            lat, lon, _ = offset_to_geodetic(float(origin[0]), float(origin[1]), 0.0,
                                             np.column_stack([p, np.zeros(len(p))]))
            return np.column_stack(self.g.to_local(lat, lon))

        return self._pair_evidence(local(p_fix), local(p_ins), sigma_fix, sigma_ins)

    def geodetic_track_evidence(self, latlon_a, latlon_b, sigma_a, sigma_b):
        """:meth:`track_evidence` of two tracks given as rows of (lat, lon) rad at the same
        times, thinned along the first."""
        if len(latlon_a) < 2:
            return None
        return self._pair_evidence(self._local(latlon_a), self._local(latlon_b), sigma_a, sigma_b)

    def _local(self, latlon):
        latlon = np.asarray(latlon, float)
        return np.column_stack(self.g.to_local(latlon[:, 0], latlon[:, 1]))

    def _pair_evidence(self, xy_a, xy_b, sigma_a, sigma_b):
        keep = thin_track(xy_a)
        sep = float(np.median(np.hypot(*(xy_a[keep] - xy_b[keep]).T)))
        if sep < max(self.evidence_min_m, 3.0 * math.hypot(sigma_a, sigma_b)):
            return None
        return (on_roads_llr(self.g, xy_a[keep], sigma_a),
                on_roads_llr(self.g, xy_b[keep], sigma_b))

    def track_off_roads(self, latlon, sigma):
        """The map's word on one track (``latlon``: rows of lat, lon rad), thinned as in
        :meth:`track_evidence`: its :func:`selfnav.roads.evidence.on_roads_llr` at ``sigma`` —
        or None when every point lies within its σ (and the road's own width) of some road,
        where the map cannot refute it (the cheap look first: the full one costs ~10 ms)."""
        xy = self._local(latlon)
        xy = xy[thin_track(xy)]
        if _near_a_road(self.g, xy, math.hypot(sigma, SIGMA_ROAD_M)).all():
            return None
        return on_roads_llr(self.g, xy, sigma)

    def start_check(self, imu, gnss, cfg, start=None):
        """The navigator's start (``start``, as :func:`start_on_roads` takes it), checked
        against the map on the data so far: None until the check's span is complete."""
        return start_on_roads(imu, gnss, self.g, cfg, complete=True, start=start)

    def on_start(self, t0, flt):
        """The navigator started at ``t0``."""

    def __call__(self, t, flt):
        """The map's constraints at an aiding epoch, applied to ``flt`` (gated, χ² 0.999 as
        each says); returns the error-state correction (zeros when nothing applied)."""
        return self.apply(self.constraints(t, flt), flt)

    @staticmethod
    def apply(meas, flt):
        """Apply measurements of :meth:`constraints` to a filter (each gated, χ² 0.999, as it
        says); returns the error-state correction. ``meas`` is not changed (the same epoch's
        constraints can go to several filters: the heading hypotheses of a start)."""
        dx = np.zeros(flt.nx)
        for m in meas:
            if isinstance(m, dict):
                m = dict(m)
                gate = m.pop("gate", True)
                m = RoadLine(**m)
            else:
                gate = True
            mod = m.model(flt)
            if gate and flt.nis(mod) > chi2_999(len(mod.r)):
                continue
            dx = dx + flt.update(mod)
        return dx

    def _corner_nodes(self):
        """Per segment: does it end (start) in a bend of more than 20° on some way on?"""
        g, off, succ = self.g, self.pf.off, self.pf.succ
        src = np.repeat(np.arange(g.n_segments), np.diff(off))
        bend = np.abs(wrap(g.seg_heading[succ] - g.seg_heading[src])) > np.radians(20.0)
        end_bend = np.zeros(g.n_segments, bool)
        end_bend[src[bend]] = True
        start_bend = np.zeros(g.n_segments, bool)
        start_bend[succ[end_bend[src]]] = True
        return end_bend, start_bend

    # ------------------------------------------------------------------ geometry
    def _line(self, s):
        """Start point, direction and right normal of directed segment ``s``."""
        h = float(self.g.seg_heading[s])
        d = np.array([np.sin(h), np.cos(h)])
        return self.g.xy[self.g.seg_u[s]], d, np.array([d[1], -d[0]])

    def _line_weight(self, segs, w, pos):
        """Weight of the particles within 2 m of the line of any of ``segs`` and heading
        within 20° of it."""
        on = np.zeros(len(w), bool)
        for s in segs:
            a, _, n = self._line(s)
            on |= ((np.abs((pos - a) @ n) < 2.0)
                   & (np.abs(wrap(self.g.seg_heading[self.pf.seg] - self.g.seg_heading[s]))
                      < np.radians(20.0)))
        return float(w[on].sum())

    def _nearer_road(self, p, line):
        """Is there another road beside ``p`` (its foot inside the segment), running along
        ``line`` within 20° and at least three ``sigma_cross`` from it (not the same road's
        other direction, a duplicate way or a lane), that ``p`` is nearer to across — by more
        than ``sigma_cross`` — than to ``line``?"""
        off = line["offset"]                       # p's distance from the line along its normal
        if abs(off) <= self.sigma_cross:
            return False
        n = np.asarray(line["normal_n"], float)
        c = self.g.nearest_segments(p, radius=abs(off), k=16)
        off_j = (p - c.foot) @ n
        return bool(np.any((c.along > 0.0) & (c.along < self.g.seg_len[c.seg])
                           & (np.abs(np.sin(self.g.seg_heading[c.seg] - line["heading"]))
                              < np.sin(np.radians(20.0)))
                           & (np.abs(off_j) < abs(off) - self.sigma_cross)
                           & (np.abs(off_j - off) >= 3.0 * self.sigma_cross)))

    def _holds(self, out, P2) -> bool:
        """Would road line or leg ``out`` (the only kinds :meth:`constraints` forms then) only
        hold the filter on its road — its offset within three ``sigma_cross`` or one of the
        filter's σ across the line — rather than move it to another? (A line 68 m across at
        σ 27 m put campaign drive 8017652828310085427 on a road 100 m from the one driven; the
        pulls of 4–9 m at σ 5–14 m across that kept others on theirs, 5205673417576926403 and
        5892921121329950675, are within it.)"""
        s_c = _sigma_along(P2, np.asarray(out["normal_n"], float))
        return abs(out["offset"]) <= max(3.0 * self.sigma_cross, s_c)

    def _agrees(self, dist, u, P2, spread=0.0):
        """The agreement test of the cloud and the filter: is ``dist`` (m, along unit vector
        ``u``) within ``max(agree_m, 3σ)`` — σ the filter's along ``u`` (``P2``) with
        ``spread``, the cloud's?"""
        s_u = math.hypot(_sigma_along(P2, u), spread)
        return abs(dist) <= max(self.agree_m, 3.0 * s_u)

    def _cloud_agrees(self, est, p, P2):
        """Is the cloud's mean ``est["xy"]`` within :meth:`_agrees` of the filter at ``p``,
        in the direction between them, with the cloud's spread? The cross-track test of a line
        misses a cloud that is on the right road but in the wrong place along it (simulated
        campaign drive 8234251124038289217 with the yaw-bias hypotheses on, stop 46: a
        collapsed cloud left 50–60 m behind at a junction, the filter and the truth past it
        at σ 6.5 m; the lines of the road the vehicle had left took the filter 4 m off the new
        one, and that one, 7° from the filter's long axis, moved it 10 m along: 27 m off at
        σ 4.6 m)."""
        d = np.asarray(est["xy"], float) - p
        dist = float(np.hypot(d[0], d[1]))
        return dist <= self.agree_m or self._agrees(dist, d / dist, P2, float(est["spread"]))

    def _arc_placed(self, legs, R, sigma_h):
        """Does the filter know where on the arc from leg ``legs[0]`` to ``legs[1]`` (radius
        ``R``) it is — its horizontal 2σ (``sigma_h``, the largest axis) within the arc's
        length ``R·θ``? The normal sweeps through the turn; placed no better than that, an
        offset beyond the arc's own 2σ is as well explained by the car being elsewhere along
        the road (never-seen campaign drive 5847359501566820251: dead-reckoning at σ 7 m
        along into an 8 m arc, 4.6 m across it moved the filter 10 m, 18 m off at σ 4.5 m; the
        arcs such a filter met on the other drives were right within 0.8 m, and they pin its
        along-track error: refused, one drive went 12 → 89 m)."""
        turn = abs(float(wrap(self.g.seg_heading[legs[1]] - self.g.seg_heading[legs[0]])))
        return 2.0 * sigma_h <= R * turn

    def _heading_agrees(self, s, hdg, flt):
        """Does directed segment ``s`` run the way the INS heads — within ``line_agree`` or
        three of the filter's heading σ?"""
        tol = max(self.line_agree, 3.0 * float(np.sqrt(max(flt.P[8, 8], 0.0))))
        return abs(float(wrap(self.g.seg_heading[s] - hdg))) < tol

    def _legs(self, est, turn_sign):
        """The corner the vehicle is at: ``(s_in, s_out)`` or None (module docstring)."""
        g, pf = self.g, self.pf
        s, L, al = est["seg"], g.seg_len[est["seg"]], est["along"]
        end_bend, start_bend = self.corner
        if end_bend[s] and L - al < self.bend_zone and (al >= L / 2 or not start_bend[s]):
            nxt = pf.succ[pf.off[s]:pf.off[s + 1]]
            turn = wrap(g.seg_heading[nxt] - g.seg_heading[s])
            ok = np.abs(turn) > np.radians(20.0)
            if turn_sign != 0:
                ok &= np.sign(turn) == turn_sign
            cand = nxt[ok]
            if len(cand) == 0:
                return None
            if len(cand) > 1:      # the branch the cloud's particles took
                w = pf.weights()
                cand = cand[[int(np.argmax([w[pf.seg == q].sum() for q in cand]))]]
            return int(s), int(cand[0])
        if start_bend[s] and al < self.bend_zone and self.seg_prev >= 0:
            q = self.seg_prev
            if (s in pf.succ[pf.off[q]:pf.off[q + 1]]
                    and abs(float(wrap(g.seg_heading[s] - g.seg_heading[q]))) > np.radians(20)):
                return int(q), int(s)
        return None

    def _corner_radii(self, legs) -> np.ndarray:
        """The radii ``v/ω`` of the current turn measured within the corner ``legs``: while
        the heading lay between the two legs' (10° margin). A turn through two corners in a
        row turns at each corner's own radius (simulated campaign drive
        2784835463978362199: 10 m through a 53° corner, then 2.6 m through the 122° one
        after it; the first's radius placed the second's arc 6 m off, taken at σ 1 m)."""
        if not self.radii:
            return np.zeros(0)
        h, r = np.asarray(self.radii, float).T
        h0, h1 = (float(self.g.seg_heading[q]) for q in legs)
        th = float(wrap(h1 - h0))
        pos = wrap(h - h0) * np.sign(th)
        margin = np.radians(10.0)
        return r[(pos >= -margin) & (pos <= abs(th) + margin)]

    def _arc(self, s_in, s_out, p, R):
        """Circle tangent to both legs with radius ``R``: ``(normal, offset)`` of ``p`` or
        None when ``p`` is not beside the arc, or the legs turn by more than ``MAX_CORNER_TURN``."""
        g = self.g
        V = g.xy[g.seg_v[s_in]]
        _, d1, _ = self._line(s_in)
        _, d2, _ = self._line(s_out)
        th = float(wrap(g.seg_heading[s_out] - g.seg_heading[s_in]))
        if abs(th) > MAX_CORNER_TURN:
            # a U-turn (the reverse of the road is a successor): the centre lies R/cos(θ/2)
            # from the vertex — 115 R at 179° — no circle tangent to both legs is near the car
            return None
        b = d2 - d1
        b /= np.linalg.norm(b)
        C = V + b * R / np.cos(th / 2.0)
        u = p - C
        rho = float(np.linalg.norm(u))
        if rho < 1e-6:
            return None
        u /= rho
        # beside the arc: between the radii to the two tangent points (with 15° margin)
        t1 = V - d1 * R * np.tan(abs(th) / 2.0) - C
        t2 = V + d2 * R * np.tan(abs(th) / 2.0) - C
        a1 = np.arctan2(t1[0], t1[1])
        a2 = np.arctan2(t2[0], t2[1])
        a = np.arctan2(u[0], u[1])
        span = float(wrap(a2 - a1))
        pos = float(wrap(a - a1))
        m = np.radians(15.0)
        if not (min(0.0, span) - m <= pos <= max(0.0, span) + m):
            return None
        return u, rho - R

    # --------------------------------------------------------------------- call
    def _yaw_rate(self, flt, hdg, dt):
        """Yaw rate, rad/s clockwise: the filter's last propagation block (bias-corrected
        gyros); else heading differences (which also carry the filter's corrections)."""
        if hasattr(flt, "_w_b"):
            return -float((flt.ins.C_nb.T @ flt._w_b)[2])
        if self.hdg_last is None:
            return 0.0
        return float(wrap(hdg - self.hdg_last)) / max(dt, 1e-3)

    def _grade_prior(self, t, flt, v, out):
        """Level-road prior on the vertical velocity (class docstring)."""
        if self.grade_sigma is None or t - self.t_grade < self.interval - 1e-9:
            return
        self.t_grade = t
        out.append(LevelRoad.at_speed(self.grade_sigma, np.hypot(v[0], v[1])))
        self.counts["grade"] += 1

    def constraints(self, t, flt):
        """The measurements of this epoch, not yet applied: a list of the level-road prior
        (:class:`~selfnav.ins.measurements.LevelRoad`) and a road line or corner (a dict of
        :class:`~selfnav.ins.measurements.RoadLine` fields, with ``gate``)."""
        meas = []
        ins, pf = flt.ins, self.pf
        x, y = self.g.to_local(ins.lat, ins.lon)
        p_ins = np.array([float(x), float(y)])
        hdg = _heading_of(ins.C_nb)
        if not pf.initialized:
            pf.seed(p_ins, max(pf.cfg.seed_radius, 3.0 * float(np.sqrt(flt.P[0, 0] + flt.P[1, 1]))),
                    heading=hdg)
            self.t_last = t
            # the fixes before the start are behind it (taken at once they dragged the cloud
            # 1 km off, seen); the start follows a run of healthy fixes (robust_init)
            self.k = int(np.searchsorted(np.asarray(self.fix_t), t - 1.0, side="right"))
            pf.reset_health(healthy_history=True)
        v = ins.velocity_n
        dt = t - self.t_last
        if self.map_doubt is not None:
            self.map_doubt.carry(t, p_ins, v)
        speed = float(np.hypot(v[0], v[1]))
        self.t_last = t
        rate = self._yaw_rate(flt, hdg, dt)
        self.hdg_last = hdg
        self.rates = [r for r in self.rates if r[0] > t - 0.6 - 1e-9] + [(t, rate)]
        w_rate = float(np.mean([r[1] for r in self.rates]))          # over the last 0.6 s
        turning = abs(w_rate) > TURN_RATE
        if turning and speed > 1.0 and abs(rate) > np.radians(1.0):
            self.radii.append((hdg, speed / abs(rate)))
        elif not turning:
            self.radii = []
        corner = self._corner_fix(t, flt, p_ins, hdg, turning, speed)
        if self.map_doubt is not None and not turning and self.watch.turn is None and speed > 2.0 \
                and t - self._t_look >= 1.0 - 1e-9:
            self._t_look = t                     # once a second on a straight run
            if self.hypotheses is None:
                self.map_doubt.look(t, p_ins, hdg)
            else:
                hyp = [f.ins for f in self.hypotheses]
                xy = self.g.to_local(np.array([i.lat for i in hyp]), np.array([i.lon for i in hyp]))
                self.map_doubt.look(t, np.column_stack(xy), [_heading_of(i.C_nb) for i in hyp])
        self._widen_along(flt, hdg, dt)
        pf.predict(speed * dt, hdg, dt)
        while self.k < len(self.fix_t) and self.fix_t[self.k] <= t:
            pf.update_gnss(np.asarray(self.fix_xy[self.k]), self.sig[self.k])
            self.k += 1
        est = pf.estimate()
        if est["seg"] != self.seg_cur:
            self.seg_prev, self.seg_cur = self.seg_cur, est["seg"]
        self._grade_prior(t, flt, v, meas)
        w, pos = pf.weights(), pf.positions()
        share = self._line_weight([est["seg"]], w, pos)
        legs = self._legs(est, int(np.sign(w_rate)) if turning else 0)
        if legs is not None:
            share = max(share, self._line_weight(legs, w, pos))
        self.history.append((t, *est["xy"], est["seg"], est["spread"], share))
        sigma_h = float(np.sqrt(max(np.linalg.eigvalsh(flt.P[0:2, 0:2])[-1], 0.0)))
        # a corner is not a line: the turn the gyros measured happened at a junction, and the
        # corner fix takes one only where it is the single junction of that turn within the
        # filter's σ (:meth:`_corner_fix`) — what the cloud's lines cannot tell (parallel
        # roads, the branch at a junction) it does not need. So it stands while dead-reckoning
        # up to ``max_sigma_m`` (campaign drive 6560021803722912080, a 118 s white window from
        # 101 s: the dead reckoning 40 m ahead at a 60° turn, 16–21 m across for 50 s without
        # it, 4 m along after it); ``max_sigma_m`` bounds it below
        # the fixes are not taken (a fault episode, an outage) and no dead reckoning of this
        # INS has yet stood the fixes' test: the cloud follows the dead reckoning and cannot
        # vouch for a road once the filter is unsure — its lines, legs and arcs turned a
        # filter onto the next road at a junction and made it sure of it (simulated drives:
        # 300 m off at σ 10 m; campaign drive 8017652828310085427, a 192 s white window from
        # 26 s: 148 m off when they moved it). They may still *hold* it on the road it runs
        # along (:meth:`_holds`): given nothing, a dead reckoning that had kept to its road
        # for minutes drifted 5–10 m across it in a bend (campaign drive 4418772899228626032,
        # 26 s off the route in a 236 s Gauss–Markov window started 28 s after the start).
        # A vouched INS keeps the lines up to ``max_sigma_m``: they then need its heading to
        # run along the road (below), which a wrong branch does not (stop 56:
        # 8632296919476031792 was 5–7 m beside its road for 22 s at σ 12 m, its lines off)
        hold_only = self.dead_reckoning and sigma_h > self.dr_sigma_m and not self.ins_vouched \
            and corner is None
        if sigma_h > self.max_sigma_m:
            # the filter is too unsure of its position for the map to say which road it is on
            # (a cloud that follows its dead reckoning takes the junction its speed error
            # picks, and the constraints would then make it sure of the wrong road)
            return meas
        if corner is not None:
            self.t_constraint = t
            if np.hypot(*(est["xy"] - corner.pop("target"))) > 15.0:
                pf.seed(p_ins - corner["e"], 10.0, heading=hdg)
            corner.pop("e")
            return meas + [corner]
        # the cloud's error is correlated over seconds: one constraint per ``interval``
        if share < 0.8 or t - self.t_constraint < self.interval - 1e-9:
            return meas
        out = None
        P2 = flt.P[0:2, 0:2]
        if legs is None and not turning:
            # not turning, the car runs along its road: while dead-reckoning, a line the INS
            # heading does not match is the next segment of a bend or a branch at a junction
            # the cloud reached first (simulated campaign drive 6218674482900036279: lines
            # 9–14° off the INS heading, at 1 m, pulled a dead reckoning 30 m along its road
            # at σ 5 m). With fixes taken the lines' road heading is what corrects a start's
            # heading (a consumer start 24° off at σ 3°): the fixes bound what a wrong one does
            # — and so while no dead reckoning of the INS has yet stood the fixes' test
            # (``ins_vouched``: that start's first episode came from its heading)
            if not (self.dead_reckoning and (self.ins_vouched or hold_only)) \
                    or self._heading_agrees(est["seg"], hdg, flt):
                a0, _, nrm = self._line(est["seg"])
                out = {"normal_n": nrm, "offset": float((p_ins - a0) @ nrm), "kind": "line",
                       "heading": float(self.g.seg_heading[est["seg"]])}
        elif legs is None and self.curve_sigma is not None and not hold_only:
            # a gentle curve (vertices below 20°): the car follows the centre line within
            # centimetres (a 12 m arc cuts a 10° vertex by 5 cm), but the heading changes
            # along it: cross-track only, looser
            a0, _, nrm = self._line(est["seg"])
            out = {"normal_n": nrm, "offset": float((p_ins - a0) @ nrm), "kind": "curve"}
        elif legs is not None and not turning:
            # on one of the straight legs of a corner: the one the INS heading matches
            dh = [abs(float(wrap(self.g.seg_heading[q] - hdg))) for q in legs]
            q = legs[int(np.argmin(dh))]
            if self._heading_agrees(q, hdg, flt):
                a0, _, nrm = self._line(q)
                out = {"normal_n": nrm, "offset": float((p_ins - a0) @ nrm), "kind": "leg",
                       "heading": float(self.g.seg_heading[q])}
        elif legs is not None and not hold_only:
            rr = self._corner_radii(legs)[2:]          # the first 0.4 s is the turn's entry
            if len(rr) >= 3 and np.subtract(*np.percentile(rr, [75, 25])) < 0.3 * np.median(rr):
                R = float(np.median(rr))
                arc = self._arc(*legs, p_ins, R)
                if arc is not None:
                    sig_a = _sigma_along(P2, arc[0])
                    agree = max(self.arc_agree_m, 2.0 * sig_a)
                    if not self._arc_placed(legs, R, sigma_h):
                        agree = 2.0 * self.sigma_arc
                    if abs(arc[1]) < agree:
                        out = {"normal_n": arc[0], "offset": arc[1], "kind": "arc"}
        if out is None or (hold_only and not self._holds(out, P2)):
            return meas
        # the cloud and the filter disagree by more than the filter's own uncertainty allows:
        # one of them is on another road, or elsewhere on this one; constraining the filter
        # then would make it two
        if not (self._agrees(out["offset"], out["normal_n"], P2)
                and self._cloud_agrees(est, p_ins, P2)):
            return meas
        if self.dead_reckoning and out["kind"] in ("line", "leg") and self._nearer_road(p_ins, out):
            # the cloud follows the dead reckoning and has only the map to tell parallel roads
            # apart: where the filter is nearer another road beside it than to the cloud's line,
            # the two disagree about the road (never-seen campaign drive 8070721305242721781:
            # after a turn the cloud took a road 10 m from the one driven, the filter 6.7 m
            # from it and 3.6 m from the right one; the line at σ 3.8 m made it sure of the
            # wrong road, 10 m off at σ 2 m)
            return meas
        self.t_constraint = t
        if abs(out["offset"]) < self.lock_m:
            # the normal to the right of travel (an arc's points to the centre)
            n_r = np.array(out["normal_n"], float)
            if n_r @ np.array([np.cos(hdg), -np.sin(hdg)]) < 0:
                n_r = -n_r
            self.lock = (t, n_r)
        kind = out.pop("kind")
        self.counts[kind] += 1
        if kind == "arc":
            out["sigma"] = self.sigma_arc
            return meas + [out]
        if kind == "curve":
            out["sigma"] = self.curve_sigma
            return meas + [out]
        # the cloud's own spread across the line: the weight it leaves on other roads (a
        # divided road's other carriageway, a parallel street) is the chance the line is the
        # wrong one (simulated campaign drive 8234251124038289217: 80 % of the cloud on a
        # road 8 m from the truth, the constraint at σ 1 m held the filter there at σ 2.3 m)
        off_c = (pos - p_ins) @ out["normal_n"] + out["offset"]
        out["sigma"] = float(np.hypot(self.sigma_cross, np.sqrt(w @ off_c**2)))   # w sums to 1
        if self.sigma_heading is None:
            del out["heading"]
        else:
            out["sigma_heading"] = self.sigma_heading
        return meas + [out]

    def _widen_along(self, flt, hdg, dt):
        """Along-track speed variance ``q_along·dt`` while GNSS is unhealthy (the cloud's test).

        The filter does not model the IMU's axis misalignment: through the turns of a drive a
        consumer part's 1 % cross-coupling tilts the INS by tenths of a degree, which without
        GNSS leaks into the along-track speed (0.03–0.05 m/s² measured on the simulated
        drives, 4σ beyond the filter's velocity σ). Widened, the filter takes the corners and
        arcs that correct it instead of refusing them at its gates.
        """
        if self.q_along is None or self.pf.healthy or dt <= 0:
            return
        u = np.array([np.sin(hdg), np.cos(hdg)])
        flt.P[3:5, 3:5] += np.outer(u, u) * (self.q_along * dt)

    def doubt(self, C_h) -> np.ndarray:
        """The horizontal output covariance ``C_h`` (2×2, ENU) with the map's doubt
        (:class:`~selfnav.roads.doubt.MapDoubt`): while the filter has been seen off the roads
        running its way (the offset ``e``, carried with its corrections since), its variance
        along ``e`` is at least ``|e|²`` — the map says the error is that large or larger. A
        receiver dragged from power-on (simulated issue-19 campaign drive 1629028103303956202,
        master seed 2: followed 40–140 m off at σ 4–6 m) gives the fixes' own tests nothing to
        see; the map does. Only the reported covariance: the filter's own is not opened, the
        map having named no place to go."""
        return C_h if self.map_doubt is None else self.map_doubt.widen(C_h)

    # ------------------------------------------------------------------ corners
    def dead_reckoning_corner(self, ref) -> bool:
        """A corner fix for one of the fault bank's map-aided twins (``ref``: its
        :class:`~selfnav.ins.hypotheses.Reference`, whose ``watch`` follows its turns; called
        after each of its steps, looking at least 0.5 s apart): the map places the turn it has
        just driven as :meth:`_corner_fix` places the navigator's filter's. A dead reckoning
        the map aids stays the hypothesis "the fixes are faulty since it branched" (the map is
        neither side), its position road-sized where the roads turn instead of a consumer
        IMU's free growth — but its σ after a fix is a road's, which its error outgrows, so
        the fault bank's envelope tests do not use it. True when a fix was applied."""
        flt = ref.flt
        if ref.watch is None:
            ref.watch = TurnWatch()
        watch, ins = ref.watch, flt.ins
        t = float(ins.t)
        if watch.last is not None and t - watch.last[0] < 0.5 - 1e-9:
            return False
        x, y = self.g.to_local(ins.lat, ins.lon)
        p = np.array([float(x), float(y)])
        hdg = _heading_of(ins.C_nb)
        speed = float(np.hypot(*ins.velocity_n[:2]))
        turn = watch.step(t, hdg, p, abs(watch.rate(t, hdg)) > TURN_RATE, speed)
        if turn is None:
            return False
        P2 = flt.P[0:2, 0:2]
        if float(np.sqrt(max(np.linalg.eigvalsh(P2)[-1], 0.0))) > self.max_sigma_m:
            return False
        e = corner_offset(self.g, self.pf.off, self.pf.succ, turn[0], turn[1], hdg, P2,
                          self.sigma_corner)
        if e is None:
            return False
        self.apply([self._corner_measurement(e, hdg)], flt)
        self.counts["dr_corner"] += 1
        ref.t_aided = t
        return True

    def _corner_fix(self, t, flt, p_ins, hdg, turning, speed):
        """A position fix from the map at the end of a turn (:mod:`selfnav.roads.corners`).

        The turn runs from the first epoch the filter turns (0.6 s mean yaw rate above 3°/s)
        to 1 s after it stops; the entry line is the filter's position and heading 1 s before
        it, the exit line now. Turns of 35–150° within 20 s whose lines meet ahead of the entry
        and behind the exit are looked up on the map within ``max(30 m, 3σ + 10 m)`` (at most
        80 m) of that vertex; the candidate that fits the filter's uncertainty (χ² 2 dof,
        0.999, of ``P + σ_corner²``) when the next one fits clearly worse (by 9: a grid of equal
        corners) gives the correction, applied along and across the new road with σ
        ``sigma_corner``.
        """
        turn = self.watch.step(t, hdg, p_ins, turning, speed)
        if turn is None:
            return None
        V, h0 = turn
        P2 = flt.P[0:2, 0:2]
        if self.map_doubt is not None:
            self.map_doubt.turn(t, V, h0, hdg)           # a junction within its reach answers it
        e = corner_offset(self.g, self.pf.off, self.pf.succ, V, h0, hdg, P2, self.sigma_corner)
        if e is None:
            return None
        self.counts["corner"] += 1
        self.corner_log.append((t, float(e[0]), float(e[1])))
        return {**self._corner_measurement(e, hdg), "e": e, "target": p_ins - e}

    def _corner_measurement(self, e, hdg) -> dict:
        """The corner fix of a position error ``e`` (E, N m) after a turn onto heading ``hdg``:
        across and along the new road, σ ``sigma_corner`` each, not gated (its own test chose
        the corner)."""
        u = np.array([np.sin(hdg), np.cos(hdg)])
        n = np.array([u[1], -u[0]])
        return {"normal_n": n, "offset": float(e @ n), "sigma": self.sigma_corner,
                "along_n": u, "along_offset": float(e @ u), "sigma_along": self.sigma_corner,
                "gate": False}
