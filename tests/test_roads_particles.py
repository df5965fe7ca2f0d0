"""Road-constrained particle matcher (issue 5): driven by travel and heading on a real map."""
import numpy as np
from support import route_drive as _drive

from selfnav.roads.particles import MatcherConfig, RoadParticles, successor_table, wrap
from selfnav.sensors import OutlierWindow


def test_successors_leave_the_end_node_and_skip_the_twin(helsinki):
    g = helsinki
    off, succ = successor_table(g)
    for s in range(0, g.n_segments, 97):
        nx = succ[off[s]:off[s + 1]]
        assert len(nx) >= 1
        assert np.all(g.seg_u[nx] == g.seg_v[s])
        if len(nx) > 1:
            assert g.seg_twin[s] not in nx


def _run(g, route, z, idx, hdg, rng):
    pf = RoadParticles(g, MatcherConfig(), seed=0)
    pf.seed(z[0], 60.0)
    err = []
    for k in range(1, len(z)):
        ds = (route.s[idx[k]] - route.s[idx[k - 1]]) * (1 + 0.01 * rng.normal())
        pf.predict(ds, hdg[idx[k]] + np.radians(3.0) * rng.normal())
        pf.update_gnss(z[k])
        err.append(np.hypot(*(pf.estimate()["xy"] - route.xy[idx[k]])))
    return np.asarray(err), pf


def test_holds_the_road_through_white_and_drifting_200m_outliers(helsinki):
    """Simulated (labelled): 300 s in central Helsinki, a 100 s white and a 100 s drifting
    200 m σ window; travel (1 % error) and heading (3°) stand in for the INS."""
    g = helsinki
    wins = [OutlierWindow(60, 100, 200, "white"), OutlierWindow(180, 100, 200, "gm")]
    route, z, idx, hdg, fx = _drive(g, wins)
    err, pf = _run(g, route, z, idx, hdg, np.random.default_rng(5))
    settled = err[30:]
    assert np.sqrt(np.mean(settled**2)) < 8.0, np.sqrt(np.mean(settled**2))
    assert np.max(settled) < 30.0
    # the raw fixes inside the windows are far worse
    raw = np.hypot(*(z - route.xy[idx]).T)[fx.outlier]
    assert np.sqrt(np.mean(raw**2)) > 100.0


def test_estimate_lies_on_a_road_and_heads_along_it(helsinki):
    g = helsinki
    pf = RoadParticles(g, seed=1)
    pf.seed(np.array([0.0, 0.0]), 50.0)
    e = pf.estimate()
    c = g.candidates(e["xy"][None], 1.0, k=1, per_way=False)
    assert len(c) and c.dist[0] < 1e-6
    assert abs(wrap(e["heading"] - g.seg_heading[e["seg"]])) < 1e-9

