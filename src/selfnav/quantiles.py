"""The few distribution quantiles selfnav's gates use, through :mod:`scipy.special`.

``scipy.stats`` takes 1.5–2 s to import (on the 2-core test machine), which every ``selfnav``
command paid before it read a line; its gates need only these. Each is the formula
``scipy.stats`` itself evaluates (scipy 1.17: ``chi2._ppf``, ``chi2._isf``, ``norm._isf``),
so the values are the same to the last bit (``tests/test_quantiles.py`` checks them against
``scipy.stats``, the oracle).
"""
from __future__ import annotations

import numpy as np
from scipy import special


def chi2_ppf(p, dof):
    """Quantile of χ²(``dof``) at probability ``p`` (``scipy.stats.chi2.ppf``)."""
    return 2.0 * special.gammaincinv(np.asarray(dof, float) / 2.0, p)


def chi2_isf(q, dof):
    """The value χ²(``dof``) exceeds with probability ``q`` (``scipy.stats.chi2.isf``)."""
    return special.chdtri(dof, q)


def norm_isf(q):
    """The value a standard normal exceeds with probability ``q`` (``scipy.stats.norm.isf``)."""
    return -special.ndtri(q)


def binom_isf(q: float, n: int, p: float) -> int:
    """The smallest ``k`` with ``P(X > k) ≤ q`` for ``X ~ Binomial(n, p)``
    (``scipy.stats.binom.isf``)."""
    k = np.arange(n + 1)
    sf = special.bdtrc(k, n, p)
    return int(k[np.argmax(sf <= q)]) if np.any(sf <= q) else n


__all__ = ["binom_isf", "chi2_isf", "chi2_ppf", "norm_isf"]
