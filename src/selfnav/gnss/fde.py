"""Fault detection and exclusion for several faulty satellites at once (one epoch, linearized).

Model of one epoch: ``r = H δx + ε``, ``ε ~ N(0, diag(σ²))`` for the fault-free satellites;
``H`` has position (or velocity) columns and one clock column per system (one-hot). For a
subset ``m`` of the satellites the weighted least-squares solution, its residuals ``v_m`` and
the consistency statistic are::

    δx_m = (Hᵀ W_m H)⁻¹ Hᵀ W_m r,    T_m = Σ_{i∈m} v_i² / σ_i²,    dof_m = |m| − p_m       (1)

(``p_m`` counts the columns the subset observes: a system without a satellite in ``m`` drops
its clock). ``T_m`` is χ²(dof_m) when ``m`` holds no fault. The subset kept is the **largest
consistent subset** (maximum consensus):

1. test all satellites; if ``T ≤ χ²_{1−α}(dof)`` nothing is excluded;
2. otherwise test every subset with ``k = 1, 2, …`` satellites left out, exhaustively while
   the number of subsets stays below ``max_subsets`` (k = 2 for 40 satellites): the first
   ``k`` with a consistent subset wins, and among those the one with the smallest
   ``T / χ²_{1−α}(dof)``. Testing the subsets themselves, not the residuals of the full set,
   is what makes two simultaneous faults separable: the full-set residuals of two faulty
   satellites are smeared over the good ones (masking and swamping), and a one-at-a-time
   test on them (RTKLIB's ``raim_fde``, Baarda's w-test) may exclude a good satellite first;
3. beyond the exhaustive levels, backward elimination from the best subset found: leave out
   the satellite whose removal lowers ``T`` most (largest w-test of the subset), until the
   test passes, at most ``max_exclusions`` (default half the satellites) are out, or no
   redundancy is left;
4. re-admission: an excluded satellite whose residual against the kept solution is within
   the test (``|v_j| / √(σ_j² + h_j P h_jᵀ)`` small) and that keeps the subset consistent is
   taken back (greedy elimination can remove a good satellite);
5. ambiguity: where other subsets of the winning size pass too with a solution beyond 3σ of
   the kept one (two consistent faults among few satellites: which two cannot be told), the
   position covariance is widened by the largest such separation ``d dᵀ`` — the solution is
   kept, its σ covers the alternative.

This is the fault-mode enumeration of solution-separation ARAIM (Blanch et al., "Baseline
advanced RAIM user algorithm and possible improvements", IEEE TAES 51(1), 2015) used for
exclusion, with a χ² (residual) test per subset instead of protection levels, as in
Teunissen's DIA procedure (detection, identification, adaptation) with multiple
alternative hypotheses; compare Knight & Wang (2009), "A comparison of outlier detection
procedures and robust estimation methods in GPS positioning", J. Navigation 62(4).

:class:`VarianceScale` calibrates the a-priori σ causally: the lower quartile of the squared
normalized residuals of the past epochs (all satellites, excluded ones against the kept
solution) divided by the lower quartile of χ²₁ (0.1015) is the variance factor by which the
weights of the next epoch are scaled; biased residuals up to three quarters of the set do not
move it (with the median, a street where a third of the signals are reflected inflated the σ
until the reflections passed the test).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from itertools import combinations
from math import comb

import numpy as np

from selfnav.quantiles import chi2_ppf

MEDIAN_CHI2_1 = 0.454936423119572
#: the quantile of the squared normalized residuals the variance factor is read from, and
#: that quantile of χ²₁: the lower quartile stays consistent with up to 3/4 of the residuals
#: biased (several reflected signals at once in a street)
SCALE_QUANTILE = 0.25
CHI2_1_Q25 = 0.10153104426762142


@dataclass
class EpochFde:
    """Result of :func:`fde_epoch`: ``used`` (n,) bool, ``dx`` (p,), ``P`` (p, p) =
    ``(Hᵀ W H)⁻¹`` of the used set, ``T``, ``dof``, ``passed``, ``residual`` (n,) against
    ``dx`` (all satellites), ``z`` (n,) normalized residuals (w-test of the used ones,
    prediction-normalized for the excluded ones), ``subsets`` tested. ``P`` includes
    ``P_ambiguity`` (see :func:`fde_epoch`)."""

    used: np.ndarray
    dx: np.ndarray
    P: np.ndarray
    T: float
    dof: int
    passed: bool
    residual: np.ndarray
    z: np.ndarray
    subsets: int
    #: (p, p) added to ``P`` by :func:`fde_epoch`: other subsets of the same size passed
    #: the test with solutions far from the kept one (the identification is ambiguous)
    P_ambiguity: np.ndarray | None = None


def _threshold(dof, alpha):
    dof = np.asarray(dof)
    return np.where(dof > 0, chi2_ppf(1.0 - alpha, np.maximum(dof, 1)), np.inf)


def subset_solve(H, r, w, masks, hold=None):
    """Weighted LS (1) for each row of ``masks`` (S, n): ``dx`` (S, p), residuals (S, n),
    ``T`` (S,), ``dof`` (S,), normal matrices (S, p, p). Columns no satellite of a subset
    observes are held (unit diagonal) and not counted in ``dof``; ``hold`` (p,) bool marks
    columns never counted as unknowns of their own (none by default)."""
    masks = np.asarray(masks, bool)
    S, n = masks.shape
    p = H.shape[1]
    Wm = w[None, :] * masks
    N = np.einsum("sn,ni,nj->sij", Wm, H, H)
    present = np.diagonal(N, axis1=1, axis2=2) > 0
    idx = np.arange(p)
    N[:, idx, idx] += ~present
    b = np.einsum("sn,ni,n->si", Wm, H, r)
    try:
        dx = np.linalg.solve(N, b[..., None])[..., 0]
    except np.linalg.LinAlgError:
        dx = np.einsum("sij,sj->si", np.linalg.pinv(N), b)
    v = r[None, :] - dx @ H.T
    T = np.sum(Wm * v * v, axis=1)
    dof = masks.sum(1) - present.sum(1)
    return dx, v, T, dof, N


def fde_epoch(H, r, var, *, alpha: float = 1e-3, max_exclusions: int | None = None,
              min_dof: int = 1, max_subsets: int = 1000, readmit: bool = True) -> EpochFde:
    """Largest consistent subset of one epoch (module docstring, steps 1–4).

    Parameters
    ----------
    H : (n, p) design matrix at the linearization point
    r : (n,) observed minus predicted
    var : (n,) variances (already scaled by any variance factor)
    alpha : false-alarm probability of each χ² test
    max_exclusions : at most this many satellites left out (default ``n // 2``)
    min_dof : redundancy a kept subset must have (1: it can still be tested)
    max_subsets : exhaustive search while C(n, k) stays below this
    """
    H = np.asarray(H, float)
    r = np.asarray(r, float)
    w = 1.0 / np.asarray(var, float)
    n = len(r)
    kmax = n // 2 if max_exclusions is None else min(max_exclusions, n)
    tested = 1
    full = np.ones((1, n), bool)
    dx, v, T, dof, N = subset_solve(H, r, w, full)
    thr = _threshold(dof, alpha)
    best_mask = full[0]
    ok = (T <= thr) | (dof < 1)
    alternatives = None
    if not ok[0] and kmax > 0:
        found = None
        cand_mask, cand_ratio = full[0], T[0] / thr[0]
        pen = chi2_ppf(1.0 - alpha, 1)          # what one more exclusion must buy
        best_score = np.inf
        k = 0
        for k in range(1, kmax + 1):
            if comb(n, k) > max_subsets:
                k -= 1
                break
            excl = np.array(list(combinations(range(n), k)))
            masks = np.ones((len(excl), n), bool)
            masks[np.arange(len(excl))[:, None], excl] = False
            dxs, vs, Ts, dofs, _ = subset_solve(H, r, w, masks)
            tested += len(masks)
            valid = dofs >= min_dof
            if not valid.any():
                break
            ratio = np.where(valid, Ts / _threshold(dofs, alpha), np.inf)
            j = int(np.argmin(ratio))
            cand_mask, cand_ratio = masks[j], ratio[j]
            if found is not None:
                # one more exclusion only if it lowers T by more than a single-satellite test
                if Ts[j] + pen * k < best_score and ratio[j] <= 1.0:
                    found, best_score = masks[j], Ts[j] + pen * k
                    alternatives = dxs[(ratio <= 1.0)]
                    continue
                break
            if ratio[j] <= 1.0:
                found, best_score = masks[j], Ts[j] + pen * k
                alternatives = dxs[(ratio <= 1.0)]
        if found is None:
            # backward elimination from the best subset of the last exhaustive level
            m = cand_mask.copy()
            while m.sum() - (n - kmax) > 0 and cand_ratio > 1.0:
                idx_in = np.flatnonzero(m)
                masks = np.repeat(m[None], len(idx_in), 0)
                masks[np.arange(len(idx_in)), idx_in] = False
                dxs, vs, Ts, dofs, _ = subset_solve(H, r, w, masks)
                tested += len(masks)
                valid = dofs >= min_dof
                if not valid.any():
                    break
                ratio = np.where(valid, Ts / _threshold(dofs, alpha), np.inf)
                j = int(np.argmin(ratio))
                m, cand_ratio = masks[j], ratio[j]
            found = m
        best_mask = found
        if readmit and not best_mask.all():
            best_mask, extra = _readmit(H, r, w, best_mask, alpha)
            tested += extra
        dx, v, T, dof, N = subset_solve(H, r, w, best_mask[None])
        thr = _threshold(dof, alpha)
    try:
        P = np.linalg.inv(N[0])
    except np.linalg.LinAlgError:
        P = np.linalg.pinv(N[0])
    res = v[0]
    q = np.einsum("ni,ij,nj->n", H, P, H)
    var = 1.0 / w
    qv = np.where(best_mask, var - q, var + q)
    z = np.where(qv > 1e-9 * var, res / np.sqrt(np.maximum(qv, 1e-300)), np.nan)
    P_amb = None
    if alternatives is not None and len(alternatives) > 1:
        # solution separation among the consistent subsets of the winning size: if another
        # passes with a solution beyond the kept one's 3σ, the σ must cover it
        d = alternatives[:, :3] - dx[0, :3]
        Pi = np.linalg.pinv(P[:3, :3])
        m = np.einsum("ki,ij,kj->k", d, Pi, d)
        j = int(np.argmax(m))
        if m[j] > 9.0:
            P_amb = np.zeros_like(P)
            P_amb[:3, :3] = np.outer(d[j], d[j])
            P = P + P_amb
    return EpochFde(best_mask, dx[0], P, float(T[0]), int(dof[0]),
                    bool(T[0] <= thr[0] or dof[0] < 1), res, z, tested, P_amb)


def _readmit(H, r, w, mask, alpha):
    """Step 4: take back excluded satellites, the most consistent first, while the subset
    stays consistent."""
    tested = 0
    m = mask.copy()
    while True:
        out = np.flatnonzero(~m)
        if out.size == 0:
            break
        masks = np.repeat(m[None], len(out), 0)
        masks[np.arange(len(out)), out] = True
        _, _, Ts, dofs, _ = subset_solve(H, r, w, masks)
        tested += len(out)
        ratio = Ts / _threshold(dofs, alpha)
        j = int(np.argmin(ratio))
        if ratio[j] > 1.0:
            break
        m = masks[j]
    return m, tested


class VarianceScale:
    """Causal variance factor of the a-priori σ (module docstring): the lower quartile of the
    squared normalized residuals of the last ``window`` residuals, over that of χ²₁, clipped to
    ``[lo, hi]``. Until ``min_count`` residuals are in, the current epoch's own normalized
    residuals (``current``) join them; with none at all, ``1``."""

    def __init__(self, window: int = 600, min_count: int = 30, lo: float = 1e-4, hi: float = 1e4):
        self.buf = deque(maxlen=window)
        self.min_count = min_count
        self.lo, self.hi = lo, hi

    def value(self, current=None) -> float:
        data = list(self.buf)
        if len(data) < self.min_count and current is not None:
            c = np.asarray(current, float)
            data += (c[np.isfinite(c)] ** 2).tolist()
        if not data:
            return 1.0
        return float(np.clip(np.quantile(data, SCALE_QUANTILE) / CHI2_1_Q25, self.lo, self.hi))

    def add(self, z) -> None:
        z = np.asarray(z, float)
        self.buf.extend((z[np.isfinite(z)] ** 2).tolist())
