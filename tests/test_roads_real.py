"""Map matching as real fleets need it (issue 21): every drivable way of the map, unjoined ways
snapped, breaks where no transition is plausible, an honest ``matched`` flag and ``match_p``.
Simulated tracks on the shipped OpenStreetMap extracts (simulated data); the seeds here are
neither the tuning seed (1) nor the reported ones (2, 3) of benchmarks/bench_mapmatch.py."""
import csv
import json

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from selfnav.cli import main
from selfnav.errors import SelfnavWarning
from selfnav.roads.fleet import MatchParams, match_batch, match_track
from selfnav.roads.graph import packaged_map, read_match_roads, read_roads
from selfnav.roads.hmm import HmmMatcher
from selfnav.sim.fleet import fleet_rows, score_fleet, simulate_real_fleet, unjoin_map
from selfnav.types import GnssData


@pytest.fixture(scope="module")
def full():
    """Both maps with every drivable way (the truth of the simulated tracks)."""
    return {n: read_roads(packaged_map(n), strongly_connected=False)
            for n in ("kotka_karhula", "helsinki_centre")}


def _outside_core_ways(full_g, core):
    drop = ~np.isin(full_g.node_id[full_g.seg_u], core.node_id) | ~np.isin(
        full_g.node_id[full_g.seg_v], core.node_id)
    return drop


def _items(g, tracks):
    items = []
    for tr in tracks:
        t, inv = np.unique(tr.t, return_inverse=True)
        xy = np.zeros((len(t), 2))
        np.add.at(xy, inv, tr.xy)
        xy /= np.bincount(inv)[:, None]
        lat, lon = g.to_geodetic(xy[:, 0], xy[:, 1])
        items.append((tr.track_id, GnssData(t, lat, lon, np.zeros(len(t)))))
    return items


def _drive_along(g, segs):
    """The directed segments of a way in driving order from the first one (one direction; the
    way's segments listed both ways would make a track that jumps back and forth)."""
    chain = [int(segs[0])]
    while True:
        nxt = [k for k in segs if g.seg_u[k] == g.seg_v[chain[-1]] and k not in chain
               and k != g.seg_twin[chain[-1]]]
        if not nxt:
            return np.asarray(chain)
        chain.append(int(nxt[0]))


