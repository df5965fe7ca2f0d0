"""Seed 004 navigator (issue 5): runs end to end on a simulated drive (labelled so)."""
import numpy as np
import pytest

from selfnav import datum as dm
from selfnav.types import GnssData
from selfnav.roads.graph import read_roads
from selfnav.seed004 import SeedConfig, _tukey, identify, road_points, run_seed
from selfnav.sim.scenarios import simulate


@pytest.fixture(scope="module")
def drive():
    spec = {"scenario": {"kind": "car", "duration": 90.0, "map": "helsinki_centre", "dt": 0.01},
            "imu": {"grade": "consumer"}, "mag": {"enabled": True},
            "gnss": {"outliers": [], "spike_rate": 0.0, "datum": "pz90"}}
    sim = simulate(spec, seed=2)
    return sim, read_roads(sim.map_path)


def test_tukey_is_bounded():
    r = np.array([0.0, 1.0, 3.0, 10.0, 1e4])
    v = _tukey(r, 3.0)
    assert v[0] == 0 and np.all(np.diff(v) >= 0)
    assert v[-1] == pytest.approx(1.5) and v[-2] == pytest.approx(1.5)


def test_identification_ignores_a_far_outlier(drive):
    _, g = drive
    pts, _, hd = road_points(g, g.xy[g.seg_u[10]], 25.0, 0.5)
    pred = pts[len(pts) // 2]
    cfg = SeedConfig()
    j0, _ = identify(pts, hd, pred, np.zeros((0, 2)), None, cfg, 0.5)
    j1, _ = identify(pts, hd, pred, (pred + [400.0, -300.0])[None], None, cfg, 0.5)
    assert j0 == j1


def test_pz90_fixes_in_output_on_the_roads(drive):
    """The seed's own case: GNSS in PZ-90 in; every output point lies on a road centre line."""
    sim, g = drive
    f = sim.gnss
    gd = f.as_gnss(source="pz90")
    res = run_seed(sim.imu, gd, g, SeedConfig(), gnss_datum="pz90")
    tr = res.trajectory
    assert len(tr.t) > 40 and res.stats["k_m"] == 100
    x, y = g.to_local(tr.lat, tr.lon)
    c = g.candidates(np.column_stack([x, y]), 2.0, k=1, per_way=False)
    assert len(np.unique(c.query)) == len(tr.t)
    assert np.all(np.isfinite(tr.velocity_n))
    # SK-42 output through the datum module round-trips
    la, lo, h = dm.convert(tr.lat, tr.lon, tr.h, "wgs84", "sk42")
    la2, lo2, _ = dm.convert(la, lo, h, "sk42", "wgs84")
    assert np.max(np.abs(la2 - tr.lat)) < 1e-9


def test_mht_matcher_runs(drive):
    sim, g = drive
    f = sim.gnss
    lat, lon, h = dm.convert(f.lat, f.lon, f.h, "pz90", "wgs84")
    gd = GnssData(f.t, lat, lon, h, f.sigma_m, None, None, "wgs84")
    res = run_seed(sim.imu, gd, g, SeedConfig(matcher="mht"))
    assert res.stats["matcher"] == "mht" and len(res.trajectory.t) > 40


def test_cli_navigate_seed_writes_sk42(drive, tmp_path, capsys):
    import json

    from selfnav.cli import main
    from selfnav.io.csvio import read_table
    from selfnav.sim.scenarios import write_simulation

    sim, _ = drive
    write_simulation(sim, tmp_path)
    out = tmp_path / "sol.csv"
    args = ["navigate", "--imu", str(tmp_path / "imu.csv"), "--gnss", str(tmp_path / "gnss.csv"),
            "--gnss-datum", "pz90", "--method", "seed", "--out", str(out), "--out-datum", "sk42",
            "--json"]
    assert main(args) != 0                     # no map: a one-line error, no traceback
    capsys.readouterr()
    assert main(args + ["--map", str(sim.map_path)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["method"] == "seed" and summary["epochs"] > 40
    tab = read_table(out, ("t", "lat_deg", "lon_deg", "h_m"))
    # SK-42 differs from WGS-84 by ~100 m around Helsinki: the file is not WGS-84
    la, lo, _ = dm.convert(np.radians(tab["lat_deg"]), np.radians(tab["lon_deg"]), tab["h_m"],
                           "sk42", "wgs84")
    x, y = read_roads(sim.map_path).to_local(la, lo)
    c = read_roads(sim.map_path).candidates(np.column_stack([x, y]), 3.0, k=1, per_way=False)
    assert len(np.unique(c.query)) == len(la)
