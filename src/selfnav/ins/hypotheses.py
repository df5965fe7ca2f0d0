"""Never worse than having no GNSS: the two-sided fault-hypothesis bank (DESIGN §7, §10).

The navigator's filter ``M`` fuses the fixes it accepts. Beside it the bank keeps
**references**: copies of ``M`` branched every ``branch_every_s`` while the GNSS is healthy,
then carried by the IMU and the vehicle constraints only (NHC, ZUPT, wheel speed) — the
hypotheses "the fixes are faulty since ``t_b``". Their covariance grows with their age as the
dead reckoning's error does (honest σ: :mod:`selfnav.ins.ekf` models the sensor errors the
grade has), so each is an envelope the truth lies in. They are kept at ages spread over
octaves (10–20 s, 20–40 s, … up to ``max_age_s``): a young one sees a fast drag early, an
old one a slow drag. Each fix is judged, at a false-alarm probability the configuration
states (:class:`selfnav.ins.config.Integrity`):

* against ``M``: ``NIS = rᵀ (H P_M Hᵀ + R)⁻¹ r`` (2 dof, horizontal) below the gate;
* against every reference ``b`` (the envelope): a fix outside one is never accepted;
* by **solution separation** (ARAIM-style, in time): had ``M`` taken the fix, its
  horizontal position ``x_M⁺`` would differ from the reference's by ``d``, whose covariance
  under "the fixes are healthy" is ``P_b − P_M⁺`` (the reference is ``M`` less the fixes since
  ``t_b``); ``dᵀ (P_b − P_M⁺)⁻¹ d`` above the gate is a fault since ``t_b``. A drag that
  each fix hides from ``M`` (every test of a fix against a state the fixes just moved passes)
  accumulates here.

A fault detected since ``t_b`` resets ``M`` to the youngest reference that detects it (the
references younger than it are contaminated and dropped) and opens an **episode**; fixes
rejected one after another open one too (``M`` itself never took them). While an episode is
open ``M`` dead-reckons, and a fix within its gate joins a **run**; the run is taken back when
it is at least ``run_s`` long and moves with the INS: the offsets of its fixes from ``M`` fit a
line whose residuals are the fixes' noise (white outliers and a Gauss–Markov error fail) and
whose slope is within what ``M``'s velocity σ allows (a drag faster than the dead reckoning
can drift fails). A run that keeps failing only the slope while it is self-consistent, with
no reference left to say the fixes are the faulty side, is the other hypothesis — the INS is
lost — after ``reinit_after_s``: ``M`` is restarted from the run (the GNSS branch).
Rejections never widen ``P`` (a defence that inflates P relaxes its own gate).

With a road map the INS-lost test also asks the map (evidence neither side controls: the car is
on a road; :mod:`selfnav.roads.evidence`): how much better each track — the fixes', ``M``'s — lies
on the roads within its σ than the same shape put elsewhere. An ``M`` whose track the map puts
off the roads by ``ln(1/α)`` beyond its σ, while the fixes' track lies on them at chance level
``q ≤ e^−map_fixes_llr``, is lost: restarted from the run. (An INS started on a drag carries
the drag's rate after it is switched off; its offsets from the clean fixes are the mirror image
of a drag, which the fixes' likelihoods alone cannot tell apart.) And the other way, while no
episode is open: ``M``'s own track — it took the fixes — off the roads by ``ln(1/α)`` beyond its
σ, while a dead reckoning's track lies on them at ``q ≤ e^−map_fixes_llr``, says the fixes
dragged ``M``; it goes back to that dead reckoning. With a map the bank also carries
**witnesses** while no mature reference stands (right after a start, while its heading
hypotheses resolve, while covariance reopenings keep the references' health clock from
running): dead reckonings no envelope test uses, judged by the map alone. Each reference and
witness has a **map-aided twin**: the same dead reckoning, branched at the same instant, that
the map also places at the end of each turn it drives (a corner fix,
:meth:`~selfnav.roads.aid.EkfRoadAid.dead_reckoning_corner`), so that an old one is still a
place on the roads when ``M`` is refuted; only the map's look uses the twins (its track, and
the state ``M`` goes back to) — the envelope and separation tests keep the free dead
reckonings, whose σ is the IMU's own (a twin's σ after a corner is a road's, and its error
then grows faster than its σ: on simulated drive 6528021596814149514 a corner-aided
reference was 127 m from a right ``M`` at χ² 26 and refused the clean fixes for 240 s).

Outputs: every decision (:class:`selfnav.ins.policy.FixDecision`), the episodes (start, end,
kind: outage / outliers / drag / ins-fault, largest separation) and per row a horizontal
protection level at the configured integrity risk (:meth:`FaultBank.protection_level`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from selfnav.earth import enu_offset
from selfnav.ins.measurements import NonHolonomic, ZeroRate, ZeroVelocity
from selfnav.ins.policy import FixStatus, chi2_gate, normal_quantile


_MAP_LOOK_S = 1.0      # s between the INS-lost test's looks at the road map (its cost)


@dataclass
class Reference:
    """A dead-reckoning branch: the hypothesis "the fixes are faulty since ``t0``"."""

    t0: float
    flt: object
    track: list = field(default_factory=list)   # (t, its lat, lon, M's lat, lon) once a
                                                # second over the last reinit_after_s, with a
                                                # road map (FaultBank._map_look)
    twin: Reference | None = None               # its map-aided copy, with a road map
    aided: bool = False                         # a twin: the map's corners correct it
    watch: object = None                        # a twin's turns (the road aid's TurnWatch)
    t_aided: float | None = None                # a twin's last corner fix


@dataclass
class SumFallback:
    """The start's heading sum as it stood at ``t0``, carried since by the IMU and the vehicle
    constraints only (each hypothesis a :class:`Reference` of :attr:`refs`): a state from
    before a drag to go back to while the heading is still undecided."""

    t0: float
    hyp: object
    refs: list = field(default_factory=list)

    @classmethod
    def of(cls, t0, hyp):
        return cls(t0, hyp, [Reference(t0, f) for f in hyp.filters])


@dataclass
class Episode:
    """A stretch where the fixes and the inertial solution disagree (or there are none)."""

    t_start: float
    t_end: float | None = None
    kind: str = "outliers"
    reset: bool = False            # M was reset to a reference when it opened
    max_separation_m: float = 0.0
    fixes: int = 0
    rejected: int = 0
    consistent_runs: int = 0
    onset: list = field(default_factory=list)   # the first fixes' offsets from M (_RunFix)
    fault: dict | None = None                   # the fault's model from them (smooth faults)
    origin: tuple | None = None                 # (lat, lon) of the first fix of the episode
    track: list = field(default_factory=list)   # the recent fixes by themselves
    characterised: bool = False
    t_fault: float | None = None                # the last time the fixes looked faulty
    t_scattered: float | None = None            # the last time the fixes by themselves
                                                # were no car's track (white, Gauss–Markov)
    unwitnessed: bool = False                   # opened right after the (re)start, before
                                                # any reference was branched
    on_reference: bool = True                   # M stood on a reference when it opened (a
                                                # mature one, or M was reset to one)
    offset: np.ndarray | None = None            # the latest fix − M, ENU horizontal, m

    def to_dict(self) -> dict:
        return {"start_s": self.t_start, "end_s": self.t_end, "kind": self.kind,
                "largest_separation_m": self.max_separation_m, "fixes": self.fixes,
                "rejected": self.rejected}


@dataclass
class _RunFix:
    t: float
    offset: np.ndarray     # fix − M's prediction, ENU horizontal, m
    sigma: float
    p: np.ndarray | None = None   # the fix, ENU horizontal from the episode's origin, m


@dataclass
class Verdict:
    """What the bank decided for one fix."""

    status: FixStatus
    reason: str
    nis: float
    apply: bool = False                 # update M with the fix
    reset_to: object = None             # a reference to reset M to (a filter)
    reset_sum: object = None            # … or a heading sum to go back to (a SumFallback's)
    excluded_since: float | None = None  # fused fixes after this time are now excluded
    widen: np.ndarray | None = None      # open M's position σ to this offset first (INS fault)
    reinit_from: list | None = None      # fixes to restart M from (the GNSS branch)
    run_velocity: tuple | None = None    # (velocity ENU, cov) the run of fixes shows
    add_R: np.ndarray | None = None      # 2×2 added to the fix's horizontal noise
    vehicle: dict = field(default_factory=dict)


def _rate(fixes, y, t_now: float, order: int):
    """The rate now of ``y`` (E, N per fix) and its covariance: a polynomial of ``order`` in
    time through it, weighted by the fixes' σ, its covariance scaled by their scatter
    (``max(χ²/dof, 1)``)."""
    t = np.array([f.t for f in fixes]) - t_now
    A = np.column_stack([t ** j for j in range(order + 1)])
    w = 1.0 / np.array([f.sigma for f in fixes]) ** 2
    N = (A * w[:, None]).T @ A
    coef = np.linalg.solve(N, (A * w[:, None]).T @ y)
    res = y - A @ coef
    k = max(float(np.sum(w[:, None] * res ** 2)) / max(2 * (len(fixes) - order - 1), 1), 1.0)
    return coef[1], np.eye(2) * np.linalg.inv(N)[1, 1] * k


class FaultBank:
    """References, episodes and the fix decisions (module docstring).

    Parameters
    ----------
    cfg : FilterConfig
        Uses ``cfg.integrity`` (gates, ages, run length) and ``cfg.vehicle`` (the constraints
        the references keep).
    """

    def __init__(self, cfg, adapter=None):
        self.cfg = cfg
        self.adapter = adapter
        ig = cfg.integrity
        self.gate = chi2_gate(2, ig.p_false_alarm)
        self.fix_dt = 1.0               # the fixes' interval (the navigator keeps it current)
        self.nhc_scale = np.ones(2)     # the constraint's σ over the configured (lateral, up)
        self.diag = None                # a list to collect (t, age, q_fix, q_sep, sep, κ) in
        self.k_pl = normal_quantile(ig.integrity_risk)
        self.refs: list[Reference] = []
        #: the start's heading sum branched while it is undecided (:meth:`maintain`): a
        #: reference branched from one filter of an undecided sum is no envelope — only a
        #: whole sum is a state to go back to
        self.fallbacks: list[SumFallback] = []
        #: set by the navigator: ``(fallback's sum, t) -> bool``, may the bank go back to it
        #: for a drag found since ``t`` — was the sum undecided then, and does the copy hold
        #: another heading hypothesis best than ``M`` is now? (None: always)
        self.sum_choice_differs = None
        self.episode: Episode | None = None
        self.outage: Episode | None = None
        self.episodes: list[Episode] = []
        self.run: list[_RunFix] = []
        self.streak = 0                 # consecutive rejected fixes (normal mode)
        self.used_streak = 0            # consecutive fused fixes (normal mode)
        self.t_healthy = None           # since when the fixes have been fused without a break
        self.innov = []                 # whitened innovations of the recent fixes (normal mode)
        self.episode_origin = None      # (lat, lon) the GNSS branch's track is relative to
        self._buf = []                  # IMU blocks since the last reference step
        self._t_step = -np.inf
        self._t_branch = -np.inf
        self.alarms = 0
        self.reinits = 0
        self.recoveries = 0
        self._sep_max = 0.0
        self.t_started = None           # the navigator's (re)start (:meth:`restart`)
        #: the road map's word on the fixes' and ``M``'s tracks while an episode is open (the
        #: road aid's :meth:`~selfnav.roads.aid.EkfRoadAid.track_evidence`), None without a map
        self.road_aid = None
        self._t_map = -np.inf
        self._t_track = -np.inf
        self._map_alarm = None          # (reference, the filter to go back to, why): the
                                        # map refuted M for it
        self.m_track = []               # (t, lat, lon) of M once a second, with a road map
        self.witnesses: list[Reference] = []   # dead reckonings only the map judges (maintain)
        self._t_witness = -np.inf

    # ------------------------------------------------------------------ references
    def restart(self, t):
        """The navigator (re)started at ``t``: no reference of the old INS stands for the new
        one, and none of its own exists yet."""
        self.refs = []
        self.fallbacks = []
        self.t_started = float(t)
        self._map_alarm = None
        self.m_track = []
        self.witnesses = []
        self.forget_innovations()

    def on_imu(self, t, dtheta, dv, dt):
        """IMU increments that moved ``M`` (stamps ``t``): the references follow once per
        ``reference_step_s``. Whether the samples were still is known only when the
        navigator has judged their aiding block (:meth:`judged`): until then they count as
        moving."""
        if not (self.refs or self.witnesses or self.fallbacks):
            return
        step = self.cfg.integrity.reference_step_s - 1e-9
        while len(t):
            # the step ends at the first sample that completes it, however the samples were
            # handed over (one a call or in blocks: the same references)
            j = int(np.searchsorted(t - self._t_step, step, side="left"))
            if j >= len(t):
                self._buf.append([t, dtheta, dv, dt, None])
                return
            self._buf.append([t[:j + 1], dtheta[:j + 1], dv[:j + 1], dt[:j + 1], None])
            self.flush()
            if not (self.refs or self.witnesses or self.fallbacks):
                return
            t, dtheta, dv, dt = t[j + 1:], dtheta[j + 1:], dv[j + 1:], dt[j + 1:]

    def judged(self, still: bool):
        """The navigator's stillness verdict on the aiding block just ended: it holds for the
        buffered samples not yet judged. (Taking the previous block's verdict gave the
        references a zero-velocity update over the second the vehicle started to move in:
        0.4 m/s forced to zero at σ 0.02 m/s tilted them, and a reference 20 s old was
        2.5 m/s off at σ 0.2 — a false alarm on clean fixes.)"""
        for b in self._buf:
            if b[4] is None:
                b[4] = bool(still)

    def flush(self):
        """Bring every reference to the last IMU sample."""
        if not self._buf:
            return
        t = np.concatenate([b[0] for b in self._buf])
        dth = np.concatenate([b[1] for b in self._buf])
        dv = np.concatenate([b[2] for b in self._buf])
        dt = np.concatenate([b[3] for b in self._buf])
        still = all(b[4] is True for b in self._buf)
        self._buf = []
        self._t_step = float(t[-1])
        veh = self.cfg.vehicle
        for ref in self.carried:
            f = ref.flt
            i = int(np.searchsorted(t, f.ins.t + 1e-12, side="right"))   # t is increasing
            if i == len(t):
                continue
            sth, sdv, _ = f.mechanize(t[i:], dth[i:], dv[i:], dt[i:])
            span = float(dt[i:].sum())
            f.propagate(span, sth, sdv)
            if still and veh.zupt:
                f.update(ZeroVelocity(veh.zupt_sigma).model(f))
                if veh.zaru:
                    w = dth[i:] / dt[i:, None] - f.bg
                    f.update(ZeroRate(w, veh.zaru_sigma, span).model(f))
            elif veh.nhc:
                # its errors are correlated over seconds: it weighs as much per second as one
                # update a reference step, however often a fix's test brings the references up
                # to date in between (σ ∝ 1/√span: two updates 0.02 s apart, seen every other
                # second, had given the dead reckoning up to twice the information across)
                k = np.sqrt(max(1.0, self.cfg.integrity.reference_step_s / max(span, 1e-6)))
                f.update(NonHolonomic(k * veh.nhc_sigma * self.nhc_scale[0],
                                      k * (veh.nhc_sigma_up or veh.nhc_sigma)
                                      * self.nhc_scale[1]).model(f))
            if ref.aided:
                self.road_aid.dead_reckoning_corner(ref)

    def maintain(self, t, flt, *, resolving: bool = False, source=None):
        """Branch a new reference from ``M`` every ``branch_every_s`` while the GNSS is healthy;
        keep the oldest reference of each age octave, none older than ``max_age_s``. With a
        road map, also **witnesses** while no mature reference stands (``resolving``: ``M`` is
        the best of the start's heading hypotheses): dead reckonings branched on the same
        clock but not judged healthy first, used by no envelope test — only by the map
        (:meth:`_map_look`), which judges their tracks itself. (The references' health clock
        can stall for minutes: a drag soon after a consumer start kept reopening ``M``'s
        covariance, and each reopening restarts the clock.) While ``resolving``, on the
        references' clock, a **fallback** instead of a reference: ``source()``, a copy of the
        whole heading sum (:class:`SumFallback`), for the innovation sums to go back to
        (:meth:`judge`)."""
        ig = self.cfg.integrity
        if not ig.bank:
            return
        if self.episode is None and self.t_healthy is not None \
                and t - self.t_healthy >= ig.branch_after_s - 1e-9 \
                and t - self._t_branch >= ig.branch_every_s - 1e-9:
            if not resolving:
                self.flush()
                self.refs.append(self._branch(t, flt))
                self._t_branch = t
            elif source is not None:
                self.flush()
                self.fallbacks.append(SumFallback.of(t, source()))
                self._t_branch = t
        self._prune(t)
        if self.road_aid is None or self.episode is not None:
            return
        if not self.mature(t) and t - self._t_witness >= ig.branch_every_s - 1e-9:
            self.flush()
            self.witnesses.append(self._branch(t, flt))
            self._t_witness = t
        self.witnesses = self._octaves(t, self.witnesses)
        if t >= self._t_track + _MAP_LOOK_S - 1e-9:
            self._t_track = float(t)
            self._map_look(t, flt, look=not resolving)

    def _branch(self, t, flt):
        """A dead reckoning of ``M`` from ``t``; with a road map, with its map-aided twin."""
        ref = Reference(t, flt.copy())
        if self.road_aid is not None:
            ref.twin = Reference(t, flt.copy(), aided=True)
        return ref

    def _map_look(self, t, flt, look=True):
        """With a road map, while no episode is open (the mirror of the INS-lost test's look):
        ``M``'s track over the last ``reinit_after_s`` — it took the fixes — lying off the roads
        by ``ln(1/α)`` beyond its σ (against the same shape put elsewhere) says the fixes dragged
        it there, a drag their own tests and a consumer IMU's wide envelopes let through
        (simulated drive 7821150004149555261: 2 m/s, followed to 420 m at σ 5 m). The next
        fix's decision opens an episode, resetting ``M`` to the map-aided twin of the youngest
        mature reference or witness that has parted from it over the same seconds
        (:meth:`~selfnav.roads.aid.EkfRoadAid.geodetic_track_evidence`) and whose track the map
        puts on its roads at ``q ≤ e^−map_fixes_llr``, if one does; if none does, nothing is
        done (an episode on the map's word alone, with ``M`` carrying the drag's velocity, took
        the fixes back as healthy against it)."""
        ig = self.cfg.integrity
        self.flush()
        self.m_track = [p for p in self.m_track if p[0] >= t - ig.reinit_after_s - 1e-9] + \
            [(t, flt.ins.lat, flt.ins.lon)]
        for ref in self.carried:
            ref.track = [r for r in ref.track if r[0] >= t - ig.reinit_after_s - 1e-9] + \
                [(t, ref.flt.ins.lat, ref.flt.ins.lon, flt.ins.lat, flt.ins.lon)]
        tr = np.array(self.m_track)
        if not look or self._map_alarm is not None \
                or tr[-1, 0] - tr[0, 0] < ig.reinit_after_s - 1e-9:
            return
        s_m = float(np.sqrt(np.linalg.eigvalsh(flt.P[:2, :2])[-1]))
        e_m = self.road_aid.track_off_roads(tr[:, 1:], s_m)
        if e_m is None or e_m > math.log(ig.p_false_alarm):
            return
        why = (f"the map puts the solution that took the fixes off its roads (log-likelihood "
               f"ratio {e_m:+.1f} over the last {ig.reinit_after_s:.0f} s)")
        candidates = sorted(self.mature(t) + [w for w in self.witnesses
                                              if t - w.t0 >= ig.min_age_s - 1e-9],
                            key=lambda r: r.t0)
        for ref0 in reversed(candidates):               # the youngest the map puts on them
            ref = ref0.twin if ref0.twin is not None else ref0
            if len(ref.track) < 2:
                continue
            rt = np.array(ref.track)
            s_b = float(np.sqrt(np.linalg.eigvalsh(ref.flt.P[:2, :2])[-1]))
            ev = self.road_aid.geodetic_track_evidence(rt[:, 3:], rt[:, 1:3], s_m, s_b)
            if ev is not None and ev[1] >= ig.map_fixes_llr:
                # (simulated campaign drives: the free dead reckonings' tracks a consumer IMU
                # had taken off the roads, their twins' on them — 4 of 240 drives mended,
                # 6129180605438802640 134.9 → 42.8 m RMS, none worse)
                self._map_alarm = (ref0, ref.flt, f"{why} and the dead reckoning since "
                                                  f"{ref.t0:.1f} s on them ({ev[1]:+.1f})")
                return

    def _prune(self, t):
        self.refs = self._octaves(t, self.refs)
        self.fallbacks = self._octaves(t, self.fallbacks)

    def _octaves(self, t, refs):
        """The oldest of each age octave, none older than ``max_age_s``."""
        ig = self.cfg.integrity
        keep, octaves = [], set()
        for ref in refs:                            # oldest first
            age = t - ref.t0
            if age > ig.max_age_s:
                continue
            o = int(np.floor(np.log2(max(age, 1e-3) / ig.branch_every_s))) if age >= \
                ig.branch_every_s else -1
            if o >= 0 and o in octaves:
                continue
            octaves.add(o)
            keep.append(ref)
        return keep

    @property
    def dead_reckonings(self) -> list:
        """The references and the map's witnesses: every dead reckoning the bank's tests use."""
        return self.refs + self.witnesses

    @property
    def twins(self) -> list:
        """Their map-aided twins (only the map's look uses them, :meth:`_map_look`)."""
        return [r.twin for r in self.dead_reckonings if r.twin is not None]

    @property
    def carried(self) -> list:
        """Every dead reckoning the bank carries, twins included: what the hardware's changes
        (a time offset found, the vibration's noise scale) apply to as they apply to ``M``."""
        return self.dead_reckonings + self.twins + [r for fb in self.fallbacks for r in fb.refs]

    def mature(self, t):
        """References old enough to judge fixes (at least one reference step old)."""
        return [r for r in self.refs if t - r.t0 >= self.cfg.integrity.min_age_s]

    # ------------------------------------------------------------------ the decision
    def judge(self, flt, m_pos, t, latlon=None) -> Verdict:
        """The decision for a position fix (a linearised :class:`~selfnav.ins.measurements.Model`
        ``m_pos`` of the horizontal rows; ``latlon`` its position, rad) against ``M`` = ``flt``
        and the references."""
        self._latlon = latlon
        P = flt.P
        self._end_outage(t)
        S = m_pos.H @ P @ m_pos.H.T + m_pos.R
        nis = _quad2(S, m_pos.r) if len(m_pos.r) == 2 else \
            float(m_pos.r @ np.linalg.solve(S, m_pos.r))
        if not self.cfg.integrity.bank:
            # the plain χ² gate of each fix alone (no references, no episodes): the baseline
            ok = nis <= self.gate
            return Verdict(FixStatus.USED if ok else FixStatus.REJECTED,
                           "" if ok else f"χ² gate (NIS {nis:.3g})", nis, apply=ok)
        if self.episode is not None:
            return self._judge_episode(flt, m_pos, t, nis)
        if self._map_alarm is not None:
            ref, ref_flt, why = self._map_alarm
            self._map_alarm = None
            self.m_track = []
            if any(r is ref for r in self.dead_reckonings):
                self.flush()
                self._open(ref.t0, reset=True)
                self.refs = [r for r in self.refs if r.t0 <= ref.t0]
                return Verdict(FixStatus.REJECTED, why, nis, reset_to=ref_flt,
                               excluded_since=ref.t0)
        if nis > self.gate:
            self.streak += 1
            self.used_streak = 0
            if self.streak >= self.cfg.integrity.rejections_to_open:
                self._open(t - 0.0, reset=False)
            return Verdict(FixStatus.REJECTED, f"χ² gate (NIS {nis:.3g})", nis)
        # a drag hides from each single test, not from their sum: the whitened innovations of
        # the recent fixes must average to zero (a sequential test over 4 … 32 fixes)
        wv = _whiten2(S, m_pos.r)
        self.innov.append(wv)
        self.innov = self.innov[-self.cfg.integrity.innovation_windows[-1]:]
        # (not while the filter is still settling: its innovations have a trend then)
        settled = self.t_healthy is not None and \
            t - self.t_healthy >= self.cfg.integrity.branch_after_s
        drift = self._innovation_drift() if settled else None
        if drift is not None:
            why, n = drift
            # the fault began within the window: back to the youngest reference before it —
            # from before twice the window where one stands: a drag grows from nothing, and
            # the sums see only its grown part; one from within the window's length before
            # it had taken the drag's first seconds and carried them with a σ that refused
            # the road lines and the clean fixes after (campaign drive 4929174180326169418: a
            # drag from 402.6 s found over 16 fixes at 430 s, M reset to the reference of
            # 414 s, 14 m across its road at σ 5 m for 45 s; to the one of 398 s, 2 s off
            # the route). None that old to go back to: the youngest before the window, as
            # before (kept without one, M followed the drag: 6860796862989826794, 9 → 63 m)
            t_from = t - n * self.fix_dt
            self.flush()
            # (a fallback of the start's heading sum counts here: the sums find the drag, the
            # fallback is the sum from before it)
            before = (self._references_before(t, t - 2 * n * self.fix_dt, t_from)
                      or self._references_before(t, t_from, t_from))
            if before:
                ref = before[-1]
                # the episode starts when the fault did (as far as the sums tell); M goes
                # back to the reference before it
                self._open(max(ref.t0, t_from), reset=True)
                self.refs = [r for r in self.refs if r.t0 <= ref.t0]
                self.fallbacks = [r for r in self.fallbacks if r.t0 <= ref.t0]
                if isinstance(ref, SumFallback):
                    return Verdict(FixStatus.REJECTED, f"{why} since {ref.t0:.1f} s (back to "
                                   f"the start's {len(ref.hyp.filters)} heading hypotheses "
                                   f"then)", nis, reset_sum=ref.hyp, excluded_since=ref.t0)
                return Verdict(FixStatus.REJECTED, f"{why} since {ref.t0:.1f} s", nis,
                               reset_to=ref.flt, excluded_since=ref.t0)
            self._open(t, reset=False)
            self.episode.kind = "drag"
            return Verdict(FixStatus.REJECTED, why, nis)
        self.flush()
        # the envelope: a fix outside a reference's is not accepted; and the separation M
        # would have from each reference after taking it
        K = np.linalg.solve(S, m_pos.H @ P).T
        dx = K @ m_pos.r
        P_plus_hh = (P - K @ S @ K.T)[:2, :2]
        alarms, tested = [], []
        mature = self.mature(t)
        gate = self.reference_gate(len(mature))
        kappa = self.cfg.integrity.reference_safety * (
            1.0 if self.adapter is None else self.adapter.reference_ratio)
        for ref in mature:
            q_fix, q_sep, sep = self._against(ref, flt, m_pos, dx, P_plus_hh)
            q_fix, q_sep = q_fix / kappa, q_sep / kappa
            tested.append((q_fix * kappa, t - ref.t0, ref.flt.q_scale))
            if self.diag is not None:
                self.diag.append((t, t - ref.t0, q_fix, q_sep, sep, kappa))
            self._sep_max = max(self._sep_max, sep)
            if max(q_fix, q_sep) > gate:
                alarms.append((ref, q_fix, q_sep, sep))
        if alarms:
            ref, q_fix, q_sep, sep = alarms[-1]            # the youngest that sees it
            self._open(ref.t0, reset=True, sep=sep)
            self.refs = [r for r in self.refs if r.t0 <= ref.t0]
            why = ("outside the dead-reckoning envelope" if q_fix > gate else
                   "would separate the solution from the dead reckoning")
            return Verdict(FixStatus.REJECTED, f"{why} since {ref.t0:.1f} s "
                           f"(χ² {max(q_fix, q_sep):.3g}, {sep:.1f} m)", nis,
                           reset_to=ref.flt, excluded_since=ref.t0)
        self.streak = 0
        self.used_streak += 1
        if self.used_streak == 1:
            self.t_healthy = t
        if self.adapter is not None:
            for q, age, lam in tested:
                self.adapter.on_reference(t, q, age, lam)
        return Verdict(FixStatus.USED, "", nis, apply=True)

    def _references_before(self, t, t_ref, t_from) -> list:
        """The mature references and sum fallbacks branched by ``t_ref``, oldest first — or,
        where the youngest is a fallback of the start's heading sum, only the youngest
        fallback that held another heading hypothesis best than ``M`` is now, if the sum was
        undecided when the drag began at ``t_from`` (the drag may have chosen M's — the sums
        date a drag late); none such: M, with the fixes since, knows more than the sum then
        did (docs/ekf.md)."""
        before = sorted((r for r in self.mature(t) + self.fallbacks
                         if r.t0 <= t_ref and t - r.t0 >= self.cfg.integrity.min_age_s),
                        key=lambda r: r.t0)
        if before and isinstance(before[-1], SumFallback) \
                and self.sum_choice_differs is not None:
            before = [r for r in before if isinstance(r, SumFallback)
                      and self.sum_choice_differs(r.hyp, t_from)][-1:]
        return before

    def _innovation_drift(self):
        """``(reason, n)`` if the recent whitened innovations have a mean: ``|Σ ν|² / n``
        above the gate of the references' false-alarm rate for the last ``n`` fixes."""
        wins = self.cfg.integrity.innovation_windows
        gate = self.reference_gate(len(wins) / 2.0)
        recent = np.array(self.innov[-wins[-1]:])
        for n in wins:
            if len(recent) < n:
                break
            m = recent[-n:].sum(axis=0)
            q = float(m @ m) / n
            if q > gate * self.cfg.integrity.reference_safety:
                return (f"the last {n} fixes pull the same way (their innovations sum to "
                        f"χ² {q:.3g}): a drag"), n
        return None

    def reference_gate(self, n_refs: float) -> float:
        """The χ² (2 dof) gate of the references' tests: ``false_alarms_per_hour`` shared
        among the tests of an hour (two per reference and fix)."""
        ig = self.cfg.integrity
        tests = max(1, 2 * n_refs) * 3600.0 / max(self.fix_dt, 1e-3)
        return chi2_gate(2, min(ig.false_alarms_per_hour / tests, ig.p_false_alarm))

    def _against(self, ref, flt, m_pos, dx, P_plus_hh):
        """(χ² of the fix against the reference, χ² of the separation ``M⁺ − b``, its size)."""
        b = ref.flt
        # the fix against the reference: its prediction differs from M's by their difference
        d0 = enu_offset(b.ins.lat, b.ins.lon, b.ins.h, flt.ins.lat, flt.ins.lon, flt.ins.h)[:2]
        r_b = m_pos.r + d0
        Pb = b.P[:2, :2]
        q_fix = _quad2(Pb + m_pos.R[:2, :2], r_b)
        # the separation after M took the fix (dx is removed from M: x⁺ = x − dx); the
        # separation's covariance floored per principal axis
        d = d0 - dx[:2]
        q_sep = _quad2_floored(Pb - P_plus_hh, d, self.cfg.integrity.separation_floor_m ** 2)
        return q_fix, q_sep, math.hypot(float(d[0]), float(d[1]))

    def _judge_episode(self, flt, m_pos, t, nis) -> Verdict:
        ep, ig = self.episode, self.cfg.integrity
        ep.fixes += 1
        in_gate = nis <= self.gate
        fix = _RunFix(t, -m_pos.r[:2].copy(), float(np.sqrt(m_pos.R[0, 0])))
        ep.offset = fix.offset
        if self._latlon is not None:
            if ep.origin is None:
                ep.origin = self._latlon
            fix.p = enu_offset(ep.origin[0], ep.origin[1], 0.0, self._latlon[0],
                               self._latlon[1], 0.0)[:2]
        if not ep.characterised:
            self._characterise(ep, fix)
        # the GNSS branch: the fixes by themselves (absolute positions), for "the INS is lost"
        ep.track = [f for f in ep.track if f.t >= t - ig.reinit_after_s] + [fix]
        self.run.append(fix)
        self.run = [f for f in self.run if f.t >= t - ig.run_max_s]
        test = self._run_test(flt)
        lost = self._ins_lost(ep, flt, t, test)
        if lost is not None:
            self.episode_origin = ep.origin
            self._close(t, kind="ins-fault")
            self.reinits += 1
            self.streak = 0
            self.used_streak = 1
            self.t_healthy = t
            return Verdict(FixStatus.USED, lost[0], nis, reinit_from=lost[1])
        if test is not None and not test["white"]:
            self.run = self.run[-1:]           # a scattered run starts again from this fix
            ep.t_fault = t                     # … and the fault was there until now
        if not in_gate:
            ep.rejected += 1
        if test is None:
            return Verdict(FixStatus.SUSPECT if in_gate else FixStatus.REJECTED,
                           f"a run of {len(self.run)} fixes is being checked" if in_gate else
                           f"outside the dead-reckoning envelope (NIS {nis:.3g})", nis)
        span = self.run[-1].t - self.run[0].t if len(self.run) > 1 else 0.0
        if test["white"] and test["moves"]:
            # the clean references still stand: a run outside any of their envelopes is
            # the drag that reset M, not the GNSS healthy again
            out = self._outside_references(flt, m_pos, t)
            if out is not None:
                return Verdict(FixStatus.SUSPECT if in_gate else FixStatus.REJECTED,
                               f"{test['why']}, but outside the dead reckoning since "
                               f"{out[0]:.1f} s (χ² {out[1]:.3g})", nis)
        if test["white"] and test["moves"]:
            still, add = self._fault_continues(ep, flt, test, t, span)
            if add is not None and in_gate:
                # the fault and health cannot be told apart: the fix is fused with the fault's
                # possible offset in its σ (no better than the dead reckoning, and as honest).
                # That offset is common to the run's fixes: each carries it N times over, so
                # the run's N fixes together tell no more of it than one (fused as independent,
                # N fixes at 4 Hz shrank a 58 m fault to 5 m and let a slow drag in)
                return Verdict(FixStatus.DEGRADED, f"{test['why']}; {still}", nis, apply=True,
                               add_R=add * max(1, len(self.run)))
            if still is not None:
                return Verdict(FixStatus.SUSPECT if in_gate else FixStatus.REJECTED,
                               f"{test['why']}, but as the fault would: {still}", nis)
        if test["white"] and test["moves"] and in_gate:
            self._close(t)
            self.recoveries += 1
            self.streak = 0
            self.used_streak = 1
            self.t_healthy = t
            return Verdict(FixStatus.USED, f"GNSS healthy again ({test['why']})", nis, apply=True,
                           run_velocity=test.get("velocity"))
        if test["white"] and test["moves"] and span >= ig.reinit_after_s - 1e-9:
            # the other hypothesis: the fixes agree with each other and move with the INS, but
            # have stood outside its envelope this long — the dead reckoning is off by more
            # than its σ (the INS is the faulty side): its position σ is opened to the offset
            self._close(t, kind="ins-fault")
            self.recoveries += 1
            self.reinits += 1
            self.streak = 0
            self.used_streak = 1
            self.t_healthy = t
            return Verdict(FixStatus.USED, f"the INS was off: {test['why']} "
                           f"{np.hypot(*test['offset']):.1f} m from it for {span:.0f} s", nis,
                           apply=True, widen=test["offset"],
                           run_velocity=test.get("velocity"))
        why = test["why"]
        onset = self._fault_continues(ep, flt, test, t, span)[0] if ep.fault is not None \
            else None
        if test["white"] and in_gate and onset is None \
                and self._outside_references(flt, m_pos, t) is None:
            # health and the faults that remain cannot be told apart (a dead reckoning wider
            # than what distinguishes them): the fix is fused as their mixture — its σ carrying
            # the variance those faults would add, weighted by their posterior — so a fix
            # inside the envelope is never refused for long, and taken no more than it is worth.
            # As above, that variance is the run's common offset: N times over for each of its
            # N fixes (fused as independent, three fixes of a Gauss–Markov window at p 1.00
            # took a consumer dead reckoning's σ from 250 to 68 m while it was 180 m off:
            # simulated drive 2855913014240202526)
            add = test["add_R"] * max(1, len(self.run))
            return Verdict(FixStatus.DEGRADED, f"{why}; fused with the faults' variance "
                           f"(p {test['p_fault']:.2f}, σ +{np.sqrt(add[0, 0]):.0f} m)",
                           nis, apply=True, add_R=add)
        if not in_gate:
            why = f"outside the dead-reckoning envelope (NIS {nis:.3g}); {why}"
        return Verdict(FixStatus.SUSPECT if in_gate else FixStatus.REJECTED, why, nis)

    def _characterise(self, ep, fix):
        """The fault's own behaviour from the first ``onset_s`` of the episode, while the dead
        reckoning is still sharp: a smooth fault (a drag, a drift, a jump: the offsets fit a
        line within the fixes' σ) is modelled as that line, to be extrapolated; a scattered
        one (white or Gauss–Markov outliers) needs none (the run test sees it)."""
        ig = self.cfg.integrity
        ep.onset.append(fix)
        span = ep.onset[-1].t - ep.onset[0].t
        if span < ig.onset_s - 1e-9 or len(ep.onset) < ig.run_min_fixes:
            return
        ep.characterised = True
        tt = np.array([f.t for f in ep.onset])
        o = np.array([f.offset for f in ep.onset])
        w = 1.0 / np.array([f.sigma for f in ep.onset]) ** 2
        tc = float(np.sum(w * tt) / np.sum(w))
        A = np.column_stack([np.ones_like(tt), tt - tc])
        N = (A * w[:, None]).T @ A
        coef = np.linalg.solve(N, (A * w[:, None]).T @ o)
        res = o - A @ coef
        chi = float(np.sum(w[:, None] * res**2))
        # the line's σ: the fixes' and the dead reckoning's own drift over the onset
        scale = max(chi / max(2 * (len(tt) - 2), 1), 1.0)
        if chi <= chi2_gate(2 * (len(tt) - 2), self.cfg.integrity.p_false_alarm) * 4.0:
            ep.fault = {"t": tc, "coef": coef, "cov": np.linalg.inv(N) * scale}

    def _fault_llr(self, ep, flt, o, var, t):
        """``((pred, C_f), llr)``: the smooth fault's line extrapolated to ``t`` (its offset
        and covariance) and the log-likelihood ratio of an offset ``o`` (variance ``var``)
        under it (H1) against zero — the dead reckoning's own error, σ from ``M`` (H0)."""
        f = ep.fault
        J = np.array([1.0, t - f["t"]])
        pred = f["coef"].T @ J
        C_f = (J @ f["cov"] @ J) * np.eye(2)
        P_r = flt.P[:2, :2] + np.eye(2) * var
        S1, S0 = P_r + C_f, P_r
        q1 = float((o - pred) @ np.linalg.solve(S1, o - pred))
        q0 = float(o @ np.linalg.solve(S0, o))
        return (pred, C_f), 0.5 * (q0 - q1) - 0.5 * np.log(np.linalg.det(S1) / np.linalg.det(S0))

    def _fault_continues(self, ep, flt, test, t, span=0.0):
        """Is a run better explained by the smooth fault going on than by healthy fixes?
        Its offset now against the fault's line extrapolated (H1) and against zero — the
        dead reckoning's own error, σ from ``M`` (H0); the run stays suspect unless H0 wins
        by ``recovery_odds``, or the fault would by now sit within one σ of
        the dead reckoning (then the two cannot be told apart, and taking the fixes costs no
        more than the dead reckoning's own error). Returns the reason, or None."""
        if ep.fault is None:
            return None, None
        o = test["offset"]
        (pred, C_f), llr = self._fault_llr(ep, flt, o, test["offset_var"], t)
        if llr < -np.log(self.cfg.integrity.recovery_odds):
            return None, None
        why = (f"its offset {np.hypot(*o):.1f} m against the fault's {np.hypot(*pred):.1f} m "
               f"(log-likelihood ratio {llr:+.1f})")
        # the fault's offset, weighted by how likely the fault still is (a two-component
        # mixture matched in its covariance: p = 1 / (1 + e^−llr))
        p_fault = 1.0 / (1.0 + math.exp(-float(np.clip(llr, -50.0, 50.0))))
        if float(pred @ np.linalg.solve(flt.P[:2, :2], pred)) <= 1.0:
            return (f"the fault would be within the dead reckoning's σ ({why})",
                    p_fault * (np.outer(pred, pred) + C_f))
        if span >= self.cfg.integrity.reinit_after_s and llr <= 0.0:
            # a fix inside the envelope is never refused for long once the fault no longer
            # explains it better: fused with the fault's possible offset in its σ (the fault
            # model may be the dead reckoning's own drift, after a false alarm)
            return (f"within the envelope for {span:.0f} s ({why})",
                    p_fault * (np.outer(pred, pred) + C_f))
        return why, None

    def _ins_lost(self, ep, flt, t, test):
        """The other side of the bank: the INS, not the GNSS, is lost — ``(reason, track)``
        or None. The last ``reinit_after_s`` of fixes must look healthy by themselves (their
        second differences as a car's, :func:`selfnav.ins.align.healthy_start`: not white or
        Gauss–Markov outliers) and move fast enough to give a course, and either the run test
        (:mod:`selfnav.ins.runtest`) finds them healthy fixes of a dead reckoning off by more
        than its covariance says, by ``ln(1/α)`` over health and every fault model, outside
        its envelope (the bank's gate) and not as the fault seen at the onset would be, or the
        episode has outlasted ``max_fault_s`` (the longest GNSS fault the navigator holds out
        against: seed 004's five minutes) with no reference left to say otherwise, or the road
        map puts ``M``'s track off the roads and the fixes' on them (module docstring)."""
        from selfnav.ins.align import healthy_start

        ig = self.cfg.integrity
        tr = ep.track
        if tr[-1].t - tr[0].t < ig.reinit_after_s - 1e-9 or len(tr) < ig.run_min_fixes + 2 \
                or any(f.p is None for f in tr):
            return None
        tt = np.array([f.t for f in tr])
        P = np.array([f.p for f in tr])
        sig = np.array([f.sigma for f in tr])
        if healthy_start(tt, P, sig, window=len(tr) - 2) is None:
            ep.t_scattered = t             # the fixes by themselves are no car's track
            return None
        s_fix = float(np.median(sig))
        # moving, with a course: the velocity at the last fix from a quadratic through the
        # track (the restart's heading; a wide one is split into hypotheses)
        tl = tt - tt[-1]
        A = np.column_stack([np.ones_like(tl), tl, tl * tl])
        coef, *_ = np.linalg.lstsq(A, P, rcond=None)
        s_v = s_fix * float(np.sqrt(np.linalg.inv(A.T @ A)[1, 1]))
        if np.hypot(*coef[1]) < max(self.cfg.init.reinit_speed, 2.0 * s_v):
            return None
        long = t - ep.t_start >= ig.max_fault_s and not self.mature(t)
        # the INS was started on the stream the bank now doubts — the episode opened within
        # ``branch_after_s`` of the (re)start, before any reference of its own existed — and
        # the fixes that followed were by themselves no car's track (white or Gauss–Markov;
        # a drag's fixes stay a smooth track and keep the likelihood test: drive_0708, a drag
        # 30 s after the start restarted on, 416 m off), and both a car's track and white
        # about the dead reckoning over the whole run now (a Gauss–Markov stream can look
        # like a car over 20 s, not also like the INS's path plus noise): nothing
        # independent stands for the INS — the start itself is what was faulty (simulated
        # drives started inside a 200 m Gauss–Markov window dead-reckoned 250 s past its end,
        # 400 m off)
        born_faulty = (ep.unwitnessed and ep.t_scattered is not None
                       and ep.t_fault is not None and tr[0].t > ep.t_fault)
        # the map refutes M and takes the fixes: M's track lies off the roads by ln(1/α) more
        # than its σ admits (against the same shape put elsewhere), while the fixes' lies on
        # them better than chance — the INS is lost whatever the fixes' own likelihoods say (an
        # INS started on a drag carries the drag's rate after it is switched off: its offsets
        # from clean fixes are the mirror image of a drag, and the run test cannot choose)
        on_roads = None
        if self.road_aid is not None and not (long or born_faulty) and ep.origin is not None \
                and t >= self._t_map + _MAP_LOOK_S - 1e-9:
            # (at most once a second however fast the fixes come: each look costs ~10 ms)
            self._t_map = float(t)
            on_roads = self.road_aid.track_evidence(
                ep.origin, P, np.array([f.p - f.offset for f in tr]), s_fix,
                float(np.sqrt(np.linalg.eigvalsh(flt.P[:2, :2])[-1])))
        map_lost = (on_roads is not None and on_roads[1] <= math.log(ig.p_false_alarm)
                    and on_roads[0] >= ig.map_fixes_llr)
        if not (long or born_faulty or map_lost):
            if test is None or test["log_lost"] < -math.log(ig.p_false_alarm):
                return None
            o = np.array([f.offset for f in tr[-ig.run_min_fixes:]]).mean(axis=0)
            if float(o @ np.linalg.solve(flt.P[:2, :2], o)) <= self.gate:
                # the fixes are still inside the dead reckoning's envelope: nothing says the
                # INS is lost (a slow drag sits there after a minute of dead reckoning); the
                # run is fused with the fault's offset in its σ instead (_fault_continues)
                return None
        why = (f"the episode outlasted {ig.max_fault_s:.0f} s" if long else
               "the start was made on the fixes that turned out faulty" if born_faulty else
               f"the map puts the fixes on its roads (log-likelihood ratio {on_roads[0]:+.1f}) "
               f"and the dead reckoning off them ({on_roads[1]:+.1f})" if map_lost else
               f"the dead reckoning is off by more than its σ (log Bayes factor "
               f"{test['log_lost']:+.1f} over health and faults)")
        return (f"the INS was lost: {len(tr)} fixes over {tt[-1] - tt[0]:.0f} s agree with each "
                f"other and {why}: restarted from them", list(tr))

    def _outside_references(self, flt, m_pos, t):
        """``(t0, χ²)`` of the youngest mature reference whose envelope the fix is outside,
        or None."""
        self.flush()
        mature = self.mature(t)
        gate = self.reference_gate(len(mature))
        kappa = self.cfg.integrity.reference_safety * (
            1.0 if self.adapter is None else self.adapter.reference_ratio)
        zero = np.zeros(flt.nx)
        P_hh = flt.P[:2, :2]
        for ref in reversed(mature):
            q_fix, _, _ = self._against(ref, flt, m_pos, zero, P_hh)
            if self.diag is not None:
                self.diag.append(("ref", t, t - ref.t0, q_fix, kappa, gate, np.sqrt(np.diag(ref.flt.P)[:2]).tolist()))
            if q_fix / kappa > gate:
                return ref.t0, q_fix / kappa
        return None

    def velocity_moves_with_fault(self, r_v, S_v, span_s: float = 10.0) -> bool:
        """While an episode refuses the positions: does a GNSS velocity move with them? Its
        offset from ``M``'s, ``r_v`` (measured − ``M``; E, N; m/s) with covariance ``S_v``,
        against the rate of the episode's fixes' offsets from ``M`` over the last ``span_s``
        (its track, not the run, which starts again at every scattered verdict; a line through
        them, weighted by their σ, its σ scaled by their scatter): a receiver whose velocity carries the positions' fault
        (a spoofer fooling both) has an innovation equal to that rate — the offsets' rate is
        the fault's minus ``M``'s velocity error, and so is the innovation; a clean Doppler's
        is ``M``'s velocity error alone. True when the first explains it better than the
        second, at prior odds of e to 1 for a clean Doppler (most position faults — multipath,
        a wrong fix — leave it clean; and a velocity the gate passes is within ``ln(1/α)`` of
        clean by construction, so that test cannot be the gate's): with the offsets standing
        still the two are alike and the velocity is kept. Such a velocity says nothing the
        refused positions did not, and
        fused it drags ``M`` along (drive_0708, a drag fooling both: the velocity gate, wider
        with every second of dead reckoning, let it in within a minute)."""
        seen = self.episode.track if self.episode is not None else self.run
        run = [f for f in seen if f.t >= seen[-1].t - span_s] if seen else []
        if len(run) < 4:
            return False
        rate, rate_cov = _rate(run, np.array([f.offset for f in run]), run[-1].t, order=1)
        r_v = np.asarray(r_v, float)[:2]
        S = np.asarray(S_v, float)[:2, :2]
        clean = float(r_v @ np.linalg.solve(S, r_v)) + math.log(np.linalg.det(S))
        d = r_v - rate
        S2 = S + rate_cov
        moving = float(d @ np.linalg.solve(S2, d)) + math.log(np.linalg.det(S2))
        return 0.5 * (clean - moving) > 1.0

    def _run_test(self, flt):
        """Are the fixes of the run healthy again? None while the run is too short; else the
        sequential likelihood-ratio test of :mod:`selfnav.ins.runtest`: ``white`` (no fault
        model explains the run decisively better than health: the run goes on; else it starts
        again from the newest fix), ``moves`` (health wins by ``ln(1/α)`` with the prior odds
        that a fault has ended by now, ``e^{d/T} − 1`` after ``d`` s of an episode whose faults
        last ``fault_mean_s`` on average), the offset and its rate (a quadratic through the
        offsets), the log Bayes factors and a reason."""
        from selfnav.ins.runtest import run_evidence, strongest_fault

        ig = self.cfg.integrity
        run = self.run
        if len(run) < ig.run_min_fixes or run[-1].t - run[0].t < ig.run_s - 1e-9:
            return None
        tt = np.array([f.t for f in run])
        o = np.array([f.offset for f in run])
        sig = np.array([f.sigma for f in run])
        p_ins = np.array([f.p - f.offset if f.p is not None else -f.offset for f in run])
        idx = [0, 1, 3, 4, 8]
        ev = run_evidence(tt, o, sig, p_ins, flt.P[np.ix_(idx, idx)], flt.acceleration_sigma(),
                          float(np.mean(flt.white_velocity_density()[:2])), ig,
                          fix_sigma=max(float(np.median(sig)), ig.fault_min_m),
                          fault_age=(tt[-1] - self.episode.t_start) if self.episode else 0.0)
        bf = ev["healthy"] - ev["fault"]
        # decisively faulty: the faults beat health and a lost INS alike
        faulty = ev["fault"] - max(ev["healthy"], ev["lost"])
        ep = self.episode
        t_f = tt[0] if ep is None else (ep.t_fault if ep.t_fault is not None else ep.t_start)
        d = tt[-1] - t_f
        prior = math.log(math.expm1(min(max(d, 1e-3) / ig.fault_mean_s, 50.0)))
        threshold = -math.log(ig.p_false_alarm)
        white = faulty < threshold
        # health again: it beats the scattered faults (white, Gauss–Markov) by ln(1/α) with the
        # prior odds that the fault has ended, and no drag beats it by as much — a drag the
        # dead reckoning cannot tell from its own drift sits inside its envelope (taken, it
        # moves the filter no further than the envelope allows); a faster one does not
        moves = (ev["healthy"] - ev["scattered"] + prior >= threshold
                 and ev["ramp"] - ev["healthy"] < threshold)
        n, dur = len(run), tt[-1] - tt[0]
        if not white:
            why = f"the fixes look faulty ({strongest_fault(ev)}; log Bayes factor {bf:+.1f})"
        elif not moves:
            why = (f"{n} fixes over {dur:.0f} s not yet healthy (log Bayes factor {bf:+.1f}, "
                   f"prior {prior:+.1f}, against {strongest_fault(ev)}; INS lost "
                   f"{ev['lost'] - max(ev['healthy'], ev['fault']):+.1f})")
        else:
            why = f"{n} fixes over {dur:.0f} s healthy (log Bayes factor {bf:+.1f})"
        # the offset and its rate now (a quadratic through the offsets, weighted by the fixes'
        # σ): what the run says of the dead reckoning's error
        w = 1.0 / sig**2
        tc = tt - tt[-1]
        A = np.column_stack([np.ones_like(tc), tc, tc * tc])
        Aw = A * w[:, None]
        N = A.T @ Aw
        coef = np.linalg.solve(N, Aw.T @ o)            # (3, 2): offset, rate, curvature
        Ni = np.linalg.inv(N)
        # the posterior of "the fault goes on" and the variance it asks a fused fix to carry
        p_fault = 1.0 / (1.0 + math.exp(min(bf + prior, 50.0)))
        out = {"white": white, "moves": moves, "offset": coef[0], "why": why,
               "offset_var": float(Ni[0, 0]), "rate": coef[1], "rate_cov": np.eye(2) * Ni[1, 1],
               "log_bf": bf, "log_lost": ev["lost"] - max(ev["healthy"], ev["fault"]),
               "p_fault": p_fault, "add_R": np.eye(2) * p_fault * ev["fault_variance"]}
        last = [f for f in run if f.t >= tt[-1] - ig.velocity_span_s - 1e-9]
        if len(last) >= 4 and all(f.p is not None for f in last):
            # the fixes' own velocity at the run's end (a quadratic through their positions
            # over the last seconds): what the run measures of the velocity, whatever M's
            # drift did during it
            out["velocity"] = _rate(last, np.array([f.p for f in last]), tt[-1], order=2)
        return out

    def on_correction(self, dx, flt):
        """``M`` was corrected by ``dx`` (an aid while the episode is open: a stop's zero
        velocity, the non-holonomic constraint, a fused fix): the run's offsets are re-expressed
        against the corrected dead reckoning — its position and velocity correction carried
        back over the run, its heading correction turning the path driven since — so that the
        run test sees the dead reckoning's error smooth, not a jump at each correction (a stop
        after a long dead reckoning moved ``M`` 50 m, and clean fixes across it looked
        faulty)."""
        ep = self.episode
        if ep is None or not self.run:
            return
        t_now = flt.t_true
        p_now = None
        if ep.origin is not None:
            p_now = enu_offset(ep.origin[0], ep.origin[1], 0.0, flt.ins.lat, flt.ins.lon,
                               0.0)[:2]
        seen = set()
        for f in self.run + ep.onset:
            if id(f) in seen:
                continue
            seen.add(id(f))
            shift = dx[0:2] + dx[3:5] * (f.t - t_now)
            if p_now is not None and f.p is not None:
                d = (f.p - f.offset) - p_now
                shift = shift + float(dx[8]) * np.array([d[1], -d[0]])
            f.offset = f.offset + shift

    def covariance_reopened(self, t):
        """``M``'s covariance was just shown too small by its trusted fixes' innovations
        (:meth:`selfnav.ins.calibrate.NoiseAdapter.on_fix`, made only while no mature
        reference stands): a young reference branched from it inherited that covariance and
        is dropped, and the health clock starts again — the
        next reference is branched only after ``branch_after_s`` of fixes fused with the
        reopened covariance, and an episode opening before then is unwitnessed
        (:meth:`doubt`). Kept, a reference branched from a start 41° off in heading at σ 4.5°
        reset ``M`` to itself, 220 m off, for four minutes (simulated)."""
        self.refs = []
        self.fallbacks = []
        self.t_healthy = float(t)

    def forget_innovations(self):
        """The recent innovations were another filter's (``M`` reset, restarted or replaced):
        the drift test and the adapter's reopening window begin again."""
        self.innov = []
        if self.adapter is not None:
            self.adapter.forget()

    def _open(self, t, reset, sep=0.0):
        self.forget_innovations()
        self.witnesses = []             # (normal mode's: the episode's M is another track)
        self.m_track = []
        self.episode = Episode(t, reset=reset, kind="drag" if reset else "outliers",
                               max_separation_m=sep,
                               unwitnessed=(self.t_started is not None
                                            and self._t_branch < self.t_started
                                            and t - self.t_started
                                            <= self.cfg.integrity.branch_after_s),
                               on_reference=reset or bool(self.mature(t)))
        self.run = []
        self.streak = 0
        self.used_streak = 0
        if reset:
            self.alarms += 1

    def _close(self, t, kind=None):
        ep = self.episode
        ep.t_end = t
        if kind is not None:
            ep.kind = kind
        ep.max_separation_m = max(ep.max_separation_m, self._sep_max if ep.reset else 0.0)
        if not ep.reset and ep.fixes and ep.rejected == ep.fixes - len(self.run):
            ep.kind = "outliers"
        self.episodes.append(ep)
        self.episode = None
        self.run = []
        self._sep_max = 0.0

    def on_outage(self, t, since):
        """No fix since ``since`` (the navigator's check at each epoch): an outage, recorded
        as an episode; it does not change how the next fix is judged (no evidence against
        the GNSS) and ends with it."""
        if self.outage is None and np.isfinite(since) and t - since > self.cfg.integrity.outage_s:
            self.outage = Episode(since, kind="outage")
            self.used_streak = 0

    def _end_outage(self, t):
        if self.outage is not None:
            self.outage.t_end = t
            self.episodes.append(self.outage)
            self.outage = None

    def finish(self, t):
        for ep in (self.episode, self.outage):
            if ep is not None:
                ep.t_end = t
                self.episodes.append(ep)
        self.episode = self.outage = None

    # ------------------------------------------------------------------ integrity
    def doubt(self, C_h) -> np.ndarray:
        """The horizontal output covariance ``C_h`` (2×2, ENU) of ``M`` as the bank can vouch
        for it. While an episode that no reference witnessed is open — nothing but the fixes
        now doubted stood behind ``M`` when it opened: a start, a restart, a recovery, each
        under ``branch_after_s`` old — the bank's verdict on the fixes rests only on ``M``'s
        own covariance, the very thing in question (simulated consumer starts 5σ off in tilt
        or 40° in heading rejected clean fixes for minutes, σ 15 m at 300 m of error). The
        two sides are then equally likely: the covariance is the mixture's about ``M``,
        ``C_h + ½ d dᵀ``, ``d`` the latest fix's offset from ``M``."""
        ep = self.episode
        if ep is None or ep.on_reference or ep.offset is None:
            return C_h
        return C_h + 0.5 * np.outer(ep.offset, ep.offset)

    def protection_level(self, flt, t, P_out=None) -> float:
        """Horizontal protection level at the configured integrity risk, m: ``M``'s own bound
        (of the reported point, ``P_out``: :func:`selfnav.ins.ekf.output_covariance`), and —
        while references stand behind it — the largest undetected fault the youngest mature
        reference allows (its detection threshold on the separation plus its bound)."""
        Ph = flt.P[:2, :2]
        pl = self.k_pl * float(np.sqrt(_largest_eig2(Ph if P_out is None else P_out)))
        if self.episode is not None:
            return pl
        mat = self.mature(t)
        if mat:
            b = mat[-1].flt
            Pb = b.P[:2, :2]
            lam = _largest_eig2(Pb - Ph)
            pl = max(pl, float(np.sqrt(self.gate * lam))
                     + self.k_pl * float(np.sqrt(_largest_eig2(Pb))))
        return pl


def _whiten2(S, r) -> np.ndarray:
    """``L⁻¹ r`` with ``S = L Lᵀ`` (Cholesky) of a 2×2 covariance: the whitened innovation."""
    a, b, d = float(S[0, 0]), float(S[1, 0]), float(S[1, 1])
    l00 = math.sqrt(a)
    l10 = b / l00
    l11 = math.sqrt(d - l10 * l10)
    w0 = float(r[0]) / l00
    return np.array([w0, (float(r[1]) - l10 * w0) / l11])


def _quad2(S, r) -> float:
    """``rᵀ S⁻¹ r`` of a 2×2 covariance ``S`` (closed form: it runs per reference and fix)."""
    a, b, c, d = float(S[0, 0]), float(S[0, 1]), float(S[1, 0]), float(S[1, 1])
    x, y = float(r[0]), float(r[1])
    return (d * x * x - (b + c) * x * y + a * y * y) / (a * d - b * c)


def _quad2_floored(C, r, floor) -> float:
    """``rᵀ C⁻¹ r`` of the symmetric part of a 2×2 ``C`` with its eigenvalues floored at
    ``floor`` (closed-form eigen-decomposition)."""
    a, d = float(C[0, 0]), float(C[1, 1])
    b = 0.5 * (float(C[0, 1]) + float(C[1, 0]))
    x, y = float(r[0]), float(r[1])
    m, h = 0.5 * (a + d), math.hypot(0.5 * (a - d), b)
    l1, l2 = m + h, m - h                       # l1 ≥ l2
    if h == 0.0:
        return (x * x + y * y) / max(l1, floor)
    # the eigenvector of l1: (b, l1 − a), or (l1 − d, b) — whichever is the better conditioned
    if abs(l1 - a) >= abs(l1 - d):
        u, v = b, l1 - a
    else:
        u, v = l1 - d, b
    n = math.hypot(u, v)
    u, v = u / n, v / n
    p1, p2 = u * x + v * y, -v * x + u * y
    return p1 * p1 / max(l1, floor) + p2 * p2 / max(l2, floor)


def _largest_eig2(A) -> float:
    """Largest eigenvalue of the symmetric part of a 2×2 matrix, clipped at 0 (closed form:
    it runs at every output state)."""
    a, d = float(A[0, 0]), float(A[1, 1])
    b = 0.5 * (float(A[0, 1]) + float(A[1, 0]))
    return max(0.5 * (a + d) + math.hypot(0.5 * (a - d), b), 0.0)


__all__ = ["FaultBank", "Reference", "Episode", "Verdict"]
