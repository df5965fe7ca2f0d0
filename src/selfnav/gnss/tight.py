"""Tightly coupled odometry + pseudorange filter with a self-tuning NLOS mixture (issue 23, part 3,
"with wheel speed and yaw rate instead of an IMU").

The car's speed and yaw rate propagate a planar dead reckoning (:mod:`selfnav.gnss.odometry`,
(1)–(2)); every pseudorange updates it **one satellite at a time in one joint update**, so a
street with two or three satellites still corrects the position, and each satellite is judged
on its own.

State (tangent plane at ``origin``)::

    x = [E, N, U, H, s, b, c, d, z, c_2 … c_k]  position (m), heading H (rad, clockwise from
                                                North), speed scale s, yaw-rate bias b (rad/s),
                                                receiver clock c (m, first system), clock drift
                                                d (m/s), residual zenith delay z (m), clock
                                                offsets of the other systems (m)

Pseudorange of satellite i (system j), with the Earth-rotation term of
:func:`selfnav.gnss.models.pseudorange_model`::

    ρ_i = |r_i − r| + ω_e/c (x_i y − y_i x) + c + z / sin(E_i) + c_j + e_i                   (1)

**The error e_i is a mixture** (:mod:`selfnav.gnss.mixture`; an urban canyon's reflected
signals arrive late: their error is positive and large)::

    p(e | C/N0) = w_0 N(0, σ_L(C/N0)²) + Σ_k w_k N(μ_k, σ_k²),   w per C/N0 band,
    σ_L(C/N0) = σ_L45 · 10^((45 − C/N0)/20)                                                 (2)

Each epoch's update is a max-mixture iterated EKF: every satellite takes the component that
explains its residual best at the current estimate (with the prior's spread on the first pass),
the update is redone from the prior until the choice settles. The mixture's parameters are
**tuned on the fly** by expectation-maximisation over the post-fit residuals of the last
``tune_window`` seconds — causal: an epoch's model was fitted on earlier epochs only.

**The σ reported** (``P_report``) is propagated with the same gains, R inflated by the lag-one
correlation of the residuals, ``(1 + ρ)/(1 − ρ)``, plus the mixture's spread about each chosen
component (responsibility-weighted): the filter's own P takes the errors as independent.

**Start**: position, clocks and height from the first epoch whose least-squares fix
(:func:`selfnav.gnss.spp.solve_spp`) passes its χ² test (``start_wait`` s at most); the heading
is not needed: a bank of ``n_heading`` filters spaced evenly around the circle runs until the
pseudoranges' likelihood leaves one (posterior ``> 1 − bank_p``, starts that converged to one
heading merged); until then the output is the most probable one.

The RTS smoother (``smooth=True``) runs over the chosen filter's stored epochs and then
re-decides each satellite's component on the smoothed track (refusing line of sight to a
satellite whose residuals keep one sign) and smooths again (``smooth_passes``). The drift guard
(:mod:`selfnav.gnss.guard`, ``cfg.guard``) is opt-in.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from selfnav.earth import enu_rotation, enu_to_geodetic, geodetic_to_ecef
from selfnav.errors import SelfnavError
from selfnav.gnss.guard import DriftGuard, GuardConfig
from selfnav.gnss.mixture import MixtureModel, ResidualCorrelation
from selfnav.gnss.models import pseudorange_model
from selfnav.gnss.odometry import propagate

IE, IN, IU, IH, IS, IB, IC, ID, IZ = range(9)
_ODO = [IE, IN, IH, IS, IB]             # the states of selfnav.gnss.odometry, in its order
_LOG_2PI = math.log(2.0 * math.pi)
_SIN_MASK = math.sin(math.radians(5.0))


@dataclass
class TightConfig:
    """Noise model and options of :class:`TightOdometryFilter` (SI units, radians)."""

    speed_sigma: float = 0.05               # m/s, white
    yaw_rate_sigma: float = 0.002           # rad/s, white
    scale_sigma0: float = 0.02              # a car's wheel-speed scale
    scale_rw: float = 1e-4                  # 1/√s
    bias_sigma0: float = math.radians(0.2)  # rad/s, a car's yaw-rate sensor
    bias_rw: float = 1e-5                   # rad/s/√s
    pos_rw: float = 0.1                     # m/√s, slip and the planar model
    height_rw: float = 0.05                 # m/√s, a road's height changes slowly
    clock_phase_rw: float = 0.5             # m/√s
    clock_drift_rw: float = 1.0             # m/s/√s
    isb_rw: float = 0.01                    # m/√s, inter-system clock offsets
    drift_sigma0: float = 200.0             # m/s
    position_sigma0: float = 30.0           # m, around the first least-squares fix (at least)
    position_sigma0_unchecked: float = 100.0  # m, when no fix passed its χ² test in start_wait
    start_wait: float = 10.0                # s of epochs searched for a consistent first fix
    n_heading: int = 12
    bank_p: float = 1e-3                    # a hypothesis below this posterior is dropped
    bank_merge: float = math.radians(3.0)   # headings this close are one hypothesis
    iterations: int = 4
    tune_window: float = 60.0               # s of post-fit residuals for the mixture's EM
    tune_every: float = 5.0                 # s
    mixture: MixtureModel = field(default_factory=MixtureModel)
    smooth_passes: int = 2
    report_ambiguity: bool = True
    bias_half_window: float = 5.0           # s, smoother: a satellite's residual mean (±)
    bias_k: float = 3.0                     # its σ before it is not line of sight (0: off)
    guard: GuardConfig | None = None        # the drift guard (opt-in: docs/gnss.md)
    zenith_sigma0: float = 3.0              # m, residual zenith delay state (0: off)
    zenith_rw: float = 0.0                  # m/√s


class Epoch(NamedTuple):
    """One stored epoch of a filter, for its smoother: the state and covariance before
    (``x_prior``, ``P_prior``, ``Pr_prior``: the reported one) and after the update, the
    transition ``F`` from the epoch before, the pseudoranges' rows ``idx`` and the components
    chosen, the odometry ``steps`` and the correlation ``inflation`` used."""

    t: float
    x_prior: np.ndarray
    P_prior: np.ndarray
    x: np.ndarray
    P: np.ndarray
    F: np.ndarray
    idx: np.ndarray
    comp: np.ndarray
    steps: list
    Pr: np.ndarray
    inflation: float
    Pr_prior: np.ndarray


class TightOdometryFilter:
    """One hypothesis of the tightly coupled filter: ``predict(v, ω, dt)``, ``update(...)``.

    After ``update`` the object holds ``x, P``, the satellites' ``residual`` (post-fit, m),
    ``component`` (0 line of sight, 1… delayed), the epoch's ``log_likelihood``, and ``P_report``:
    the covariance the same gains give when each satellite's error is correlated in time
    (:class:`selfnav.gnss.mixture.ResidualCorrelation`) and its component uncertain — the σ it
    reports.
    """

    def __init__(self, x0, P0, origin_ecef, C_en, systems, cfg: TightConfig):
        self.x = np.array(x0, float)
        self.P = np.array(P0, float)
        self.P_report = self.P.copy()
        self.n = len(self.x)
        self.r0 = np.asarray(origin_ecef, float)
        self.C_ne = np.asarray(C_en, float).T                 # ENU -> ECEF
        self.systems = list(systems)
        self.cfg = cfg
        self.residual = np.empty(0)
        self.component = np.empty(0, int)
        self.log_likelihood = 0.0
        self.history = []
        self.nd = None                                        # first drift state (a branch)
        self.init_args = (self.x.copy(), self.P.copy(), origin_ecef, C_en, systems, cfg)

    def branch(self, drift_sigma: float):
        """A copy (no history) that also explains the GNSS by a common drift: four states at
        the end, the offset ``d`` (E, N, m; 0 now) every pseudorange sees and its rate (prior
        σ ``drift_sigma`` m/s): ρ is computed at ``p + d`` (:mod:`selfnav.gnss.guard`)."""
        n = self.n
        x = np.r_[self.x, np.zeros(4)]
        P = np.zeros((n + 4, n + 4))
        P[:n, :n] = self.P
        P[n + 2, n + 2] = P[n + 3, n + 3] = drift_sigma ** 2
        b = TightOdometryFilter(x, P, *self.init_args[2:])
        Pr = P.copy()
        Pr[:n, :n] = self.P_report
        b.P_report = Pr
        b.nd = n
        b.drift_rw = self.cfg.guard.drift_rw
        return b

    # --- propagation: seed odometry (1)-(2) and the clock -----------------------------------
    def predict(self, v, w, dt):
        cfg, x, n = self.cfg, self.x, self.n
        # the odometry's own states follow docs/smartloc.md (2) (selfnav.gnss.odometry)
        xo, Fo, Go = propagate(x[_ODO], v, w, dt)
        x[_ODO] = xo
        F = np.eye(n)
        F[np.ix_(_ODO, _ODO)] = Fo
        G = np.zeros((n, 2))
        G[_ODO] = Go
        F[IC, ID] = dt
        x[IC] += dt * x[ID]
        q = np.zeros(n)
        q[IE] = q[IN] = cfg.pos_rw ** 2 * dt
        q[IU] = cfg.height_rw ** 2 * dt
        q[IS] = cfg.scale_rw ** 2 * dt
        q[IB] = cfg.bias_rw ** 2 * dt
        q[IC] = cfg.clock_phase_rw ** 2 * dt
        q[ID] = cfg.clock_drift_rw ** 2 * dt
        q[IZ] = cfg.zenith_rw ** 2 * dt
        q[IZ + 1:IZ + len(self.systems)] = cfg.isb_rw ** 2 * dt
        nd = self.nd
        if nd is not None:                                    # the drift branch's d, ḋ
            F[nd, nd + 2] = F[nd + 1, nd + 3] = dt
            x[nd:nd + 2] += dt * x[nd + 2:nd + 4]
            q[nd + 2:nd + 4] = self.drift_rw ** 2 * dt
        Q = G @ np.diag([cfg.speed_sigma ** 2, cfg.yaw_rate_sigma ** 2]) @ G.T + np.diag(q)
        self.P = F @ self.P @ F.T + Q
        self.P_report = F @ self.P_report @ F.T + Q
        return F

    # --- the pseudorange model (1) at a state -----------------------------------------------
    def _model(self, x, sat, sys_idx):
        p = x[IE:IU + 1].copy()
        if self.nd is not None:
            p[:2] += x[self.nd:self.nd + 2]
        rho, H4 = pseudorange_model(self.r0 + self.C_ne @ p, 0.0, sat)
        Hm = np.zeros((len(rho), self.n))
        Hm[:, IE:IU + 1] = H4[:, :3] @ self.C_ne
        if self.nd is not None:
            Hm[:, self.nd:self.nd + 2] = Hm[:, IE:IN + 1]
        Hm[:, IC] = 1.0
        # a zenith delay left by the atmosphere models, mapped by 1/sin(elevation)
        Hm[:, IZ] = 1.0 / np.maximum(-Hm[:, IU], _SIN_MASK)
        clk = x[IC] + Hm[:, IZ] * x[IZ]
        for j in range(1, len(self.systems)):
            m = sys_idx == j
            Hm[m, IZ + j] = 1.0
            clk[m] += x[IZ + j]
        return rho + clk, Hm

    def update(self, pr, sat, sys_idx, cn0, mixture: MixtureModel | None = None, *,
               components=None, inflation=1.0):
        """Max-mixture iterated update with one epoch's pseudoranges (module docstring);
        ``components`` (0, 1, … per satellite) fixes the choice instead (the smoother's
        re-pass); ``inflation`` multiplies R in ``P_report`` only."""
        cfg = self.cfg
        mix = mixture or cfg.mixture
        xp, Pp = self.x.copy(), self.P
        w, mu, var = mix.components(cn0)
        logw = np.log(w)
        rows = np.arange(len(pr))
        xj, comp, P = xp, None, Pp
        for it in range(cfg.iterations if components is None else 1):
            h, Hm = self._model(xj, sat, sys_idx)
            e = pr - h
            spread = np.einsum("ij,jk,ik->i", Hm, Pp if it == 0 else P, Hm)
            tot = var + spread[:, None]
            ll = logw - 0.5 * (np.log(tot) + (e[:, None] - mu) ** 2 / tot)
            new = np.argmax(ll, axis=1) if components is None else np.asarray(components, int)
            if comp is not None and np.array_equal(new, comp):
                break
            comp = new
            R = var[rows, comp]
            innov = e - mu[rows, comp] - Hm @ (xp - xj)
            PHt = Pp @ Hm.T
            S = Hm @ PHt + np.diag(R)
            K = np.linalg.solve(S, PHt.T).T
            xj = xp + K @ innov
            IKH = np.eye(self.n) - K @ Hm
            P = IKH @ Pp @ IKH.T + (K * R) @ K.T
            if it == 0:
                _, logdet = np.linalg.slogdet(S)
                self.log_likelihood = float(-0.5 * (innov @ np.linalg.solve(S, innov) + logdet
                                                    + len(pr) * _LOG_2PI)
                                            + np.sum(logw[rows, comp]))
        self.x, self.P = xj, 0.5 * (P + P.T)
        R_rep = R * inflation
        if cfg.report_ambiguity:
            # the choice of component is itself uncertain: the reported covariance takes the
            # mixture's spread about the chosen component, weighted by the responsibilities
            # at the residual the choice was made on
            g = np.exp(ll - ll.max(1, keepdims=True))
            g /= g.sum(1, keepdims=True)
            chosen = mu[rows, comp]
            R_rep = (R_rep + np.sum(g * (var + (mu - chosen[:, None]) ** 2), 1)
                     - g[rows, comp] * var[rows, comp])
        Pr = IKH @ self.P_report @ IKH.T + (K * R_rep) @ K.T
        self.P_report = 0.5 * (Pr + Pr.T)
        h, _ = self._model(self.x, sat, sys_idx)
        self.residual = pr - h
        self.component = comp
        return self


@dataclass
class TightResult:
    """Per epoch: ``t``, ``east, north, up`` (tangent plane at ``origin`` = (lat, lon, h)),
    ``lat, lon, h``, ``heading`` (rad), ``scale``, ``yaw_bias`` (rad/s), ``sigma_e, sigma_n``,
    ``n_sats``, ``n_reflected`` (the satellites given a delayed component), ``clock`` (m),
    ``smoothed``; ``stats`` (dict); per input pseudorange ``obs_residual`` (m, at the output
    state) and ``obs_component``."""

    t: np.ndarray
    east: np.ndarray
    north: np.ndarray
    up: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    heading: np.ndarray
    scale: np.ndarray
    yaw_bias: np.ndarray
    sigma_e: np.ndarray
    sigma_n: np.ndarray
    n_sats: np.ndarray
    n_reflected: np.ndarray
    clock: np.ndarray
    origin: tuple
    smoothed: bool = False
    stats: dict = field(default_factory=dict)
    obs_residual: np.ndarray | None = None     # (M,) m, per input pseudorange (NaN: not used)
    obs_component: np.ndarray | None = None    # (M,) 0 line of sight, 1… delayed, −1 not used

    @property
    def sigma_h(self):
        return np.hypot(self.sigma_e, self.sigma_n)


def _epochs(t_obs):
    order = np.argsort(t_obs, kind="stable")
    t_ep, first = np.unique(t_obs[order], return_index=True)
    bounds = np.append(first, len(order))
    return t_ep, order, bounds


def _first_fix(prs, idx, systems):
    """Least-squares position and clocks of one epoch (C/N0 weights, exclusion), or None;
    with whether its residuals pass their χ² test with 2 or more degrees of freedom left, and
    its horizontal σ per axis scaled by the residuals."""
    from selfnav.gnss.spp import SppConfig, solve_spp

    sp = solve_spp(prs.t[idx], prs.pr[idx], prs.var[idx], prs.sat_ecef[idx], prs.system[idx],
                   prs.elevation[idx], prs.cn0[idx], SppConfig(weighting="cn0"))
    if not np.isfinite(sp.lat[0]):
        return None
    clocks = np.zeros(len(systems))
    have = dict(zip(sp.systems.tolist(), sp.clock[0].tolist()))
    ref = have.get(systems[0], np.nan)
    for j, s in enumerate(systems):
        c = have.get(s, np.nan)
        clocks[j] = c if np.isfinite(c) else (ref if np.isfinite(ref) else 0.0)
    if not np.isfinite(clocks[0]):
        clocks[0] = np.nanmean([v for v in have.values()])
    vf = sp.variance_factor[0]
    sigma = float(sp.sigma_m[0] * math.sqrt(max(vf, 1.0) if np.isfinite(vf) else 1.0))
    return sp.lat[0], sp.lon[0], sp.h[0], clocks, bool(sp.passed[0] and sp.dof[0] >= 2), sigma


def run_tight(prs, odo, cfg: TightConfig | None = None, *, smooth: bool = False,
              heading0=None, progress=None) -> TightResult:
    """Run the tightly coupled filter over a record: pseudoranges ``prs``
    (:class:`selfnav.io.smartloc.Pseudoranges`) and odometry ``odo``
    (:class:`selfnav.io.smartloc.Odometry`: speed and yaw rate).

    One output row per pseudorange epoch from the first one with a least-squares fix. Causal
    unless ``smooth`` (the RTS smoother of the module docstring). ``heading0 = (H, σ_H)`` (rad,
    clockwise from North) replaces the heading bank with one filter.
    """
    cfg = cfg or TightConfig()
    t0_wall = time.perf_counter()
    t_ep, order, bounds = _epochs(np.asarray(prs.t, float))
    systems = np.unique(prs.system).tolist()
    sys_of = {s: j for j, s in enumerate(systems)}
    sys_idx_all = np.array([sys_of[s] for s in prs.system.tolist()], int)
    if len(odo.t) < 2:
        raise SelfnavError("the odometry has fewer than 2 samples")
    # the start: the first epoch whose least-squares fix passes its χ² test; failing one within
    # ``start_wait`` s, the first fix at all, with a wide σ
    k0, fix, first = 0, None, None
    while k0 < len(t_ep):
        idx = order[bounds[k0]:bounds[k0 + 1]]
        f = _first_fix(prs, idx, systems) if len(idx) >= 3 + len(systems) else None
        if f is not None and first is None:
            first = (k0, f)
        if f is not None and f[4]:
            fix = f
            break
        if first is not None and t_ep[k0] - t_ep[first[0]] >= cfg.start_wait:
            break
        k0 += 1
    if fix is None:
        if first is None:
            raise SelfnavError("no epoch has enough pseudoranges for a first fix")
        k0, fix = first
        fix = fix[:4] + (False, max(fix[5], cfg.position_sigma0_unchecked))
    lat0, lon0, h0, clocks, _, fix_sigma = fix
    pos_sigma0 = max(cfg.position_sigma0, 3.0 * fix_sigma)
    origin = (float(lat0), float(lon0), float(h0))
    r0 = geodetic_to_ecef(lat0, lon0, h0)
    C_en = enu_rotation(lat0, lon0)
    nsys = len(systems)
    n = IZ + nsys
    keys_all = np.asarray(prs.system, np.int64) * 1000 + np.asarray(prs.sat_id, np.int64)
    x0 = np.zeros(n)
    x0[IS] = 1.0
    x0[IC] = clocks[0]
    x0[IZ + 1:] = clocks[1:] - clocks[0]
    P0 = np.diag(np.r_[[pos_sigma0 ** 2] * 3, [0.0], cfg.scale_sigma0 ** 2,
                       cfg.bias_sigma0 ** 2, pos_sigma0 ** 2, cfg.drift_sigma0 ** 2,
                       cfg.zenith_sigma0 ** 2, [cfg.position_sigma0 ** 2] * (nsys - 1)])
    if heading0 is None:
        spacing = 2 * math.pi / cfg.n_heading
        starts = [(i * spacing, spacing / 2) for i in range(cfg.n_heading)]
    else:
        starts = [tuple(heading0)]
    bank = []
    for h_start, h_sigma in starts:
        x = x0.copy()
        x[IH] = h_start
        P = P0.copy()
        P[IH, IH] = h_sigma ** 2
        bank.append(TightOdometryFilter(x, P, r0, C_en, systems, cfg))
    logw = np.zeros(len(bank))
    mix = cfg.mixture.copy()
    tune_e, tune_c, tune_t = [], [], []
    dt_med = float(np.median(np.diff(t_ep))) if len(t_ep) > 1 else 1.0
    corr = ResidualCorrelation(cfg.tune_window, 2.5 * dt_med)
    next_tune = t_ep[k0] + cfg.tune_every
    speed, yaw_rate = np.asarray(odo.speed, float), np.asarray(odo.yaw_rate, float)
    K = len(t_ep) - k0
    out = {k: np.full(K, np.nan) for k in ("E", "N", "U", "H", "S", "B", "sE", "sN", "clk")}
    n_sats = np.zeros(K, int)
    n_refl = np.zeros(K, int)
    infl = np.ones(K)
    held = np.zeros(K, bool)
    guard = DriftGuard(cfg.guard) if cfg.guard is not None else None
    M = len(prs.t)
    obs_res = np.full(M, np.nan)
    obs_comp = np.full(M, -1, int)
    t_prev = t_ep[k0]
    for j, k in enumerate(range(k0, len(t_ep))):
        t = t_ep[k]
        idx = order[bounds[k]:bounds[k + 1]]
        steps = []
        if j:
            # zero-order hold of the odometry sample in effect, stepping at each odometry sample
            ts = odo.t[(odo.t > t_prev) & (odo.t < t)]
            for a, b in zip(np.r_[t_prev, ts], np.r_[ts, t]):
                i_od = max(int(np.searchsorted(odo.t, a, side="right")) - 1, 0)
                steps.append((speed[i_od], yaw_rate[i_od], b - a))
        for f in bank:
            F = np.eye(f.n)
            for v, w, dt in steps:
                F = f.predict(v, w, dt) @ F
            xprior, Pprior, Prprior = f.x.copy(), f.P.copy(), f.P_report.copy()
            f.update(prs.pr[idx], prs.sat_ecef[idx], sys_idx_all[idx], prs.cn0[idx], mix,
                     inflation=corr.inflation)
            f.history.append(Epoch(t, xprior, Pprior, f.x.copy(), f.P.copy(), F, idx,
                                   f.component.copy(), steps, f.P_report.copy(),
                                   corr.inflation, Prprior))
        if len(bank) > 1:
            logw += np.array([f.log_likelihood for f in bank])
            logw -= logw.max()
            post = np.exp(logw)
            post /= post.sum()
            keep = post >= cfg.bank_p
            # two starts that converged to one heading are one hypothesis: keep the likelier
            for a in np.argsort(-post):
                if not keep[a]:
                    continue
                for b in range(len(bank)):
                    if b != a and keep[b] and post[b] <= post[a] and abs(
                            (bank[b].x[IH] - bank[a].x[IH] + math.pi) % (2 * math.pi)
                            - math.pi) < cfg.bank_merge:
                        keep[b] = False
            bank = [f for f, kp in zip(bank, keep) if kp]
            logw = logw[keep]
        best = bank[int(np.argmax(logw))]
        shown = best if guard is None or len(bank) > 1 else guard.step(
            t, steps, best, (prs.pr[idx], prs.sat_ecef[idx], sys_idx_all[idx], prs.cn0[idx]),
            mix, corr.inflation)
        held[j] = shown is not best
        x, P = shown.x, shown.P_report
        out["E"][j], out["N"][j], out["U"][j] = x[IE], x[IN], x[IU]
        out["H"][j] = x[IH] % (2 * math.pi)
        out["sE"][j], out["sN"][j] = math.sqrt(P[IE, IE]), math.sqrt(P[IN, IN])
        out["clk"][j] = x[IC]
        out["S"][j], out["B"][j] = x[IS], x[IB]
        n_sats[j] = len(idx)
        obs_res[idx], obs_comp[idx] = best.residual, best.component
        n_refl[j] = int(np.sum(best.component >= 1))
        infl[j] = corr.add(t, keys_all[idx], best.residual / mix.sigma_los(prs.cn0[idx]),
                           best.component == 0)
        # the mixture learns from the chosen filter's post-fit residuals (causal)
        tune_e.append(best.residual)
        tune_c.append(prs.cn0[idx])
        tune_t.append(np.full(len(idx), t))
        if t >= next_tune:
            te = np.concatenate(tune_t)
            m = te > t - cfg.tune_window
            mix.fit(np.concatenate(tune_e)[m], np.concatenate(tune_c)[m])
            keep_from = int(np.searchsorted([a[0] for a in tune_t], t - cfg.tune_window))
            del tune_e[:keep_from], tune_c[:keep_from], tune_t[:keep_from]
            next_tune = t + cfg.tune_every
        t_prev = t
        if progress is not None:
            progress(j + 1, K)
    final = bank[int(np.argmax(logw))]
    stats = {"epochs": int(K), "start_epoch_t": float(t_ep[k0]), "systems": systems,
             "bank_left": len(bank), "mixture": {"sigma_los45": mix.sigma_los45,
                                                 "means": mix.means.tolist(),
                                                 "sigmas": mix.sigmas.tolist(),
                                                 "weights": mix.weights.round(3).tolist()},
             "reflected_share": float(n_refl.sum() / max(n_sats.sum(), 1)),
             "inflation_median": float(np.median(infl)),
             "guard_episodes": [] if guard is None else guard.episodes,
             "guard_max_llr": None if guard is None else guard.max_llr,
             "held_s": float(np.sum(np.diff(t_ep[k0:], prepend=t_ep[k0])[held]))}
    smoothed = False
    if smooth:
        X, Ps, hist = _smooth(final, prs, sys_idx_all, keys_all, mix, cfg)
        for k, ep in enumerate(hist):
            hx, _ = final._model(X[k], prs.sat_ecef[ep.idx], sys_idx_all[ep.idx])
            obs_res[ep.idx], obs_comp[ep.idx] = prs.pr[ep.idx] - hx, ep.comp
        n_refl = np.array([int(np.sum(ep.comp >= 1)) for ep in hist])
        out["E"], out["N"], out["U"] = X[:, IE], X[:, IN], X[:, IU]
        out["H"] = X[:, IH] % (2 * math.pi)
        # the smoother's reported covariance (Ps here): the same gains on the report model
        out["sE"] = np.sqrt(np.maximum(Ps[:, IE, IE], 0.0))
        out["sN"] = np.sqrt(np.maximum(Ps[:, IN, IN], 0.0))
        out["clk"] = X[:, IC]
        out["S"], out["B"] = X[:, IS], X[:, IB]
        smoothed = True
    enu = np.column_stack([out["E"], out["N"], out["U"]])
    lat, lon, h = enu_to_geodetic(enu, *origin)
    stats["runtime_s"] = time.perf_counter() - t0_wall
    return TightResult(t_ep[k0:], out["E"], out["N"], out["U"], np.asarray(lat), np.asarray(lon),
                       np.asarray(h), out["H"], out["S"], out["B"], out["sE"], out["sN"], n_sats,
                       n_refl, out["clk"], origin, smoothed, stats, obs_res, obs_comp)


def _rts(hist, report: bool = False):
    """RTS smoother over stored :class:`Epoch` s; heading differences wrapped. ``report``: also
    the reported covariance the same gains give, from the stored ``P_report`` before and after
    each update (the σ the smoother reports)."""
    K = len(hist)
    X = np.array([ep.x for ep in hist])
    Ps = np.array([ep.P for ep in hist])
    Pr = np.array([ep.Pr for ep in hist]) if report else None
    for k in range(K - 2, -1, -1):
        xf, Pf = hist[k].x, hist[k].P
        xp1, Pp1, F1 = hist[k + 1].x_prior, hist[k + 1].P_prior, hist[k + 1].F
        # a state held at zero variance (a switched-off state) gains nothing
        C = np.linalg.solve(Pp1.T + 1e-9 * np.eye(len(Pp1)), (Pf @ F1.T).T).T
        dx = X[k + 1] - xp1
        dx[IH] = (dx[IH] + math.pi) % (2 * math.pi) - math.pi
        X[k] = xf + C @ dx
        Ps[k] = Pf + C @ (Ps[k + 1] - Pp1) @ C.T
        if report:
            Pr[k] = hist[k].Pr + C @ (Pr[k + 1] - hist[k + 1].Pr_prior) @ C.T
    return (X, Ps, Pr) if report else (X, Ps)


def _biased(filt, hist, X, prs, sys_idx_all, keys_all, mix, half: float, k: float):
    """Per input pseudorange: does its satellite's residual on the smoothed track ``X`` keep
    one sign around it? The mean of the residuals (in σ_L) within ±``half`` s against its σ
    under the line-of-sight model, ``√(N/n)`` (N the correlation inflation, n the count), beyond
    ``k``. A smoother may look both ways; a bias the mixture's line-of-sight σ hides shows."""
    M = len(prs.t)
    z = np.full(M, np.nan)
    infl = np.ones(M)
    for kk, h in enumerate(hist):
        idx = h.idx
        hx, _ = filt._model(X[kk], prs.sat_ecef[idx], sys_idx_all[idx])
        z[idx] = (prs.pr[idx] - hx) / mix.sigma_los(prs.cn0[idx])
        infl[idx] = h.inflation
    out = np.zeros(M, bool)
    ok = np.isfinite(z)
    for key in np.unique(keys_all[ok]):
        m = np.flatnonzero(ok & (keys_all == key))
        m = m[np.argsort(prs.t[m], kind="stable")]
        tt, zz = prs.t[m], z[m]
        c = np.r_[0.0, np.cumsum(zz)]
        lo = np.searchsorted(tt, tt - half, side="left")
        hi = np.searchsorted(tt, tt + half, side="right")
        n = hi - lo
        mean = (c[hi] - c[lo]) / n
        out[m] = np.abs(mean) > k * np.sqrt(np.maximum(infl[m], 1.0) / n)
    return out


