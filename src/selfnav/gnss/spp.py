"""Single-point positioning (SPP) from pseudoranges by iterative weighted least squares, with
RAIM-style fault detection and exclusion (DESIGN §7 "Outliers", §8 smartLoc).

Observation model of satellite ``i`` of system ``s(i)`` at one epoch (the satellite clock and the
atmosphere already removed, as in the smartLoc files)::

    ρ_i = |R_3(Ω τ_i) r^s_i − r| + c·δt_{s(i)} + ε_i,     τ_i = |r^s_i − r| / c          (1)

``r^s_i`` is the satellite's ECEF position at transmit time; ``R_3(Ω τ)`` rotates it into the
ECEF frame of the reception time (the Sagnac or Earth-rotation correction, up to ~30 m of range and
tens of metres of position at mid-latitudes if ignored). Each constellation (GPS, GLONASS,
Galileo, …) has its own receiver clock term ``c·δt_s`` in metres: the inter-system biases are
estimated, not assumed.

Gauss–Newton on (1), unknowns ``x = (r, c·δt_1 … c·δt_K)``::

    H_i = [−u_iᵀ, e_{s(i)}ᵀ],  u_i = (R_3 r^s_i − r)/|R_3 r^s_i − r|                     (2)
    δx = (Hᵀ W H)⁻¹ Hᵀ W (ρ − ρ̂(x)),   W = diag(1/σ_i²)                                  (3)

Weights from the given variance (default), an elevation model ``σ² = σ0²/sin²E``, a C/N0 model
``σ² = σ0² · 10^{(C0 − C/N0)/10}``, or equal weights.

**Fault detection and exclusion.** With the weighted residuals ``v`` the test statistic
``T = vᵀ W v`` is χ²-distributed with ``n − 3 − K_used`` degrees of freedom when the model holds;
``T > χ²_{1−α}`` flags the epoch. While the test fails and at least two degrees of freedom remain,
the satellite with the largest normalized residual (Baarda's w-test)::

    w_i = |v_i| / √(Q_vv)_ii,     Q_vv = W⁻¹ − H (Hᵀ W H)⁻¹ Hᵀ                           (4)

is excluded and the epoch re-solved. A satellite that is alone in its system has ``(Q_vv)_ii = 0``
(its own clock absorbs it) and is never chosen. All epochs are solved together (padded arrays,
batched ``numpy.linalg.solve``); each exclusion round touches only the epochs still failing.

References: Kaplan & Hegarty, *Understanding GPS/GNSS* (3rd ed.), ch. 11 (SPP, Sagnac);
Baarda (1968) data snooping; Teunissen, *Testing theory*.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from selfnav.earth import OMEGA_EARTH, WGS84, ecef_to_geodetic, enu_rotation
from selfnav.errors import SelfnavError
from selfnav.gnss.fde import VarianceScale, fde_epoch
from selfnav.quantiles import chi2_ppf
from selfnav.types import GnssData

C_LIGHT = 299_792_458.0


@dataclass
class SppConfig:
    """Options of :func:`solve_spp`.

    Attributes
    ----------
    weighting : {"variance", "elevation", "cn0", "equal"}
    sigma0 : float
        Zenith / reference σ of the elevation and C/N0 models, m.
    cn0_ref : float
        C/N0 at which the C/N0 model gives ``sigma0``, dBHz.
    variance_scale : float
        Multiplies every variance (the χ² test uses the scaled values).
    sagnac : bool
        Apply the Earth-rotation correction of (1).
    raim : bool
        Fault detection and exclusion.
    alpha : float
        False-alarm probability of the global χ² test.
    max_exclusions : int
        At most this many satellites excluded per epoch.
    min_elevation : float
        Satellites below this elevation (rad) are not used.
    max_iter, tol : Gauss–Newton limits (tol in metres).
    fde : {"w-test", "subset", "none"}
        Exclusion method when ``raim``: ``"w-test"`` the one-at-a-time Baarda exclusion of the
        module docstring, ``"subset"`` the largest consistent subset of
        :func:`selfnav.gnss.fde.fde_epoch` (several faults at once).
    adaptive_sigma : bool
        Scale the variances by the causal variance factor of
        :class:`selfnav.gnss.fde.VarianceScale` (epochs in time order) before testing.
    max_subsets : int
        Exhaustive subset search while C(n, k) stays below this (``fde="subset"``).
    """

    weighting: str = "variance"
    sigma0: float = 5.0
    cn0_ref: float = 45.0
    variance_scale: float = 1.0
    sagnac: bool = True
    raim: bool = True
    alpha: float = 1e-3
    max_exclusions: int = 8
    min_elevation: float = 0.0
    max_iter: int = 12
    tol: float = 1e-4
    fde: str = "w-test"
    adaptive_sigma: bool = False
    max_subsets: int = 1000


@dataclass
class SppResult:
    """Per-epoch SPP solutions (arrays of length E) and per-observation bookkeeping (length M).

    ``sigma_enu`` comes from the LS covariance ``(Hᵀ W H)⁻¹`` with the a-priori weights;
    ``sigma_m`` is its horizontal σ per axis ``√((σ_E² + σ_N²)/2)``. Epochs without enough
    satellites have NaN position. ``test_stat`` is ``vᵀ W v`` after exclusion, ``dof`` its
    degrees of freedom, ``passed`` the χ² verdict (True when dof = 0: nothing to test).
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    ecef: np.ndarray
    clock: np.ndarray            # (E, K) receiver clock per system, m (NaN: system not used)
    systems: np.ndarray          # (K,) system codes, the columns of ``clock``
    sigma_enu: np.ndarray
    sigma_m: np.ndarray
    n_sats: np.ndarray
    n_used: np.ndarray
    n_excluded: np.ndarray
    test_stat: np.ndarray
    dof: np.ndarray
    passed: np.ndarray
    obs_epoch: np.ndarray        # (M,) epoch index of each observation
    obs_used: np.ndarray         # (M,) bool
    obs_residual: np.ndarray     # (M,) m, NaN where the epoch has no solution
    stats: dict = field(default_factory=dict)
    sigma_scale: np.ndarray | None = None   # (E,) σ factor applied to the a-priori σ

    @property
    def variance_factor(self) -> np.ndarray:
        """A-posteriori variance factor ``T / dof`` (NaN where dof = 0); multiply the variances
        behind ``sigma_enu`` by it for a covariance scaled to the observed residuals."""
        return np.where(self.dof > 0, self.test_stat / np.maximum(self.dof, 1), np.nan)

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.lat)

    def to_gnss(self, *, only_valid: bool = True) -> GnssData:
        """The fixes as :class:`selfnav.io.gnss.GnssData` (quality 5 = single)."""
        m = self.valid if only_valid else np.ones(len(self.t), bool)
        return GnssData(self.t[m], self.lat[m], self.lon[m], self.h[m], self.sigma_m[m],
                        None, np.full(int(m.sum()), 5), "selfnav spp")


