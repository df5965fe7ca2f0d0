"""Scenarios and ``selfnav simulate`` (issue 3): files, determinism, outliers, aircraft."""
import json

import numpy as np
import pytest

from selfnav import attitude as att
from selfnav.cli import main
from selfnav.io.csvio import read_table
from selfnav.io.readers import read_imu
from selfnav.sim import scenarios as sc
from selfnav.sim.aircraft import aircraft_trajectory
from selfnav.io.trajectory import read_truth


@pytest.mark.parametrize("name", sc.BUILTIN)
def test_builtin_scenarios_write_labelled_files(name, tmp_path):
    out = tmp_path / name
    assert main(["simulate", name, "--out", str(out), "--seed", "3", "--duration", "60",
                 "--json"]) == 0
    imu = read_imu(out / "imu.csv")
    assert open(out / "imu.csv").readline().startswith("# simulated")
    assert open(out / "truth.csv").readline().startswith("# simulated")
    truth = read_truth(out / "truth.csv")
    assert imu.t[0] > truth.t[0] - 1e-9 and imu.t[-1] <= truth.t[-1] + 1e-9
    assert abs(imu.dt - sc.load_scenario(name)["scenario"]["dt"]) < 1e-9   # 0.005: rover, drone
    if name in ("car", "ship", *sc.PLATFORMS):
        assert imu.mag_b is not None and (out / "mag.csv").is_file()
    if name == "car":
        assert (out / "kotka_karhula.osm.pbf").is_file()
        assert "OpenStreetMap" in (out / "MAP_ATTRIBUTION.txt").read_text()
    if (out / "gnss.csv").is_file():
        g = read_table(out / "gnss.csv", ("t", "lat_deg", "lon_deg", "h_m", "sigma_m"))
        assert open(out / "gnss.csv").readline().startswith("# simulated")
        assert "outlier" not in open(out / "gnss.csv").read()[-2000:]   # unflagged
        assert np.all(g["sigma_m"] > 0) and np.all(np.abs(g["lat_deg"]) < 90)


def test_same_seed_same_files_other_seed_other_files(tmp_path, capsys):
    names = ("imu.csv", "gnss.csv", "truth.csv", "mag.csv", "gnss_errors.csv")
    for d, seed in (("a", "5"), ("b", "5"), ("c", "6")):
        assert main(["simulate", "car", "--out", str(tmp_path / d), "--seed", seed,
                     "--duration", "90", "--json"]) == 0
    capsys.readouterr()
    for n in names:
        assert (tmp_path / "a" / n).read_bytes() == (tmp_path / "b" / n).read_bytes(), n
        assert (tmp_path / "a" / n).read_bytes() != (tmp_path / "c" / n).read_bytes(), n


