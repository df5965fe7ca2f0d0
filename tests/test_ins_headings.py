"""The Gaussian sum over the heading (selfnav.ins.headings): a sum built from one filter and
joined by another — a restart from the fixes beside the INS's own heading — and its
collapse, moment-matched about the best."""
import math

import numpy as np
import pytest

from selfnav import attitude as att
from selfnav.earth import enu_offset
from selfnav.ins import config as ic
from selfnav.ins.ekf import IBG
from selfnav.ins.headings import heading_hypotheses, split_heading
from selfnav.ins.navigator import initial_filter


def _filter(yaw_bias_sigma_deg=0.05):
    """A start within the linear range: heading σ 2°, and its gyro biases measured (a stop
    before it) to ``yaw_bias_sigma_deg`` °/s — ``None``: the grade's prior (1 °/s)."""
    cfg = ic.navigator_config()
    init = {"t": 0.0, "lat": math.radians(60.0), "lon": math.radians(25.0), "h": 10.0,
            "velocity_n": np.array([0.0, 8.0, 0.0]), "C_nb": att.dcm_nb_from_euler(0.0, 0.0, 0.0),
            "sigmas": ([3.0, 3.0, 5.0], [0.3, 0.3, 0.3],
                       [math.radians(0.5), math.radians(0.5), math.radians(2.0)])}
    if yaw_bias_sigma_deg is not None:
        init.update(gyro_bias=np.zeros(3),
                    gyro_bias_sigma=np.full(3, math.radians(yaw_bias_sigma_deg)))
    return cfg, initial_filter(cfg, init)


def test_a_start_unsure_of_its_yaw_bias_is_split_by_default():
    """The default splits a start whose z gyro bias is only the grade's prior (1 °/s: a
    consumer part moving with no stop to measure it) along that bias even when its heading
    is within the linear range — seven yaw-bias hypotheses, the prior's σ back by moment
    matching — and leaves a start whose bias a stop measured as one filter."""
    cfg, f = _filter(None)
    assert cfg.init.yaw_bias_split_sigma == pytest.approx(math.radians(0.5))
    hyp = split_heading(f, cfg)
    assert hyp is not None
    # the heading within the linear range: its offsets ±6° carry no weight (the first fix
    # prunes them), the seven yaw-bias offsets at heading 0 carry it all
    live = hyp.weights > 1e-9
    assert live.sum() == 7 and np.allclose(hyp.deltas[live], 0.0)
    w, b = hyp.weights, hyp.bias_deltas
    iz = IBG.start + 2                                     # the z gyro's bias
    s2 = np.array([g.P[iz, iz] for g in hyp.filters])
    assert float(w @ (s2 + b * b)) == pytest.approx(float(f.P[iz, iz]), rel=0.05)
    assert split_heading(_filter()[1], cfg) is None


@pytest.mark.parametrize("weight", [0.5, 0.2])
def test_a_joined_hypothesis_holds_its_weight_and_the_collapse_covers_both(weight):
    """One filter within the linear range (not split) joined by a second 10° and 12 m away
    holding ``weight``: the sum's weights are ``1 − weight, weight``; collapsed about the
    first (the best), its covariance is ``P + w d dᵀ`` with ``d`` the error-state difference
    (heading to first order: ``sin δ``)."""
    cfg, f = _filter()
    assert split_heading(f, cfg) is None               # within the linear range: one
    hyp = heading_hypotheses(f, cfg, split=False)
    assert len(hyp.filters) == 1 and np.allclose(hyp.filters[0].P, f.P)
    other = f.copy()
    d = math.radians(10.0)
    other.ins.set_state(C_nb=att.dcm_nb_from_euler(0.0, 0.0, d),
                        lat=f.ins.lat + 12.0 / 6.36e6)
    hyp.join(other, weight, d)
    assert np.allclose(hyp.weights, [1.0 - weight, weight])
    assert hyp.best == 0 and len(hyp.filters) == 2 and hyp.spawned == 2
    P = hyp.collapse().P
    assert P[8, 8] == pytest.approx(f.P[8, 8] + weight * math.sin(d) ** 2, rel=1e-6)
    north = enu_offset(f.ins.lat, f.ins.lon, f.ins.h, other.ins.lat, other.ins.lon, f.ins.h)[1]
    assert north == pytest.approx(12.0, rel=0.01)
    assert P[1, 1] == pytest.approx(f.P[1, 1] + weight * north**2, rel=1e-6)


def test_a_snapshot_of_the_sum_is_its_own_and_names_its_hypotheses_as_the_sum_does():
    """The fault bank's fallback while the heading is undecided: a copy of the whole sum.
    What the sum does after it (a correction of one filter, pruning) leaves the copy as it
    was, and a hypothesis keeps its name through the pruning: the copy's hypothesis of the
    same name is the same filter as it stood."""
    cfg, f = _filter(None)
    hyp = split_heading(f, cfg)
    snap = hyp.snapshot()
    n = len(hyp.filters)
    assert np.array_equal(snap.ids, np.arange(n)) and np.allclose(snap.weights, hyp.weights)
    assert all(a is not b and np.allclose(a.P, b.P) for a, b in zip(snap.filters, hyp.filters))
    lat0 = [g.ins.lat for g in snap.filters]
    keep = np.argsort(hyp.logw)[-3:]                     # three survive the pruning
    hyp.logw[np.setdiff1d(np.arange(n), keep)] -= 100.0
    hyp.prune()
    hyp.filters[0].ins.set_state(lat=hyp.filters[0].ins.lat + 1e-5)
    hyp.filters[0].P *= 4.0
    assert len(hyp.filters) == 3 and len(snap.filters) == n
    assert [g.ins.lat for g in snap.filters] == lat0
    assert np.array_equal(hyp.ids, np.sort(keep))
    for k, i in enumerate(hyp.ids[1:], start=1):
        assert np.allclose(snap.filters[int(i)].P, hyp.filters[k].P)
