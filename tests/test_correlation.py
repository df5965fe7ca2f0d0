"""The AR(1) factor on the variance of a mean of correlated samples (selfnav.correlation),
against a Monte Carlo of the process itself."""
import math

import numpy as np
import pytest

from selfnav.correlation import ar1_factor_of_time, ar1_variance_factor, lag_one_correlation


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.9, 0.98])
def test_the_factor_is_the_variance_of_the_mean_of_an_ar1_process(rho):
    """2000 series of 2000 samples, x_k = ρ x_{k−1} + w_k, stationary start: the variance of
    their means is f(ρ) σ²/n to within the Monte Carlo's 5 %, and ρ is found from one series
    to within 0.03."""
    rng = np.random.default_rng(7)
    m, n = 2000, 2000
    x = np.empty((m, n))
    x[:, 0] = rng.standard_normal(m)
    w = rng.standard_normal((m, n)) * math.sqrt(1.0 - rho**2)
    for k in range(1, n):
        x[:, k] = rho * x[:, k - 1] + w[:, k]
    # the exact finite-n factor differs from f(ρ) by O(1/(n(1−ρ))): 2.5 % at ρ 0.98
    assert np.var(x.mean(axis=1)) * n / ar1_variance_factor(rho) == pytest.approx(1.0, abs=0.08)
    assert lag_one_correlation(x[0]) == pytest.approx(rho, abs=0.03)
    assert lag_one_correlation(x[:5]) == pytest.approx(rho, abs=0.03)     # rows pooled


def test_edges_and_time_form():
    assert lag_one_correlation([]) == 0.0 and lag_one_correlation([3.0]) == 0.0
    assert lag_one_correlation(np.zeros(10)) == 0.0
    assert lag_one_correlation([1.0, -1.0] * 50) == 0.0             # anti-correlated: white
    assert lag_one_correlation(np.ones(100), rho_max=0.9) == 0.9
    assert ar1_factor_of_time(1.0, 10.0) == pytest.approx(
        (1 + math.exp(-0.1)) / (1 - math.exp(-0.1)))
    assert ar1_factor_of_time(1.0, 10.0) == pytest.approx(20.0, rel=0.01)   # ≈ 2τ/Δt