def test_toml_scenario_outliers_where_the_file_says(tmp_path, capsys):
    toml = tmp_path / "flight.toml"
    toml.write_text("""
[scenario]
kind = "aircraft"
duration = 400.0
dt = 0.02
lat_deg = 55.75
lon_deg = 37.62
h_m = 300.0
[imu]
grade = "perfect"
[gnss]
rate_hz = 5
sigma_m = 4.0
outliers = [{start = 0.0, duration = 120.0, sigma_m = 200.0, kind = "gm", tau = 30.0},
            {start = 250.0, duration = 60.0, sigma_m = 200.0, kind = "white"}]
outages = [[200.0, 230.0]]
""")
    out = tmp_path / "o"
    assert main(["simulate", str(toml), "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["scenario"] == "flight" and res["grade"] == "perfect"
    assert [(w["start_s"], w["end_s"], w["kind"]) for w in res["outlier_windows"]] == [
        (0.0, 120.0, "gm"), (250.0, 310.0, "white")]
    e = read_table(out / "gnss_errors.csv", ("t", "err_e_m", "err_n_m", "outlier"))
    t = e["t"]
    np.testing.assert_array_equal(e["outlier"] == 1, (t < 120.0) | ((t >= 250) & (t < 310)))
    assert not np.any((t >= 200) & (t < 230))
    clean = e["outlier"] == 0
    assert np.sqrt(np.mean(e["err_e_m"][clean] ** 2)) < 6.0
    assert np.sqrt(np.mean(e["err_e_m"][~clean] ** 2)) > 60.0
    # perfect IMU: the written rates are the exact inverse strapdown values
    sim = sc.simulate(str(toml))
    np.testing.assert_array_equal(sim.imu.omega_ib_b, sim.imu_exact.omega_ib_b)


def test_simulate_in_memory_determinism_and_stream_independence():
    a = sc.simulate("static", seed=1, duration=30.0)
    b = sc.simulate("static", seed=1, duration=30.0)
    np.testing.assert_array_equal(a.imu.omega_ib_b, b.imu.omega_ib_b)
    np.testing.assert_array_equal(a.gnss.lat, b.gnss.lat)
    # changing the GNSS σ leaves the IMU noise untouched (separate random streams)
    c = sc.simulate({"scenario": {"kind": "static"}, "gnss": {"sigma_m": 1.0}}, seed=1,
                    duration=30.0)
    np.testing.assert_array_equal(a.imu.omega_ib_b, c.imu.omega_ib_b)
    assert not np.array_equal(a.gnss.lat, c.gnss.lat)


@pytest.mark.parametrize("grade", ["consumer", "industrial"])
def test_the_recorded_imu_errors_rebuild_the_measured_rates(grade):
    # the errors a simulation records (the truth a filter's sensor states are checked against,
    # benchmarks/roadnav_nees.py): exact rates through T, plus the turn-on bias, the
    # Gauss–Markov and random-walk processes, leave only the white noise of the grade
    from selfnav.sensors import imu_grade

    sim = sc.simulate({"scenario": {"kind": "static"}, "imu": {"grade": grade}}, seed=4,
                      duration=60.0)
    c = sim.imu_errors["gyro"]
    rebuilt = sim.imu_exact.omega_ib_b @ c["matrix"].T + c["bias"]
    for key in ("gauss_markov", "random_walk"):
        if key in c:
            rebuilt = rebuilt + c[key]
    white = imu_grade(grade).gyro.white / np.sqrt(sim.imu.dt)
    resid = sim.imu.omega_ib_b - rebuilt
    assert np.all(np.abs(resid.std(axis=0) / white - 1.0) < 0.05)
    assert np.all(np.abs(resid.mean(axis=0)) < 5 * white / np.sqrt(len(resid)))
    assert ("random_walk" in c) == (grade == "industrial")


def test_car_scenario_follows_the_driven_path():
    """The spline truth stays on the car's analytic path (the road centre line with corner arcs)."""
    sim = sc.simulate({"scenario": {"kind": "car", "truth_hz": 0}}, seed=2, duration=120.0,
                      grade="perfect")
    route = sim.route
    g = route.graph
    # positions at the trajectory samples = the car model's own (exact) positions
    lat, lon = g.to_geodetic(route.xy[:, 0], route.xy[:, 1])
    n = min(len(lat), len(sim.truth))
    R = 6.37e6
    d = np.hypot((sim.truth.lat[:n] - lat[:n]) * R,
                 (sim.truth.lon[:n] - lon[:n]) * R * np.cos(lat[:n]))
    assert d.max() < 1e-6
    sp = np.linalg.norm(sim.truth.velocity_n[:n], axis=1)
    np.testing.assert_allclose(sp, route.speed[:n], atol=0.02)   # spline vs piecewise motion


def test_aircraft_climbs_and_turns_coordinated():
    tr = aircraft_trajectory(900.0, 0.05, np.radians(50.0), np.radians(30.0), 500.0)
    roll, pitch, heading = att.euler_from_dcm_nb(tr.C_nb)
    assert tr.h[int(0.36 * len(tr))] - tr.h[0] > 500.0          # climbed (4° at ~65 m/s)
    i0, i1 = int(0.39 * len(tr)), int(0.62 * len(tr))
    dh = np.degrees(np.unwrap(heading)[i1] - np.unwrap(heading)[i0])
    assert 160.0 < dh < 200.0                                   # about a half turn, right
    v = np.linalg.norm(tr.velocity_n, axis=1)
    rate = np.gradient(np.unwrap(heading), tr.t)
    np.testing.assert_allclose(np.tan(roll), v * rate / 9.81, atol=2e-3)
    assert np.all(np.abs(np.degrees(roll)) < 30.0)


def test_bad_inputs_are_one_line_errors(tmp_path, capsys):
    assert main(["simulate", "nosuch", "--out", str(tmp_path / "x")]) == 2
    assert main(["simulate", "car", "--out", str(tmp_path / "x"), "--grade", "bogus"]) == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario\nkind=1")
    assert main(["simulate", str(bad), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.count("selfnav: error:") == 3 and "Traceback" not in err