def _redo(filt: TightOdometryFilter, hist, X, Ps, prs, sys_idx_all, mix, biased=None):
    """The forward pass over stored epochs ``hist`` again, each satellite's component decided
    on the smoothed track ``X, Ps`` instead of the running estimate (never line of sight where
    ``biased``). Returns (new hist, filter)."""
    f = TightOdometryFilter(*filt.init_args)
    new = []
    for k, h in enumerate(hist):
        t, idx, steps, infl = h.t, h.idx, h.steps, h.inflation
        F = np.eye(f.n)
        for v, w, dt in steps:
            F = f.predict(v, w, dt) @ F
        sat, si = prs.sat_ecef[idx], sys_idx_all[idx]
        hx, Hm = f._model(X[k], sat, si)
        e = prs.pr[idx] - hx
        wgt, mu, var = mix.components(prs.cn0[idx])
        tot = var + np.einsum("ij,jk,ik->i", Hm, Ps[k], Hm)[:, None]
        ll = np.log(wgt) - 0.5 * (np.log(tot) + (e[:, None] - mu) ** 2 / tot)
        if biased is not None:
            ll[biased[idx], 0] = -np.inf
        comp = np.argmax(ll, 1)
        xprior, Pprior, Prprior = f.x.copy(), f.P.copy(), f.P_report.copy()
        f.update(prs.pr[idx], sat, si, prs.cn0[idx], mix, components=comp, inflation=infl)
        new.append(Epoch(t, xprior, Pprior, f.x.copy(), f.P.copy(), F, idx, comp, steps,
                    f.P_report.copy(), infl, Prprior))
    return new, f


def _smooth(filt: TightOdometryFilter, prs, sys_idx_all, keys_all, mix, cfg):
    """RTS, then each satellite's component re-decided on the smoothed track and the forward
    pass and RTS redone with those components fixed (``cfg.smooth_passes`` in all)."""
    hist = filt.history
    X, Ps, Pr = _rts(hist, report=True)
    for _ in range(cfg.smooth_passes - 1):
        biased = (_biased(filt, hist, X, prs, sys_idx_all, keys_all, mix, cfg.bias_half_window,
                          cfg.bias_k) if cfg.bias_k > 0 else None)
        hist, _ = _redo(filt, hist, X, Ps, prs, sys_idx_all, mix, biased)
        X, Ps, Pr = _rts(hist, report=True)
    return X, Pr, hist
