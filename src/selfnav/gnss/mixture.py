"""The pseudorange error model of the tightly coupled filter (:mod:`selfnav.gnss.tight`, (2)):
a mixture of line-of-sight and delayed errors fitted on the fly, and the correlation of a
satellite's residuals from epoch to epoch.

Line of sight: N(0, σ_L²), σ_L = σ_L45 · 10^((45 − C/N0)/20) (the code noise's C/N0 law);
delayed (multipath, reflections): N(μ_k, σ_k²), positive means; each component's share per
C/N0 band. :meth:`MixtureModel.fit` is expectation-maximisation over post-fit residuals.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from selfnav.correlation import ar1_variance_factor

_CN0_EDGES = np.array([25.0, 30.0, 35.0, 40.0, 45.0])       # C/N0 bands (dBHz)


@dataclass
class MixtureModel:
    """Pseudorange error model (2): component 0 is the line of sight (mean 0, σ_L45 at 45 dBHz,
    scaled with C/N0), components 1… are delayed signals (multipath, reflections; mean and σ
    each); ``weights`` (6, K) the components' shares per C/N0 band (below 25, 25–30, …, 45 and
    above)."""

    sigma_los45: float = 3.0
    means: np.ndarray = field(default_factory=lambda: np.array([8.0, 40.0]))
    sigmas: np.ndarray = field(default_factory=lambda: np.array([6.0, 40.0]))
    weights: np.ndarray = field(default_factory=lambda: np.array(
        [[0.2, 0.3, 0.5], [0.3, 0.3, 0.4], [0.4, 0.3, 0.3], [0.5, 0.3, 0.2], [0.7, 0.2, 0.1],
         [0.9, 0.07, 0.03]]))
    sigma_los_min: float = 1.0
    sigma_los_max: float = 60.0
    #: the least line-of-sight σ at 45 dBHz the fit may reach, m
    sigma_los45_min: float = 0.5

    def copy(self):
        return MixtureModel(self.sigma_los45, self.means.copy(), self.sigmas.copy(),
                            self.weights.copy(), self.sigma_los_min, self.sigma_los_max,
                            self.sigma_los45_min)

    def sigma_los(self, cn0):
        s = self.sigma_los45 * 10.0 ** ((45.0 - np.asarray(cn0, float)) / 20.0)
        return np.clip(s, self.sigma_los_min, self.sigma_los_max)

    def components(self, cn0):
        """(weights, means, variances), each (n, K): column 0 line of sight, 1… delayed."""
        cn0 = np.asarray(cn0, float)
        w = np.clip(self.weights[np.searchsorted(_CN0_EDGES, cn0, side="right")], 1e-3, 1.0)
        sl = self.sigma_los(cn0)
        n = len(sl)
        mu = np.column_stack([np.zeros(n)] + [np.full(n, m) for m in self.means])
        var = np.column_stack([sl * sl] + [np.full(n, s * s) for s in self.sigmas])
        return w, mu, var

    def fit(self, e, cn0, iters: int = 8, prior_count: float = 20.0):
        """EM on post-fit residuals ``e`` (m) with their C/N0: updates the model in place.
        ``prior_count`` pseudo-observations per band keep a sparse band's shares near theirs."""
        e = np.asarray(e, float)
        cn0 = np.asarray(cn0, float)
        if e.size < 50:
            return self
        band = np.searchsorted(_CN0_EDGES, cn0, side="right")
        scale = 10.0 ** ((45.0 - cn0) / 20.0)
        w0 = self.weights.copy()
        K = w0.shape[1]
        for _ in range(iters):
            w, mu, var = self.components(cn0)
            ll = np.log(w) - 0.5 * (np.log(var) + (e[:, None] - mu) ** 2 / var)
            ll -= ll.max(1, keepdims=True)
            g = np.exp(ll)
            g /= g.sum(1, keepdims=True)
            s2 = np.sum(g[:, 0] * (e / scale) ** 2) / max(np.sum(g[:, 0]), 1e-9)
            self.sigma_los45 = float(np.clip(np.sqrt(s2), self.sigma_los45_min, 15.0))
            lo = 0.0
            for k in range(1, K):
                nk = max(np.sum(g[:, k]), 1e-9)
                m = float(np.clip(np.sum(g[:, k] * e) / nk, lo + 1.0, 300.0))
                self.means[k - 1] = m
                self.sigmas[k - 1] = float(np.clip(np.sqrt(np.sum(g[:, k] * (e - m) ** 2) / nk),
                                                   2.0, 300.0))
                lo = m
            cnt = np.bincount(band, minlength=6).astype(float)[:, None]
            got = np.column_stack([np.bincount(band, weights=g[:, k], minlength=6)
                                   for k in range(K)])
            self.weights = (got + prior_count * w0) / (cnt + prior_count)
        return self


class ResidualCorrelation:
    """Lag-one correlation ρ of each satellite's line-of-sight residuals between consecutive
    epochs (scaled by σ_L, pooled over satellites, forgotten with time constant ``window``), and
    the variance inflation ``(1 + ρ)/(1 − ρ)`` of averaging an AR(1) series: what the filter's
    white-noise covariance misses when it averages correlated errors."""

    def __init__(self, window: float, max_gap: float, max_inflation: float = 100.0):
        self.window, self.max_gap, self.max_inflation = window, max_gap, max_inflation
        self.last = {}
        self.sxy = self.sxx = self.syy = 0.0
        self.t = None
        self.inflation = 1.0

    def add(self, t, keys, z, los):
        if self.t is not None:
            f = math.exp(-(t - self.t) / self.window)
            self.sxy *= f
            self.sxx *= f
            self.syy *= f
        self.t = t
        for k, v, ok in zip(keys.tolist(), z.tolist(), los.tolist()):
            prev = self.last.get(k)
            if ok and prev is not None and t - prev[0] <= self.max_gap:
                self.sxy += prev[1] * v
                self.sxx += prev[1] * prev[1]
                self.syy += v * v
            self.last[k] = (t, v) if ok else None
        if self.sxx > 0 and self.syy > 0:
            rho = min(max(self.sxy / math.sqrt(self.sxx * self.syy), 0.0), 0.999)
            self.inflation = min(ar1_variance_factor(rho), self.max_inflation)
        return self.inflation


__all__ = ["MixtureModel", "ResidualCorrelation"]
