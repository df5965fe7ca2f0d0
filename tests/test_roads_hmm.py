"""GNSS-only map matching (selfnav.roads.hmm, ``selfnav match``) on real OpenStreetMap roads with
simulated 5-second floating-car tracks (simulated data, labelled so in the files written)."""
import itertools
import json

import networkx as nx
import numpy as np
import pytest

from selfnav.cli import main
from selfnav.io.csvio import read_table, write_csv
from selfnav.roads.hmm import HmmMatcher, neighbour_points, transition_route_distance
from selfnav.roads.routes import node_distances
from selfnav.roads.graph import (Candidates, packaged_map, project_points_to_segments,
                                 project_to_polyline)
from selfnav.sim.car import car_route


@pytest.fixture(scope="module")
def maps(karhula, helsinki):
    return {"kotka_karhula": karhula, "helsinki_centre": helsinki}


def floating_car(g, seed, sigma, duration=1800.0, period=5.0):
    """A simulated floating-car track: true route and noisy fixes every ``period`` s."""
    traj, route = car_route(g, duration=duration, dt=period, seed=seed)
    rng = np.random.default_rng(1000 + seed)
    noisy = route.xy + rng.normal(0.0, sigma, route.xy.shape)
    return traj, route, noisy


@pytest.mark.parametrize("name", ["kotka_karhula", "helsinki_centre"])
def test_95_percent_of_fixes_within_5_m_of_the_true_route(maps, name):
    g = maps[name]
    shares = []
    for seed in (11, 12):
        traj, route, noisy = floating_car(g, seed, sigma=10.0)
        res = HmmMatcher(g, sigma=10.0).match(traj.t, noisy)
        assert len(res.t) == len(traj.t)                    # every fix gets a road position
        _, cross, _ = project_to_polyline(res.xy, route.polyline)
        shares.append(np.mean(np.abs(cross) < 5.0))
        # the raw fixes are nowhere near that: the matching does the work
        _, raw, _ = project_to_polyline(noisy, route.polyline)
        assert np.mean(np.abs(raw) < 5.0) < 0.6
    assert min(shares) >= 0.95, shares


def test_noise_free_track_is_matched_onto_the_route(maps):
    g = maps["helsinki_centre"]
    traj, route = car_route(g, duration=900.0, dt=5.0, seed=3)
    res = HmmMatcher(g, sigma=5.0).match(traj.t, route.xy)
    _, cross, _ = project_to_polyline(res.xy, route.polyline)
    # the car cuts corners by up to a few metres (corner arcs); everywhere else exact
    e = route.path.element(route.s)
    straight = route.path.kappa[e] == 0
    assert np.mean(np.abs(cross[straight]) < 0.01) > 0.97
    assert np.all(res.in_radius) and res.restart.sum() == 1


def test_every_fix_is_matched_even_far_outliers(maps):
    g = maps["kotka_karhula"]
    traj, route, noisy = floating_car(g, 5, sigma=10.0, duration=600.0)
    noisy = noisy.copy()
    noisy[40] += [600.0, -700.0]                             # far off the map
    noisy[41:46] += np.random.default_rng(0).normal(0, 200.0, (5, 2))
    res = HmmMatcher(g, sigma=10.0).match(traj.t, noisy)
    assert np.all(np.isfinite(res.xy)) and len(res.xy) == len(noisy)
    # matched points are on the road network: distance to the nearest segment is ~0
    c = g.candidates(res.xy, 1.0, k=1, per_way=False)
    assert np.max(c.dist) < 1e-6
    assert not res.in_radius[40]