@pytest.mark.parametrize("name", ["kotka_karhula", "helsinki_centre"])
def test_short_track_on_a_way_outside_the_core_is_matched_onto_it(full, name):
    """The issue's failure, reproduced: ten good fixes (σ 2 m) along a way that the strongly
    connected core leaves out (a one-way exit the extract cuts, a parking aisle). On the core
    -- the map `selfnav match` used before -- every fix went to another road 30-400 m away and
    most were flagged matched; on the map as matching now reads it they are on their way, and
    on the core they are not flagged."""
    g_full = full[name]
    core = read_roads(packaged_map(name))
    match_map = read_match_roads(packaged_map(name))
    drop = _outside_core_ways(g_full, core)
    rng = np.random.default_rng(7)
    on_way = flagged_far = n = 0
    for w in np.unique(g_full.seg_way[drop])[:10]:
        s = _drive_along(g_full, np.flatnonzero((g_full.seg_way == w) & drop))[:6]
        pts = np.concatenate([g_full.segment_points(np.full(5, k), np.linspace(
            0, g_full.seg_len[k], 5)) for k in s])
        pts = pts[::max(1, len(pts) // 8)][:10]
        xy = pts + rng.normal(0, 2.0, pts.shape)
        lat, lon = g_full.to_geodetic(xy[:, 0], xy[:, 1])
        gd = GnssData(np.arange(len(xy)) * 10.0, lat, lon, np.zeros(len(xy)))
        r = match_track(MatchParams().matcher(match_map), str(w), gd).result
        x, y = g_full.to_local(r.lat, r.lon)
        on_way += int(np.sum(np.hypot(x - pts[:, 0], y - pts[:, 1]) < 10.0))
        r0 = match_track(MatchParams().matcher(core), str(w), gd).result
        x0, y0 = g_full.to_local(r0.lat, r0.lon)
        far = np.hypot(x0 - pts[:, 0], y0 - pts[:, 1]) > 10.0
        flagged_far += int(np.sum(far & r0.matched))
        n += len(xy)
    assert on_way >= 0.95 * n, (on_way, n)     # (a fix near the way's end may take the next road)
    # on the core, the road under the fixes is missing: few of the far placements are flagged
    # (those within 30 m and 3 σ of another road: σ is estimated from that distance)
    assert flagged_far <= 0.1 * n, flagged_far


def test_unjoined_ways_are_snapped_back_into_the_same_graph(full, tmp_path):
    """Every end of a way that ends on another way moved 0.5-3 m off it: the snap tolerance
    joins each back, and route distances are those of the original map (within the offsets)."""
    src = packaged_map("kotka_karhula")
    n = unjoin_map(src, tmp_path / "u.osm", share=1.0, seed=11)
    g = read_match_roads(tmp_path / "u.osm")
    ref = read_match_roads(src)
    # (two ends moved off the same node: one joins the other, one snap for two)
    assert n > 100 and 0.95 * n <= g.snapped <= n
    loose = read_match_roads(tmp_path / "u.osm", snap_m=0)
    assert loose.snapped == 0 and loose.n_nodes == ref.n_nodes + n
    # (nearly) the same graph: the snapped ends take the ids of the nodes they join
    assert abs(g.n_nodes - ref.n_nodes) <= 0.01 * ref.n_nodes
    assert abs(g.n_segments - ref.n_segments) <= 0.01 * ref.n_segments
    common = np.intersect1d(g.node_id, ref.node_id)
    assert len(common) >= 0.9 * ref.n_nodes      # (a junction whose ways all moved: a new id)
    rng = np.random.default_rng(3)
    src_ids = rng.choice(common, 20, replace=False)
    d_ref = dijkstra(ref.csr, indices=np.searchsorted(ref.node_id, src_ids))[
        :, np.searchsorted(ref.node_id, common)]
    d_g = dijkstra(g.csr, indices=np.searchsorted(g.node_id, src_ids))[
        :, np.searchsorted(g.node_id, common)]
    ok = np.isfinite(d_ref)
    assert np.mean(ok == np.isfinite(d_g)) > 0.99
    both = ok & np.isfinite(d_g)
    assert np.median(np.abs(d_g[both] - d_ref[both])) < 3.0
    # no end is left loose: the dead ends are the original map's
    und = [np.unique(np.sort(np.column_stack([x.seg_u, x.seg_v]), axis=1), axis=0)
           for x in (g, ref, loose)]
    dead = [int(np.sum(np.bincount(u.ravel()) == 1)) for u in und]
    assert dead[0] == dead[1] < dead[2] - 100


def test_chain_breaks_where_the_map_does_not_connect(full, tmp_path):
    """On a map whose ways are not joined (no snapping), a track over an unjoined junction
    cannot pass: the chain breaks there, each piece is matched on its own (the fixes stay on
    their roads), and the breaks are reported per track."""
    src = packaged_map("kotka_karhula")
    unjoin_map(src, tmp_path / "u.osm", share=1.0, seed=12)
    loose = read_match_roads(tmp_path / "u.osm", snap_m=0)
    tracks = simulate_real_fleet(full["kotka_karhula"], 40, seed=12, fixes=(10, 20),
                                 outlier_p=0.0)
    res = [r.result for r in match_batch(MatchParams().matcher(loose),
                                         _items(full["kotka_karhula"], tracks))]
    share, ok, _ = score_fleet(full["kotka_karhula"], tracks, res)
    assert sum(r.breaks for r in res) > 10
    assert ok.mean() >= 0.97, ok.mean()
    r = next(r for r in res if r.breaks)
    assert r.quality()["breaks"] == r.breaks and r.piece[-1] == r.breaks


def test_a_multipath_outlier_keeps_the_road_of_its_neighbours(full):
    """One fix 100 m off (multipath) in a good track: it is placed on the road its neighbours
    are on, not on a road under the outlier, and it is not flagged matched."""
    g = read_match_roads(packaged_map("helsinki_centre"))
    hits = 0
    for seed in range(20, 30):
        tr = simulate_real_fleet(full["helsinki_centre"], 1, seed=seed, fixes=(12, 12),
                                 park_p=0.0, outlier_p=0.0, dup_prob=0.0, sigma=(2.0, 2.0))[0]
        tr.xy[6] += 100.0 * np.array([np.cos(seed), np.sin(seed)])
        r = match_batch(MatchParams().matcher(g), _items(g, [tr]))[0].result
        _, ok, _ = score_fleet(full["helsinki_centre"], [tr], [r])
        hits += bool(ok[6])
        assert ok[6] or not r.matched[6]          # flagged only if right (it may land on the route)
    assert hits >= 9, hits


def _write(path, g, tracks):
    ids, ts, lats, lons = fleet_rows(g, tracks, rng=np.random.default_rng(2), shuffle_prob=0.02)
    with open(path, "w") as fh:
        fh.write("track_id,t,lat_deg,lon_deg\n")
        fh.writelines(f"{a},{b},{c:.8f},{d:.8f}\n" for a, b, c, d in zip(ids, ts, lats, lons))


def test_real_like_fleet_in_one_call_is_right_and_says_when_it_is_not(full, tmp_path, capsys):
    """120 short tracks (2-20 fixes, 5-15 s, ISO stamps, repeated stamps, stationary runs,
    multipath) on a map with unjoined ways, one `selfnav match` call: the matched positions,
    the flag's precision, the per-track quality in the JSON, and match_p as a probability."""
    src = tmp_path / "u.osm"
    unjoin_map(packaged_map("kotka_karhula"), src, seed=13)
    truth = full["kotka_karhula"]
    tracks = simulate_real_fleet(truth, 120, seed=13)
    _write(tmp_path / "fleet.csv", truth, tracks)
    out = tmp_path / "out.csv"
    assert main(["match", "--gnss", str(tmp_path / "fleet.csv"), "--map", str(src), "--out",
                 str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["map_snapped"] > 50 and len(s["track_quality"]) == s["tracks"] == 120
    rows = {}
    for r in csv.DictReader(ln for ln in open(out) if not ln.startswith("#")):
        rows.setdefault(r["track_id"], []).append(r)
    res = []
    for tr in tracks:
        rr = rows[tr.track_id]
        res.append(np.column_stack(truth.to_local(np.radians([float(r["lat_deg"]) for r in rr]),
                                                  np.radians([float(r["lon_deg"]) for r in rr]))))
    share, ok, _ = score_fleet(truth, tracks, res)
    flag = np.array([r["matched"] == "1" for tr in tracks for r in rows[tr.track_id]])
    p = np.array([float(r["match_p"]) for tr in tracks for r in rows[tr.track_id]])
    assert share.mean() >= 0.985 and ok.mean() >= 0.985, (share.mean(), ok.mean())
    assert ok[flag].mean() >= 0.99 and flag.mean() >= 0.9, (ok[flag].mean(), flag.mean())
    assert s["matched_share"] == pytest.approx(flag.mean(), abs=0.01)
    assert np.all((p >= 0) & (p <= 1)) and ok[p >= 0.9].mean() >= 0.98
    q = {d["track_id"]: d for d in s["track_quality"]}
    worst = min(q.values(), key=lambda d: d["matched_share"])
    assert set(worst) >= {"fixes", "matched_share", "breaks", "median_cross_m", "mean_match_p"}


def test_every_drivable_way_is_kept_service_roads_and_parking_aisles_too():
    """The map matching reads keeps every drivable way (the core drops one-way exits and
    isolated parking aisles), and one-way roads stay one-way."""
    name = packaged_map("helsinki_centre")
    core, full_g = read_roads(name), read_roads(name, strongly_connected=False)
    g = read_match_roads(name, snap_m=0)
    assert g.n_segments == full_g.n_segments > core.n_segments
    assert np.sum(g.seg_highway == "service") > np.sum(core.seg_highway == "service") + 100
    assert np.sum(g.seg_twin < 0) == np.sum(full_g.seg_twin < 0) > 0      # one-way segments


def test_helsinki_real_like_fleet_meets_the_issue_and_match_p_is_a_probability(full, tmp_path,
                                                                               capsys):
    """120 short tracks in central Helsinki (parallel service roads, dual carriageways), one
    `selfnav match` call: ≥ 99 % per-track mean within 5 m and ≥ 99 % of the flagged fixes
    right (the issue's targets); `match_p` as a probability -- its mean within a point of the
    share right, and the fixes it calls ≥ 0.99 right 99 % of the time -- and the shared share
    of the error found in the fixes."""
    truth = full["helsinki_centre"]
    tracks = simulate_real_fleet(truth, 120, seed=14)
    _write(tmp_path / "fleet.csv", truth, tracks)
    assert main(["match", "--gnss", str(tmp_path / "fleet.csv"), "--map",
                 str(packaged_map("helsinki_centre")), "--out", str(tmp_path / "o.csv"),
                 "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    rows = {}
    for r in csv.DictReader(ln for ln in open(tmp_path / "o.csv") if not ln.startswith("#")):
        rows.setdefault(r["track_id"], []).append(r)
    res = [np.column_stack(truth.to_local(
        np.radians([float(r["lat_deg"]) for r in rows[tr.track_id]]),
        np.radians([float(r["lon_deg"]) for r in rows[tr.track_id]]))) for tr in tracks]
    share, ok, _ = score_fleet(truth, tracks, res)
    flag = np.array([r["matched"] == "1" for tr in tracks for r in rows[tr.track_id]])
    p = np.array([float(r["match_p"]) for tr in tracks for r in rows[tr.track_id]])
    assert share.mean() >= 0.99 and ok[flag].mean() >= 0.99, (share.mean(), ok[flag].mean())
    assert flag.mean() >= 0.85
    assert abs(p.mean() - ok.mean()) <= 0.01 and ok[p >= 0.99].mean() >= 0.99
    assert 0.3 <= s["error_corr"] <= 0.9


@pytest.mark.slow
def test_match_p_is_calibrated_where_it_doubts(full, tmp_path):
    """Of the fixes ``match_p`` doubts, the share on the route is what it says (issue 21's
    reliability table): four fleets of 263 tracks (both maps, seeds 7 and 8, never used to fit
    the calibration, which is fitted on seed 1), one ``match_files`` call each. The
    calibration of the posterior's log odds alone called fixes of 0.94 right that were right
    86 % of the time here; with the track's end and length and the fix's distance from its
    road: 0.914 against 0.904."""
    from selfnav.roads.fleet import match_files

    ps, oks = [], []
    for name in ("kotka_karhula", "helsinki_centre"):
        truth = full[name]
        for seed in (7, 8):
            tracks = simulate_real_fleet(truth, 263, seed=seed, sigma=(1.0, 4.0))
            _write(tmp_path / "fleet.csv", truth, tracks)
            with pytest.warns(SelfnavWarning):        # repeated stamps, rows out of order
                match_files([tmp_path / "fleet.csv"], packaged_map(name), tmp_path / "o.csv")
            rows = {}
            for r in csv.DictReader(ln for ln in open(tmp_path / "o.csv")
                                    if not ln.startswith("#")):
                rows.setdefault(r["track_id"], []).append(r)
            res = [np.column_stack(truth.to_local(
                np.radians([float(r["lat_deg"]) for r in rows[tr.track_id]]),
                np.radians([float(r["lon_deg"]) for r in rows[tr.track_id]]))) for tr in tracks]
            ps.append([float(r["match_p"]) for tr in tracks for r in rows[tr.track_id]])
            oks.append(score_fleet(truth, tracks, res)[1])
    p, ok = np.concatenate(ps), np.concatenate(oks)
    for lo, hi, tol in ((0.0, 0.95, 0.04), (0.95, 0.99, 0.015), (0.99, 1.01, 0.005)):
        sel = (p >= lo) & (p < hi)
        assert sel.sum() > 150 and abs(ok[sel].mean() - p[sel].mean()) <= tol, (
            lo, sel.sum(), p[sel].mean(), ok[sel].mean())


def test_standing_car_is_one_position_and_keeps_its_outlier(full):
    """A car standing at a junction (the end of its route) for ten fixes of σ 3 m, one of them
    80 m off (multipath), after driving in: the standing fixes are one position on the road it
    stands on, the outlier is put there too and not flagged."""
    g = read_match_roads(packaged_map("kotka_karhula"))
    rng = np.random.default_rng(3)
    deg = np.bincount(np.concatenate([g.seg_u, g.seg_v]))
    node = int(np.flatnonzero(deg >= 6)[5])                  # a junction of three roads
    s_in = int(np.flatnonzero(g.seg_v == node)[0])
    a = g.xy[g.seg_u[s_in]]
    drive = a + (g.xy[node] - a) * np.linspace(0.0, 0.95, 4)[:, None]
    stand = np.repeat(g.xy[node][None], 10, axis=0)
    xy = np.concatenate([drive, stand]) + rng.normal(0, 3.0, (14, 2))
    xy[9] += [60.0, -55.0]
    t = np.arange(14) * 10.0
    r = HmmMatcher(g, sigma=3.0).match(t, xy)
    at = np.hypot(*(r.xy[4:] - g.xy[node]).T)
    assert np.all(at < 5.0), at                              # on the junction's roads, there
    spread = np.ptp(np.delete(xy[4:], 5, axis=0), axis=0).max()
    assert np.ptp(r.xy[4:], axis=0).max() < 0.3 * spread    # one position, not the noise's
    assert not r.matched[9] and r.moved[9] > 50.0


def test_the_shared_error_is_found_in_the_fixes(full):
    """The shared share of the GNSS error, estimated from a fleet's fixes alone: about 0 for
    white noise, well above for an error mostly shared by consecutive fixes (Gauss-Markov,
    τ 60 s) -- the matcher's model follows the fleet."""
    from selfnav.sim.fleet import gnss_errors

    g = read_match_roads(packaged_map("helsinki_centre"))
    tracks = simulate_real_fleet(full["helsinki_centre"], 80, seed=16, fixes=(8, 20),
                                 outlier_p=0.0)
    m = HmmMatcher(g)
    est = {}
    for white in (1.0, 0.2):
        rng = np.random.default_rng(5)
        items = [(tr.t, tr.true_xy + gnss_errors(tr.t, 3.0, rng, white_share=white)[0], None)
                 for tr in tracks]
        est[white] = m.estimate_error_corr([(np.unique(t, return_index=True)[0],
                                             xy[np.unique(t, return_index=True)[1]], None)
                                            for t, xy, _ in items])
    assert est[1.0] < 0.15 and est[0.2] > 0.5, est


def test_a_crawling_car_keeps_its_progress_along_the_road(full):
    """A car creeping along a street at 1 m/s with fixes every 5 s (σ 3 m: consecutive fixes
    within the noise of each other, one run): its matched positions follow it along the road
    (a constant speed fitted to the run), not one point for all."""
    g = read_match_roads(packaged_map("kotka_karhula"))
    k = int(np.argmax(g.seg_len))
    a, b = g.xy[g.seg_u[k]], g.xy[g.seg_v[k]]
    true = a + (b - a) * (np.arange(12) * 5.0 / g.seg_len[k])[:, None]
    xy = true + np.random.default_rng(4).normal(0, 3.0, true.shape)
    r = HmmMatcher(g, sigma=3.0).match(np.arange(12) * 5.0, xy)
    err = np.hypot(*(r.xy - true).T)
    assert np.sqrt(np.mean(err ** 2)) < 3.0 and np.ptp(r.along) > 40.0, (err, r.along)


def test_a_standing_car_outweighs_one_multipath_fix_before_it():
    """Track car0114 of the Helsinki real-like fleet, seed 3 (simulated): a 2.4 m fix 108 m off
    (multipath), then three fixes of the car standing where it is. As one epoch each, the
    outlier and the standing car were equally likely to be the track's outlier, and all four
    fixes were put 100 m off by the outlier. A standing car's epoch is an outlier only if all
    its fixes are: the car is matched where it stands, the outlier on its way in, unflagged."""
    g = read_match_roads(packaged_map("helsinki_centre"))
    xy = np.array([[-264.8, -162.5], [-334.8, -86.4], [-337.6, -87.9], [-337.0, -86.1]])
    car = np.array([-339.1, -83.4])
    t = np.array([0.0, 9.0, 16.0, 25.0])
    for sigma in (2.4, 4.0):
        r = HmmMatcher(g, sigma=sigma).match(t, xy)
        off = np.hypot(*(r.xy - car).T)
        assert np.all(off[1:] < 3.0) and off[0] < 20.0, (sigma, off)
        assert not r.matched[0] and r.matched[1:].all()


def _l_shaped_graph():
    """An L of two-way road, (0, 0) → (200, 0) → (200, 200), and a road (0, 150)–(100, 150)
    that no route reaches (local metres)."""
    from selfnav.roads.graph import RoadGraph

    xy = [(0, 0), (200, 0), (200, 200), (0, 150), (100, 150)]
    pairs = [(0, 1), (1, 0), (1, 2), (2, 1), (3, 4), (4, 3)]
    u, v = zip(*pairs)
    return RoadGraph("L", np.radians(60.5), np.radians(27.0), np.arange(5), xy, u, v,
                     [1, 1, 2, 2, 3, 3], ["residential"] * 6, [13.9] * 6)


def test_points_along_route_are_at_their_share_of_its_length():
    """Analytic: from 150 m along the first leg to 50 m up the second, a 100 m route: 40 % of
    it is 190 m along the first leg, 60 % 10 m up the second; none to an unreachable road."""
    from selfnav.roads.routes import points_along_route

    g = _l_shaped_graph()
    xy, seg, along = points_along_route(g, 0, 150.0, 2, 50.0, [0.0, 0.4, 0.6, 1.0])
    np.testing.assert_allclose(xy, [[150, 0], [190, 0], [200, 10], [200, 50]], atol=1e-9)
    assert list(seg) == [0, 0, 2, 2] and np.allclose(along, [150, 190, 10, 50])
    xy, seg, _ = points_along_route(g, 0, 20.0, 0, 80.0, [0.5])           # one segment
    np.testing.assert_allclose(xy, [[50, 0]])
    assert points_along_route(g, 0, 150.0, 4, 10.0, [0.5]) is None
    assert points_along_route(g, 0, 150.0, 3, 150.0, [0.5], limit=150.0) is None  # 200 m
    xy, _, _ = points_along_route(g, 0, 150.0, 3, 150.0, [0.5], limit=250.0)   # up and back
    np.testing.assert_allclose(xy, [[200, 150]])                 # 200 of its 400 m


def test_a_multipath_fix_matched_off_the_route_is_put_on_its_neighbours_route():
    """A fix 100 m off, matched 50 m away to a road its neighbours' route never takes (the chain broke
    at it): it goes onto the route between its neighbours at its time's share (8 of 20 s:
    40 % of the 100 m), the breaks close; a good fix and an outlier without a route stay."""
    from selfnav.roads.fixes import outliers_on_route

    g = _l_shaped_graph()
    t = np.array([0.0, 8.0, 20.0])
    fix = np.array([[150.0, 1.0], [60.0, 100.0], [199.0, 50.0]])
    point = np.array([[150.0, 0.0], [60.0, 150.0], [200.0, 50.0]])
    seg, along = np.array([0, 4, 2]), np.array([150.0, 40.0, 50.0])
    restart, mp = np.array([True, True, True]), np.array([0.99, 0.5, 0.9])
    p, s, a, q, r, placed = outliers_on_route(t, t, fix, point, seg, along, mp,
                                              np.full(3, 3.0), restart, np.array([0, 3]), g)
    np.testing.assert_allclose(p[1], [190.0, 0.0])
    assert s[1] == 0 and a[1] == pytest.approx(190.0)
    assert list(placed) == [False, True, False] and list(r) == [True, False, False]
    assert list(q) == [0.99, 0.9, 0.9]                  # as sure as the less sure neighbour
    # the next fix on the unreachable road: no route, nothing moves
    seg2, point2 = np.array([0, 4, 5]), point.copy()
    point2[2] = (10.0, 150.0)
    p, _, _, q, r, placed = outliers_on_route(
        t, t, np.array([[150.0, 1.0], [60.0, 60.0], [10.0, 151.0]]), point2, seg2, along, mp,
        np.full(3, 3.0), restart, np.array([0, 3]), g)
    assert not placed.any() and np.array_equal(p, point2) and r.all()
    assert np.array_equal(q, mp)
