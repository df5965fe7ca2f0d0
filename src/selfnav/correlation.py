"""Errors correlated from one sample to the next, seen through a first-order (AR(1)) model.

``n`` samples of an error with lag-one correlation ``ρ`` carry, for their mean, the
information of ``n (1 − ρ) / (1 + ρ)`` independent ones (large ``n``): a statistic that treats
them as independent must have its variance multiplied by::

    f(ρ) = (1 + ρ) / (1 − ρ)

The navigator's road constraints and clock model (``ρ = exp(−Δt/τ)`` of a Gauss–Markov error
seen every ``Δt``), the sideways constraint's slip check, the magnetometer's turn fit and the
pseudorange mixture's residuals (``ρ`` estimated from the samples) all use it.
"""
from __future__ import annotations

import math

import numpy as np


def lag_one_correlation(x, rho_max: float = 0.99) -> float:
    """Lag-one correlation about zero of the samples ``x`` (along the last axis; rows of a 2-D
    ``x`` are separate series pooled): ``Σ x_k x_{k−1} / Σ x_k²``, within ``[0, rho_max]``
    (an anti-correlated error is taken as white). 0 for fewer than two samples or all zero."""
    x = np.asarray(x, float)
    if x.shape[-1] < 2:
        return 0.0
    ss = float(np.sum(x * x))
    if not ss > 0.0:
        return 0.0
    return min(max(float(np.sum(x[..., 1:] * x[..., :-1])) / ss, 0.0), float(rho_max))


def ar1_variance_factor(rho: float) -> float:
    """``(1 + ρ) / (1 − ρ)``: the factor on the variance of a mean of AR(1) samples."""
    return (1.0 + rho) / (1.0 - rho)


def ar1_factor_of_time(step_s: float, corr_s: float) -> float:
    """:func:`ar1_variance_factor` of ``ρ = exp(−step/τ)``: measurements every ``step_s`` of an
    error correlated over ``corr_s`` carry, in sum, the information they have — not as if
    each were independent."""
    return ar1_variance_factor(math.exp(-step_s / corr_s))