def test_route_distances_agree_with_networkx(maps):
    g = maps["helsinki_centre"]
    rng = np.random.default_rng(2)
    src = rng.integers(0, g.n_nodes, 40)
    dst = rng.integers(0, g.n_nodes, 40)
    d = node_distances(g, src, dst)
    ref = [nx.shortest_path_length(g.nx, int(a), int(b), weight="length") for a, b in zip(src, dst)]
    np.testing.assert_allclose(d, ref, rtol=1e-12, atol=1e-9)
    d_lim = node_distances(g, src, dst, limit=300.0)
    assert np.all(np.isinf(d_lim[np.asarray(ref) > 300.0]))


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_viterbi_and_posterior_agree_with_brute_force(maps, seed):
    """The numba kernels (transitions on the fly, windows of 2 fixes, cached route rows, pruned
    pairs, stored weights) find the path an exhaustive search finds over the model written out
    in numpy (route distances by :func:`transition_route_distance`, the detour against the
    straight line between the two road points, the shared error's residual term, the cut, a
    break at every transition with log p ``log_break``, the robust emission), and the
    posterior of every candidate is the one the enumeration of every path gives."""
    g = maps["kotka_karhula"]
    traj, route, noisy = floating_car(g, seed, sigma=15.0, duration=300.0, period=5.0)
    t, xy = traj.t[20:26], noisy[20:26].copy()
    xy[3] += [70.0, -40.0]                     # a multipath outlier: neighbour candidates too
    m = HmmMatcher(g, sigma=15.0, k=3, window=2, error_corr=0.5, stationary_k=0.0)
    res = m.match(t, xy)
    bounds = np.array([0, len(t)])
    radius = np.full(len(t), m.radius)
    ep = m._epochs(t, xy, np.full(len(t), m.sigma), bounds)
    assert len(ep.xy) == len(t)                # (no stationary run: one epoch per fix)
    dec = m._decode(ep, radius, np.full(len(t), m.beta), np.full(len(t), m.backtrack))
    off, seg, along, dist, foot, pos = m._candidates(xy, radius,
                                                     neighbour_points(xy, bounds, radius))
    np.testing.assert_array_equal(dec["seg"], seg)
    assert np.diff(off)[3] > 3                 # the outlier got its neighbours' roads
    query = np.repeat(np.arange(len(t)), np.diff(off))
    cand = Candidates(query, seg, along, np.zeros(len(seg)), dist, foot)
    em = m.emission(dist, m.sigma)
    r = xy[query] - foot                       # residuals, not beyond 3 σ nor for neighbours'
    r[(np.hypot(*(xy[query] - pos).T) > 0) | (dist > 3 * m.sigma)] = np.nan
    table = {}
    for e in range(len(t) - 1):
        i, j = (a.ravel() for a in np.meshgrid(np.arange(off[e], off[e + 1]),
                                               np.arange(off[e + 1], off[e + 2]), indexing="ij"))
        fastest = m.max_speed * (t[e + 1] - t[e]) + 2 * m.radius
        d = transition_route_distance(g, cand, i, j, backtrack=m.backtrack, limit=np.inf)
        detour = np.maximum(d - np.hypot(*(foot[j] - foot[i]).T), 0.0)
        rho = 0.5 * np.exp(-(t[e + 1] - t[e]) / m.error_tau)
        both = np.isfinite(r[i, 0]) & np.isfinite(r[j, 0])
        corr = np.where(both, (np.sum(r[j] ** 2, 1) - np.sum((r[j] - rho * r[i]) ** 2, 1)
                               / (1 - rho ** 2)) / (2 * m.sigma ** 2), 0.0)
        lt = np.where(np.isfinite(d) & (d <= fastest), -detour / m.beta + corr, -np.inf)
        lt[lt < -m.cut] = -np.inf
        table.update({(a, b): v for a, b, v in zip(i, j, lt)})
    best, best_path = -np.inf, None
    paths, logw = [], []
    for combo in itertools.product(*[range(off[e], off[e + 1]) for e in range(len(t))]):
        steps = [table[a, b] for a, b in zip(combo[:-1], combo[1:])]
        v = sum(em[k] for k in combo) + sum(max(s, m.log_break) for s in steps)
        if v > best:
            best, best_path = v, combo
        paths.append(combo)
        logw.append(sum(em[k] for k in combo) + sum(np.logaddexp(s, m.log_break)
                                                     for s in steps))
    np.testing.assert_array_equal(res.seg, seg[list(best_path)])
    np.testing.assert_array_equal(dec["path"], best_path)
    w = np.exp(np.asarray(logw) - max(logw))
    post = np.zeros(len(seg))
    for combo, wk in zip(paths, w):
        post[list(combo)] += wk
    post /= w.sum()
    np.testing.assert_allclose(dec["post"], post, atol=1e-4)
    assert not res.matched[3] and res.moved[3] > 30.0    # the outlier is not "matched"


def test_chain_restarts_where_no_transition_is_possible(maps):
    g = maps["kotka_karhula"]
    traj, route, noisy = floating_car(g, 6, sigma=5.0, duration=600.0)
    t = traj.t.copy()
    t[60:] += 1000.0                                          # a 1000 s gap: max_gap 120 s
    res = HmmMatcher(g, sigma=5.0).match(t, noisy)
    assert res.restart[0] and res.restart[60]


def _write_track(path, g, traj, xy, sigma):
    lat, lon = g.to_geodetic(xy[:, 0], xy[:, 1])
    write_csv(path, {"t": traj.t, "lat_deg": np.degrees(lat), "lon_deg": np.degrees(lon),
                     "h_m": np.zeros(len(lat)), "sigma_m": np.full(len(lat), sigma)},
              comments=["simulated 5-s floating-car GNSS track (selfnav tests)"],
              fmt={"lat_deg": "%.10f", "lon_deg": "%.10f"})