def observation_variance(var, elevation, cn0, cfg: SppConfig):
    """Pseudorange variances (m²) under the configured weighting model (see module docstring)."""
    w = cfg.weighting.lower()
    if w == "variance":
        v = np.asarray(var, dtype=float)
    elif w == "elevation":
        v = cfg.sigma0**2 / np.maximum(np.sin(elevation), 0.05) ** 2
    elif w == "cn0":
        v = cfg.sigma0**2 * 10.0 ** ((cfg.cn0_ref - np.asarray(cn0, float)) / 10.0)
    elif w == "equal":
        v = np.full(np.shape(var), cfg.sigma0**2)
    else:
        raise SelfnavError(f"unknown weighting '{cfg.weighting}' (variance, elevation, cn0, equal)")
    return v * cfg.variance_scale


def sagnac_rotate(sat_ecef, rx_ecef):
    """Satellite positions rotated by ``Ω τ`` about ECEF z into the reception-time frame, (1)."""
    rho = np.linalg.norm(sat_ecef - rx_ecef, axis=-1)
    th = OMEGA_EARTH * rho / C_LIGHT
    c, s = np.cos(th), np.sin(th)
    out = np.empty_like(sat_ecef)
    out[..., 0] = c * sat_ecef[..., 0] + s * sat_ecef[..., 1]
    out[..., 1] = -s * sat_ecef[..., 0] + c * sat_ecef[..., 1]
    out[..., 2] = sat_ecef[..., 2]
    return out


def _pad(epoch, n_epochs, *arrays):
    """Scatter per-observation arrays into (E, S, …) padded arrays; returns (mask, slot, padded)."""
    counts = np.bincount(epoch, minlength=n_epochs)
    S = int(counts.max()) if counts.size else 0
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(len(epoch)) - start[epoch]
    mask = np.zeros((n_epochs, S), bool)
    mask[epoch, slot] = True
    out = []
    for a in arrays:
        p = np.zeros((n_epochs, S) + a.shape[1:], dtype=a.dtype)
        p[epoch, slot] = a
        out.append(p)
    return mask, slot, out


