"""selfnav.quantiles against scipy.stats, the oracle: the same values to the last bit."""
import subprocess
import sys

import numpy as np
from scipy import stats

from selfnav.quantiles import binom_isf, chi2_isf, chi2_ppf, norm_isf


def test_the_gates_quantiles_are_scipy_stats_own_to_the_last_bit():
    for dof in (1, 2, 3, 4, 6, 9, 20, 58):
        for p in (0.5, 0.9, 0.99, 0.999, 0.9999, 1.0 - 1e-7):
            assert chi2_ppf(p, dof) == stats.chi2.ppf(p, dof)
            assert chi2_isf(1.0 - p, dof) == stats.chi2.isf(1.0 - p, dof)
    dof = np.array([1, 2, 5, 11])
    np.testing.assert_array_equal(chi2_ppf(0.999, dof), stats.chi2.ppf(0.999, dof))
    for q in (0.5, 0.05, 5e-4, 1e-5, 1e-9):
        assert norm_isf(q) == stats.norm.isf(q)


def test_the_binomial_count_is_scipy_stats_own():
    # (away from exact ties sf(k) == q, where the two round differently: n 1, p = q 0.05)
    for n in (1, 5, 12, 20, 40, 100):
        for p in (0.01, 0.07, 0.2, 0.5):
            for q in (0.45, 0.04, 1e-3, 1e-6):
                assert binom_isf(q, n, p) == int(stats.binom.isf(q, n, p)), (n, p, q)
    # the start's check, as the navigator calls it
    from selfnav.roads.aid import ALPHA_START_CHECK, P_FAR_NOMINAL, far_allowed
    for n in range(1, 201):
        assert far_allowed(n) == int(stats.binom.isf(ALPHA_START_CHECK, n, P_FAR_NOMINAL))


def test_navigating_does_not_import_scipy_stats_or_signal():
    # 1.5-2 s of every command's start on the test machine before (selfnav.quantiles)
    code = ("import sys, selfnav.api, selfnav.cli, selfnav.ins.navigator, selfnav.roads.aid; "
            "print(sorted(m for m in ('scipy.stats', 'scipy.signal') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"