def test_cli_match_json_and_output(maps, tmp_path, capsys):
    g = maps["kotka_karhula"]
    traj, route, noisy = floating_car(g, 8, sigma=8.0, duration=900.0)
    gnss = tmp_path / "gnss.csv"
    _write_track(gnss, g, traj, noisy, 8.0)
    out = tmp_path / "sol.csv"
    rc = main(["match", "--gnss", str(gnss), "--map", str(packaged_map("kotka_karhula")),
               "--out", str(out), "--json"])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    # the map as matching reads it: every drivable way (1677 directed segments, not only the
    # 1514 of the strongly connected core)
    assert summary["fixes"] == len(traj.t) and summary["map_segments"] == 1677
    tab = read_table(out, ("t", "lat_deg", "lon_deg", "cross_m", "matched", "match_p"))
    x, y = g.to_local(np.radians(tab["lat_deg"]), np.radians(tab["lon_deg"]))
    _, cross, _ = project_to_polyline(np.column_stack([x, y]), route.polyline)
    assert np.mean(np.abs(cross) < 5.0) >= 0.95
    ok = tab["matched"] == 1
    assert summary["matched_share"] == pytest.approx(ok.mean()) and ok.mean() > 0.9
    assert np.mean(np.abs(cross[ok]) < 5.0) >= 0.97
    assert np.all((tab["match_p"] >= 0) & (tab["match_p"] <= 1))
    q, = summary["track_quality"]
    assert q["breaks"] == summary["breaks"] == 0 and q["fixes"] == len(traj.t)
    assert summary["mean_correction_m"] == pytest.approx(np.mean(tab["cross_m"]), abs=1e-3)
    assert out.read_text().startswith("t,lat_deg,lon_deg")   # pandas reads it as is
    assert "OpenStreetMap" in json.loads((tmp_path / "sol.csv.json").read_text())["notes"][2]


def test_cli_match_errors_are_one_line(tmp_path, capsys, maps):
    gnss = tmp_path / "far.csv"
    write_csv(gnss, {"t": [0.0, 1.0], "lat_deg": [55.75, 55.75], "lon_deg": [37.61, 37.62]})
    bad_map = tmp_path / "bad.osm.pbf"
    bad_map.write_bytes(b"\x00\x01garbage")
    cases = [
        (["--map", str(packaged_map("kotka_karhula"))], "none of the 2 fixes"),
        (["--map", str(bad_map)], "cannot be read"),
        (["--map", str(tmp_path / "missing.osm")], "no such map"),
    ]
    for extra, msg in cases:
        rc = main(["match", "--gnss", str(gnss), "--out", str(tmp_path / "o.csv"), *extra])
        err = capsys.readouterr().err.strip()
        assert rc == 2 and err.startswith("selfnav: error:") and msg in err
        assert len(err.splitlines()) == 1
    assert not (tmp_path / "o.csv").exists()


def test_snap_to_road_uses_the_direction_of_travel(maps):
    from selfnav.roads.hmm import snap_to_road

    g = maps["helsinki_centre"]
    two_way = np.flatnonzero((g.seg_twin >= 0) & (g.seg_len > 30))[0]
    mid = g.segment_points([two_way], [g.seg_len[two_way] / 2])[0]
    normal = np.array([-np.cos(g.seg_heading[two_way]), np.sin(g.seg_heading[two_way])])  # left
    p = mid + 2.0 * normal
    h = g.seg_heading[two_way]
    foot, seg, cross, rh = snap_to_road(g, [p, p], [h, h + np.pi], radius=10.0)
    assert seg[0] == two_way and seg[1] == g.seg_twin[two_way]
    np.testing.assert_allclose(foot[0], mid, atol=1e-9)
    assert cross[0] == pytest.approx(2.0) and cross[1] == pytest.approx(-2.0)
    assert rh[1] == pytest.approx((h + np.pi) % (2 * np.pi))
    one_way = np.flatnonzero((g.seg_twin < 0) & (g.seg_len > 30))[0]
    q = g.segment_points([one_way], [g.seg_len[one_way] / 2])
    _, s_ok, _, _ = snap_to_road(g, q, g.seg_heading[one_way], radius=3.0)
    _, s_no, _, _ = snap_to_road(g, q, g.seg_heading[one_way] + np.pi, radius=3.0)
    assert s_ok[0] == one_way and s_no[0] != one_way