def _model(x, sat, sys_col, K, sagnac):
    """Predicted pseudoranges and design matrix (2) for state x (E, 3+K)."""
    pos = x[:, None, :3]
    s = sagnac_rotate(sat, pos) if sagnac else sat
    d = s - pos
    rho = np.linalg.norm(d, axis=-1)
    u = d / rho[..., None]
    onehot = (sys_col[..., None] == np.arange(K)).astype(float)
    clk = np.take_along_axis(x[:, 3:], sys_col, axis=1)
    H = np.concatenate([-u, onehot], axis=-1)
    return rho + clk, H


def _solve_batched(N, b):
    """``N⁻¹ b`` per epoch; the pseudo-inverse if some epoch's geometry is degenerate."""
    try:
        return np.linalg.solve(N, b[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return np.einsum("eij,ej->ei", np.linalg.pinv(N), b)


def _normal_equations(x, pr, w, sat, sys_col, K, sagnac, eye):
    """Residuals, design matrix, normal matrix and right-hand side of (3) at ``x``.

    Clocks of systems with no used satellite are held fixed (unit diagonal, zero right side).
    """
    pred, H = _model(x, sat, sys_col, K, sagnac)
    r = pr - pred
    HW = H * w[..., None]
    N = np.einsum("esi,esj->eij", HW, H)
    absent = np.diagonal(N, axis1=1, axis2=2)[:, 3:] == 0
    N[:, 3:, 3:] += absent[:, :, None] * eye[3:, 3:][None]
    return r, H, N, np.einsum("esi,es->ei", HW, r), absent


def _wls(x, pr, w, sat, sys_col, K, sagnac, max_iter, tol):
    """Gauss–Newton iterations of (3) for all epochs at once; w = 0 for unused observations."""
    eye = np.eye(3 + K)
    for _ in range(max_iter):
        _, _, N, b, _ = _normal_equations(x, pr, w, sat, sys_col, K, sagnac, eye)
        dx = _solve_batched(N, b)
        x = x + dx
        if np.max(np.abs(dx[:, :3])) < tol:
            break
    r, H, N, _, absent = _normal_equations(x, pr, w, sat, sys_col, K, sagnac, eye)
    try:
        Ninv = np.linalg.inv(N)
    except np.linalg.LinAlgError:      # a degenerate geometry somewhere: pseudo-inverse there
        Ninv = np.linalg.pinv(N)
    return x, r, H, Ninv, absent


def solve_spp(t, pr, var, sat_ecef, system, elevation=None, cn0=None,
              cfg: SppConfig | None = None) -> SppResult:
    """Single-point positions of every epoch (observations grouped by equal ``t``).

    Parameters
    ----------
    t : (M,) s, observation epochs (any order)
    pr : (M,) m, pseudoranges (satellite clock and atmosphere removed)
    var : (M,) m², a-priori variances (used by ``weighting="variance"``)
    sat_ecef : (M, 3) m, satellite positions at transmit time
    system : (M,) int, constellation codes; one receiver clock per distinct code
    elevation : (M,) rad, optional (elevation weighting, elevation mask)
    cn0 : (M,) dBHz, optional (C/N0 weighting)
    cfg : SppConfig

    Returns
    -------
    SppResult
    """
    cfg = cfg or SppConfig()
    t = np.asarray(t, float)
    pr = np.asarray(pr, float)
    M = len(t)
    sat_ecef = np.asarray(sat_ecef, float).reshape(M, 3)
    system = np.asarray(system)
    elevation = np.full(M, np.pi / 2) if elevation is None else np.asarray(elevation, float)
    cn0 = np.full(M, cfg.cn0_ref) if cn0 is None else np.asarray(cn0, float)
    var = np.full(M, cfg.sigma0**2) if var is None else np.asarray(var, float)
    v_obs = observation_variance(var, elevation, cn0, cfg)

    order = np.argsort(t, kind="stable")
    t_ep, epoch_sorted = np.unique(t[order], return_inverse=True)
    E = len(t_ep)
    systems, sys_idx = np.unique(system, return_inverse=True)
    K = len(systems)
    mask, slot, (prp, vp, satp, sysp, elp) = _pad(
        epoch_sorted, E, pr[order], v_obs[order], sat_ecef[order], sys_idx[order].astype(int),
        elevation[order])
    use = mask & (elp >= cfg.min_elevation)
    n_sats = use.sum(1)

    # initial guess: on the Earth's surface below the mean line of sight
    ms = (satp * mask[..., None]).sum(1) / np.maximum(mask.sum(1), 1)[:, None]
    x = np.zeros((E, 3 + K))
    x[:, :3] = WGS84.a * ms / np.maximum(np.linalg.norm(ms, axis=1), 1.0)[:, None]

    def solve(x, use, idx):
        w = np.divide(1.0, vp[idx], out=np.zeros_like(vp[idx]), where=use[idx])
        return _wls(x[idx], prp[idx], w, satp[idx], sysp[idx], K, cfg.sagnac, cfg.max_iter, cfg.tol), w

    def clocks_used(u, idx):
        onehot = sysp[idx][..., None] == np.arange(K)
        return np.any(onehot & u[..., None], axis=1).sum(1)

    def statistic(r, w, u, idx):
        T = np.sum(w * r * r, axis=1)
        dof = u.sum(1) - 3 - clocks_used(u, idx)
        return T, dof

    if cfg.raim and cfg.fde == "subset":
        return _solve_subset(t_ep, order, epoch_sorted, slot, mask, use, prp, vp, satp, sysp,
                             systems, x, cfg, M)
    all_idx = np.arange(E)
    dof = use.sum(1) - 3 - clocks_used(use, all_idx)
    ok_idx = np.flatnonzero(dof >= 0)          # enough satellites for the unknowns
    n = 3 + K
    r = np.zeros(use.shape)
    H = np.zeros(use.shape + (n,))
    Ninv = np.full((E, n, n), np.nan)
    T = np.full(E, np.nan)
    n_excl = np.zeros(E, int)
    if ok_idx.size:
        (x[ok_idx], r[ok_idx], H[ok_idx], Ninv[ok_idx], _), w0 = solve(x, use, ok_idx)
        T[ok_idx], dof[ok_idx] = statistic(r[ok_idx], w0, use[ok_idx], ok_idx)
    rounds = 0
    if cfg.raim and cfg.fde != "none":
        while rounds < cfg.max_exclusions:
            thr = np.where(dof > 0, chi2_ppf(1.0 - cfg.alpha, np.maximum(dof, 1)), np.inf)
            fail = np.flatnonzero((T > thr) & (dof >= 2))
            if fail.size == 0:
                break
            u = use[fail]
            Hf = H[fail]
            Qh = np.einsum("esi,eij,esj->es", Hf, Ninv[fail], Hf)
            qvv = np.where(u, vp[fail] - Qh, 0.0)
            wtest = np.where(qvv > 1e-6 * vp[fail], np.abs(r[fail]) / np.sqrt(np.maximum(qvv, 1e-300)), -1.0)
            wtest[~u] = -1.0
            worst = np.argmax(wtest, axis=1)
            ok = wtest[np.arange(len(fail)), worst] > 0
            fail, worst = fail[ok], worst[ok]
            if fail.size == 0:
                break
            use[fail, worst] = False
            n_excl[fail] += 1
            (xf, rf, Hf, Nf, _), wf = solve(x, use, fail)
            x[fail], r[fail], H[fail], Ninv[fail] = xf, rf, Hf, Nf
            Tf, dff = statistic(rf, wf, use[fail], fail)
            T[fail], dof[fail] = Tf, dff
            rounds += 1
    thr = np.where(dof > 0, chi2_ppf(1.0 - cfg.alpha, np.maximum(dof, 1)), np.inf)
    passed = T <= thr
    n_used = use.sum(1)
    solvable = dof >= 0
    # a Gauss–Newton run that did not converge to the Earth's surface is no fix
    with np.errstate(invalid="ignore"):
        solvable &= np.abs(np.linalg.norm(x[:, :3], axis=1) - WGS84.a) < 1e5
    pos = np.where(solvable[:, None], x[:, :3], np.nan)
    lat, lon, h = ecef_to_geodetic(pos)
    # covariance to ENU: C_e^n P C_e^nᵀ per epoch
    Cen = enu_rotation(np.atleast_1d(lat), np.atleast_1d(lon))
    P_enu = np.einsum("eij,ejk,elk->eil", Cen, Ninv[:, :3, :3], Cen)
    sig = np.sqrt(np.maximum(np.diagonal(P_enu, axis1=1, axis2=2), 0.0))
    sig[~solvable] = np.nan
    sig_m = np.sqrt(0.5 * (sig[:, 0] ** 2 + sig[:, 1] ** 2))
    present = np.any((sysp[..., None] == np.arange(K)) & use[..., None], axis=1)
    clock = np.where(solvable[:, None] & present, x[:, 3:], np.nan)
    # per-observation outputs in the caller's order
    obs_epoch = np.empty(M, int)
    obs_epoch[order] = epoch_sorted
    obs_used = np.empty(M, bool)
    obs_used[order] = use[epoch_sorted, slot]
    obs_res = np.empty(M)
    obs_res[order] = np.where(solvable[epoch_sorted], r[epoch_sorted, slot], np.nan)
    stats = {"epochs": E, "solved": int(solvable.sum()), "excluded": int(n_excl.sum()),
             "epochs_with_exclusion": int((n_excl > 0).sum()), "passed": int(passed[solvable].sum()),
             "exclusion_rounds": rounds}
    return SppResult(t_ep, lat, lon, h, pos, clock, systems, sig, sig_m, n_sats, n_used, n_excl,
                     T, dof, passed, obs_epoch, obs_used, obs_res, stats)


def _solve_subset(t_ep, order, epoch_sorted, slot, mask, use, prp, vp, satp, sysp, systems, x,
                  cfg, M):
    """``fde="subset"``: epochs in time order, largest consistent subset per epoch
    (:func:`selfnav.gnss.fde.fde_epoch`), variances scaled by the causal variance factor."""
    E, S = use.shape
    K = len(systems)
    n = 3 + K
    use0 = use.copy()
    dof0 = use.sum(1) - 3 - np.any((sysp[..., None] == np.arange(K)) & use[..., None], 1).sum(1)
    solv = np.flatnonzero(dof0 >= 0)
    if solv.size:     # all-satellite solution: the linearization point of every epoch
        w = np.divide(1.0, vp[solv], out=np.zeros_like(vp[solv]), where=use[solv])
        x[solv] = _wls(x[solv], prp[solv], w, satp[solv], sysp[solv], K, cfg.sagnac,
                       cfg.max_iter, cfg.tol)[0]
    scale = VarianceScale()
    s2 = np.ones(E)
    eye = np.eye(n)
    subsets = 0
    P_amb = np.zeros((E, 3, 3))
    for e in solv:
        u = np.flatnonzero(use[e])
        xe = x[e:e + 1].copy()
        s2[e] = scale.value()
        for _ in range(3):
            r, H, _, _, _ = _normal_equations(xe, prp[e:e + 1], np.ones((1, S)), satp[e:e + 1],
                                              sysp[e:e + 1], K, cfg.sagnac, eye)
            if cfg.adaptive_sigma and len(scale.buf) < scale.min_count:
                # the epoch's own all-satellite residuals start the factor
                f0 = fde_epoch(H[0, u], r[0, u], vp[e, u], alpha=cfg.alpha, max_exclusions=0)
                s2[e] = scale.value(f0.z)
            ve = vp[e, u] * (s2[e] if cfg.adaptive_sigma else 1.0)
            f = fde_epoch(H[0, u], r[0, u], ve, alpha=cfg.alpha,
                          max_exclusions=min(cfg.max_exclusions, len(u) // 2),
                          max_subsets=cfg.max_subsets)
            subsets += f.subsets
            xe[0] += f.dx
            if np.linalg.norm(f.dx[:3]) < 10.0:
                break
        use[e, u[~f.used]] = False
        if f.P_ambiguity is not None:
            P_amb[e] = f.P_ambiguity[:3, :3]
        if cfg.adaptive_sigma:
            scale.add(f.z * np.sqrt(s2[e]))
        else:
            s2[e] = 1.0
    # final Gauss–Newton of the kept subsets, with the scaled variances
    vs = vp * s2[:, None]
    r = np.zeros(use.shape)
    Ninv = np.full((E, n, n), np.nan)
    T = np.full(E, np.nan)
    dof = np.full(E, -1)
    if solv.size:
        w = np.divide(1.0, vs[solv], out=np.zeros_like(vs[solv]), where=use[solv])
        xs, rs, _, Ns, _ = _wls(x[solv], prp[solv], w, satp[solv], sysp[solv], K, cfg.sagnac,
                                cfg.max_iter, cfg.tol)
        x[solv], r[solv], Ninv[solv] = xs, rs, Ns
        T[solv] = np.sum(w * rs * rs, axis=1)
        cu = np.any((sysp[solv][..., None] == np.arange(K)) & use[solv][..., None], 1).sum(1)
        dof[solv] = use[solv].sum(1) - 3 - cu
    thr = np.where(dof > 0, chi2_ppf(1.0 - cfg.alpha, np.maximum(dof, 1)), np.inf)
    passed = T <= thr
    # a failed test means the σ model is too optimistic there: inflate by the variance factor
    infl = np.where(~passed & (dof > 0), T / np.maximum(dof, 1), 1.0)
    Ninv = Ninv * infl[:, None, None]
    Ninv[:, :3, :3] += P_amb
    n_excl = use0.sum(1) - use.sum(1)
    return _assemble(t_ep, order, epoch_sorted, slot, use, r, x, Ninv, T, dof, passed, n_excl,
                     sysp, systems, dof >= 0, M,
                     {"exclusion_rounds": 0, "subsets_tested": int(subsets),
                      "ambiguous_epochs": int(np.any(P_amb != 0, axis=(1, 2)).sum()),
                      "sigma_scale_median": float(np.sqrt(np.median(s2[solv]))) if solv.size
                      else float("nan")}, np.sqrt(s2))


def _assemble(t_ep, order, epoch_sorted, slot, use, r, x, Ninv, T, dof, passed, n_excl, sysp,
              systems, solvable, M, extra, sigma_scale=None):
    """SppResult from the padded per-epoch arrays (shared by both exclusion methods)."""
    K = len(systems)
    n_used = use.sum(1)
    n_sats = n_used + n_excl
    with np.errstate(invalid="ignore"):
        solvable = solvable & (np.abs(np.linalg.norm(x[:, :3], axis=1) - WGS84.a) < 1e5)
    pos = np.where(solvable[:, None], x[:, :3], np.nan)
    lat, lon, h = ecef_to_geodetic(pos)
    Cen = enu_rotation(np.atleast_1d(lat), np.atleast_1d(lon))
    P_enu = np.einsum("eij,ejk,elk->eil", Cen, Ninv[:, :3, :3], Cen)
    sig = np.sqrt(np.maximum(np.diagonal(P_enu, axis1=1, axis2=2), 0.0))
    sig[~solvable] = np.nan
    sig_m = np.sqrt(0.5 * (sig[:, 0] ** 2 + sig[:, 1] ** 2))
    present = np.any((sysp[..., None] == np.arange(K)) & use[..., None], axis=1)
    clock = np.where(solvable[:, None] & present, x[:, 3:], np.nan)
    obs_epoch = np.empty(M, int)
    obs_epoch[order] = epoch_sorted
    obs_used = np.empty(M, bool)
    obs_used[order] = use[epoch_sorted, slot]
    obs_res = np.empty(M)
    obs_res[order] = np.where(solvable[epoch_sorted], r[epoch_sorted, slot], np.nan)
    stats = {"epochs": len(t_ep), "solved": int(solvable.sum()), "excluded": int(n_excl.sum()),
             "epochs_with_exclusion": int((n_excl > 0).sum()),
             "passed": int(passed[solvable].sum()), **extra}
    return SppResult(t_ep, lat, lon, h, pos, clock, systems, sig, sig_m, n_sats, n_used, n_excl,
                     T, dof, passed, obs_epoch, obs_used, obs_res, stats, sigma_scale)


def spp_from_pseudoranges(prs, cfg: SppConfig | None = None) -> SppResult:
    """:func:`solve_spp` on a :class:`selfnav.io.smartloc.Pseudoranges`."""
    return solve_spp(prs.t, prs.pr, prs.var, prs.sat_ecef, prs.system, prs.elevation, prs.cn0, cfg)


def horizontal_error(result: SppResult, t_truth, ecef_truth):
    """Horizontal error (m) of each epoch against truth at the same times (interpolated)."""
    tr = np.column_stack([np.interp(result.t, t_truth, ecef_truth[:, i]) for i in range(3)])
    d = result.ecef - tr
    lat, lon, _ = ecef_to_geodetic(tr)
    e = np.einsum("eij,ej->ei", enu_rotation(np.atleast_1d(lat), np.atleast_1d(lon)), d)
    return np.hypot(e[:, 0], e[:, 1])