def test_cli_match_reads_and_writes_other_datums(maps, tmp_path, capsys):
    from selfnav.datum import convert

    g = maps["kotka_karhula"]
    traj, route, noisy = floating_car(g, 9, sigma=5.0, duration=300.0)
    lat, lon = g.to_geodetic(noisy[:, 0], noisy[:, 1])
    wgs = tmp_path / "wgs.csv"
    _write_track(wgs, g, traj, noisy, 5.0)
    la42, lo42, h42 = convert(lat, lon, np.zeros(len(lat)), "wgs84", "sk42")
    sk = tmp_path / "sk42.csv"
    write_csv(sk, {"t": traj.t, "lat_deg": np.degrees(la42), "lon_deg": np.degrees(lo42),
                   "h_m": h42}, comments=["simulated, SK-42"],
              fmt={"lat_deg": "%.10f", "lon_deg": "%.10f"})
    m = str(packaged_map("kotka_karhula"))
    assert main(["match", "--gnss", str(wgs), "--map", m, "--out", str(tmp_path / "a.csv")]) == 0
    assert main(["match", "--gnss", str(sk), "--map", m, "--out", str(tmp_path / "b.csv"),
                 "--gnss-datum", "sk42", "--out-datum", "sk42"]) == 0
    capsys.readouterr()
    a = read_table(tmp_path / "a.csv", ("lat_deg", "lon_deg"))
    b = read_table(tmp_path / "b.csv", ("lat_deg", "lon_deg"))
    # the SK-42 output converted back to WGS-84 is the WGS-84 run's output (SK-42 differs by
    # ~100 m here, so a datum ignored would show)
    la, lo, _ = convert(np.radians(b["lat_deg"]), np.radians(b["lon_deg"]),
                        np.zeros(len(b["lat_deg"])), "sk42", "wgs84")
    x1, y1 = g.to_local(np.radians(a["lat_deg"]), np.radians(a["lon_deg"]))
    x2, y2 = g.to_local(la, lo)
    assert np.max(np.hypot(x1 - x2, y1 - y2)) < 0.05
    x3, y3 = g.to_local(np.radians(b["lat_deg"]), np.radians(b["lon_deg"]))
    assert np.median(np.hypot(x1 - x3, y1 - y3)) > 20.0


def _brute_candidates(g, xy, radius, k, per_way):
    """Every segment measured against every point (numpy), nearest per (way, direction), k
    nearest by (distance, segment): the oracle of the grid search."""
    from selfnav.roads.graph import project_points_to_segments

    out = []
    a, b = g.xy[g.seg_u], g.xy[g.seg_v]
    for q, p in enumerate(xy):
        _, _, d, _ = project_points_to_segments(np.broadcast_to(p, a.shape), a, b)
        idx = np.flatnonzero(d <= radius)
        idx = idx[np.lexsort((idx, d[idx]))]
        if per_way:
            key = g.seg_way[idx] * 2 + (g.seg_u[idx] < g.seg_v[idx])
            _, first = np.unique(key, return_index=True)
            idx = idx[np.sort(first)]
        out += [(q, int(i), d[i]) for i in idx[:k]]
    return out


@pytest.mark.parametrize("per_way,radius,k", [(True, 40.0, 16), (False, 25.0, 4),
                                              (True, 150.0, 50)])
def test_grid_candidate_search_agrees_with_brute_force(maps, per_way, radius, k):
    g = maps["helsinki_centre"]
    rng = np.random.default_rng(4)
    x0, y0, x1, y1 = g.bounds()
    xy = np.column_stack([rng.uniform(x0 - 100, x1 + 100, 150),
                          rng.uniform(y0 - 100, y1 + 100, 150)])
    c = g.candidates(xy, radius, k=k, min_candidates=0, per_way=per_way)
    ref = _brute_candidates(g, xy, radius, k, per_way)
    assert [(q, s) for q, s, _ in ref] == list(zip(c.query.tolist(), c.seg.tolist()))
    np.testing.assert_allclose(c.dist, [d for *_, d in ref], rtol=0, atol=1e-9)


def test_a_small_route_store_gives_the_same_match(maps):
    """The route store is emptied when full (bounded memory); results do not depend on it."""
    from selfnav.roads.routes import RouteCache

    g = maps["helsinki_centre"]
    traj, _, noisy = floating_car(g, 31, sigma=10.0, duration=1800.0, period=5.0)
    ref = HmmMatcher(g, sigma=10.0).match(traj.t, noisy)
    small = RouteCache(g, max_entries=3000)
    res = HmmMatcher(g, sigma=10.0, window=64, cache=small).match(traj.t, noisy)
    assert small.clears > 3
    np.testing.assert_array_equal(res.seg, ref.seg)
    np.testing.assert_array_equal(res.restart, ref.restart)
    np.testing.assert_allclose(res.xy, ref.xy, atol=1e-9)
