"""Tightly coupled odometry + pseudorange filter (selfnav.gnss.tight; issue 23, part 3).

Simulated drives (labelled so) check the filter in its own model's world — any start heading,
delayed signals given their own component, two or three satellites still used, error/σ near
1 —; the real smartLoc record checks the figures of docs/gnss.md and causality (cut the file at
T, compare the past).
"""
from dataclasses import replace

import numpy as np
import pytest

from selfnav.earth import ecef_to_enu, enu_rotation, geodetic_to_ecef
from selfnav.gnss.models import pseudorange_model
from selfnav.gnss.odometry import dead_reckon
from selfnav.gnss.guard import GuardConfig
from selfnav.gnss.tight import MixtureModel, TightConfig, run_tight
from selfnav.io.smartloc import (Odometry, Pseudoranges, find_smartloc_files,
                                 read_smartloc_input, read_smartloc_truth)

DT = 0.2
ORIGIN = (np.radians(52.5), np.radians(13.37), 40.0)


def sky(n=8, seed=0):
    """``n`` satellites 20,200 km up, spread in azimuth, elevations 15–75° (ECEF, fixed)."""
    rng = np.random.default_rng(seed)
    az = np.sort(rng.uniform(0, 2 * np.pi, n))
    el = rng.uniform(np.radians(15), np.radians(75), n)
    u_enu = np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
    r0 = geodetic_to_ecef(*ORIGIN)
    return r0 + (u_enu * 2.02e7) @ enu_rotation(ORIGIN[0], ORIGIN[1])


def simulated_drive(seed=0, duration=200.0, heading0_deg=30.0, sigma=3.0, sats=None,
                    visible=None, delayed=None):
    """SIMULATED car: 90° turns every 40 s, odometry with white noise, white pseudoranges of
    σ ``sigma`` (C/N0 45 dBHz) from ``sats``; ``visible(t) -> mask`` hides satellites,
    ``delayed = (sat indices, t0, t1, metres)`` adds a reflection's delay."""
    rng = np.random.default_rng(seed)
    sats = sky() if sats is None else sats
    t = np.arange(0.0, duration, DT)
    v = 8.0 + 2.0 * np.sin(2 * np.pi * t / 90.0)
    w = np.zeros_like(t)
    for t0 in np.arange(20.0, duration, 40.0):
        w[(t >= t0) & (t < t0 + 10.0)] = (1 if int(t0 / 40) % 2 else -1) * np.pi / 20.0
    truth = dead_reckon(t, v, w, (0.0, 0.0, np.radians(heading0_deg), 1.0, 0.0))
    enu = np.column_stack([truth[:, 0], truth[:, 1], np.zeros(len(t))])
    r = geodetic_to_ecef(*ORIGIN) + enu @ enu_rotation(ORIGIN[0], ORIGIN[1])
    clock = 1.0e5 - 40.0 * t
    rows = []
    for k in range(len(t)):
        m = np.ones(len(sats), bool) if visible is None else visible(t[k])
        for i in np.flatnonzero(m):
            rho, _ = pseudorange_model(r[k], clock[k], sats[i])
            e = rng.normal(0.0, sigma)
            if delayed is not None and i in delayed[0] and delayed[1] <= t[k] < delayed[2]:
                e += delayed[3]
            rows.append((t[k], rho + e, i))
    rows = np.array(rows)
    n = len(rows)
    idx = rows[:, 2].astype(int)
    prs = Pseudoranges(rows[:, 0], rows[:, 1], np.full(n, sigma ** 2), sats[idx], idx + 1,
                       np.ones(n, int), np.full(n, np.radians(45.0)), np.full(n, 45.0),
                       "simulated")
    odo = Odometry(t, np.column_stack([v + rng.normal(0, 0.05, len(t)), np.zeros((len(t), 2))]),
                   np.column_stack([np.zeros((len(t), 2)), w + rng.normal(0, 0.002, len(t))]),
                   np.tile([0.0025, 0, 0, 0, 0, 4e-6], (len(t), 1)), "simulated")
    return prs, odo, t, truth


def errors(r, t, truth):
    """Horizontal errors in the filter's own tangent plane (at its first fix, not ORIGIN)."""
    enu = np.column_stack([truth[:, 0], truth[:, 1], np.zeros(len(t))])
    g = ecef_to_enu(geodetic_to_ecef(*ORIGIN) + enu @ enu_rotation(ORIGIN[0], ORIGIN[1]),
                    *r.origin)
    e = np.column_stack([r.east - np.interp(r.t, t, g[:, 0]),
                         r.north - np.interp(r.t, t, g[:, 1])])
    return e, np.hypot(e[:, 0], e[:, 1])


# a model that matches the simulated world: line of sight 3 m at 45 dBHz, rare delays
SIM_MIX = MixtureModel(weights=np.tile([0.96, 0.02, 0.02], (6, 1)))


@pytest.mark.parametrize("heading0_deg", [30.0, 200.0])
def test_a_clean_simulated_drive_is_followed_from_any_start_heading(heading0_deg):
    prs, odo, t, truth = simulated_drive(heading0_deg=heading0_deg)
    r = run_tight(prs, odo, TightConfig(mixture=SIM_MIX))
    e, eh = errors(r, t, truth)
    after = r.t >= 20.0
    assert np.sqrt(np.mean(eh[after] ** 2)) < 1.5
    dh = (np.degrees(r.heading - np.interp(r.t, t, truth[:, 2])) + 180) % 360 - 180
    assert np.max(np.abs(dh[r.t >= 30.0])) < 3.0
    # a σ is a promise: error/σ per axis RMS near 1 in the filter's own world
    z = np.concatenate([e[after, 0] / r.sigma_e[after], e[after, 1] / r.sigma_n[after]])
    assert 0.5 < np.sqrt(np.mean(z ** 2)) < 1.6


def test_a_delayed_signal_gets_its_own_component_and_costs_little():
    delayed = ([1, 5], 60.0, 120.0, 40.0)
    prs, odo, t, truth = simulated_drive(seed=3, delayed=delayed)
    r = run_tight(prs, odo, TightConfig(mixture=SIM_MIX))
    _, eh = errors(r, t, truth)
    inside = (r.t >= 60.0) & (r.t < 120.0)
    assert np.max(eh[inside]) < 3.0
    hit = np.isin(prs.sat_id - 1, delayed[0]) & (prs.t >= 60.0) & (prs.t < 120.0)
    assert np.mean(r.obs_component[hit] >= 1) > 0.95
    assert np.mean(r.obs_component[~hit & (prs.t >= 20.0)] == 0) > 0.97


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_three_satellites_still_hold_the_position_where_a_fix_needs_four(seed):
    """60 s with 3 satellites in view and a yaw-rate bias of 0.1 °/s appearing as they go: no
    single-point fix, so a loosely coupled filter dead-reckons with what it had learned; the
    tight filter keeps using the three ranges — half that error or less (issue 23)."""
    few = np.zeros(8, bool)
    few[[0, 3, 6]] = True
    visible = lambda tk: few if 60.0 <= tk < 120.0 else np.ones(8, bool)  # noqa: E731
    prs, odo, t, truth = simulated_drive(seed=seed, sats=sky(8, seed=1), visible=visible)
    odo.omega_b[odo.t >= 60.0, 2] += np.radians(0.1)
    r = run_tight(prs, odo, TightConfig(mixture=SIM_MIX))
    _, eh = errors(r, t, truth)
    k0, k1 = int(np.searchsorted(r.t, 60.0)), int(np.searchsorted(r.t, 119.8))
    i0 = int(np.searchsorted(odo.t, 60.0))
    lc = dead_reckon(odo.t[i0:], odo.speed[i0:], odo.yaw_rate[i0:],
                     (r.east[k0], r.north[k0], r.heading[k0], r.scale[k0], r.yaw_bias[k0]))
    lc_r = replace(r, t=odo.t[i0:], east=lc[:, 0], north=lc[:, 1])
    _, lc_err = errors(lc_r, t, truth)
    lc_end = lc_err[int(np.searchsorted(odo.t[i0:], 119.8))]
    assert lc_end > 5.0
    assert eh[k1] <= 0.5 * lc_end
    assert np.max(eh[k0:k1]) < 5.0


@pytest.fixture(scope="module")
def berlin(shared_data):
    out = {}
    for name in ("smartloc_berlin_potsdamer_platz", "smartloc_berlin_potsdamer_platz_rtklib"):
        inp, gt = find_smartloc_files(shared_data / name)
        out[name] = (read_smartloc_input(inp), read_smartloc_truth(gt))
    return out


def _score(r, truth):
    from selfnav.sim.urban import horizontal_errors

    eh = horizontal_errors(r.t, r.east, r.north, r.origin, truth)
    return float(np.sqrt(np.mean(eh ** 2))), float(np.sqrt(np.mean((eh / r.sigma_h) ** 2)))


@pytest.mark.parametrize("name, causal_max, smooth_max", [
    # measured 7.32 / 6.06 m (libRSF 7.97 / 5.18; the targets 7.5 / 5.0)
    ("smartloc_berlin_potsdamer_platz", 7.5, 6.5),
    # measured 5.47 / 2.10 m (libRSF 4.92 / 2.42; the targets 4.5 / 2.3)
    ("smartloc_berlin_potsdamer_platz_rtklib", 5.8, 2.3)])
@pytest.mark.long
def test_berlin_potsdamer_platz_tightly_coupled(berlin, name, causal_max, smooth_max):
    (prs, odo), truth = berlin[name]
    causal = run_tight(prs, odo)
    smooth = run_tight(prs, odo, smooth=True)
    rms_c, z_c = _score(causal, truth)
    rms_s, z_s = _score(smooth, truth)
    assert rms_c <= causal_max
    assert rms_s <= smooth_max
    # the loosely coupled robust filter of docs/smartloc.md: 26.0 m; SPP 26.5–27.6 m
    assert rms_c < 0.35 * 26.0
    # σ inflated for errors correlated over epochs; not yet a promise (docs/gnss.md)
    assert 1.0 < z_c < 4.5 and 1.0 < z_s < 4.5
    # the drift guard (opt-in) never holds on the clean record
    guarded = run_tight(prs, odo, TightConfig(guard=GuardConfig()))
    assert guarded.stats["guard_episodes"] == [] and guarded.stats["held_s"] == 0.0
    assert _score(guarded, truth)[0] == pytest.approx(rms_c, abs=1e-9)


def test_the_filter_is_causal_cut_the_record_and_compare_the_past(berlin):
    (prs, odo), _ = berlin["smartloc_berlin_potsdamer_platz"]
    T = 120.0
    m = prs.t <= T
    cut_prs = Pseudoranges(*(getattr(prs, f)[m] for f in
                             ("t", "pr", "var", "sat_ecef", "sat_id", "system", "elevation",
                              "cn0")), prs.source)
    mo = odo.t <= T
    cut_odo = Odometry(odo.t[mo], odo.velocity_b[mo], odo.omega_b[mo], odo.variances[mo])
    full = run_tight(prs, odo)
    cut = run_tight(cut_prs, cut_odo)
    n = len(cut.t)
    assert n > 500 and np.array_equal(full.t[:n], cut.t)
    for f in ("east", "north", "sigma_e", "heading"):
        np.testing.assert_allclose(getattr(full, f)[:n], getattr(cut, f), rtol=0, atol=1e-9)


def _drifted(prs, t0, az_deg, r_ecef, rate=0.5, duration=120.0):
    """Every pseudorange moved as by a receiver displaced ``rate`` m/s towards ``az_deg`` from
    ``t0`` for ``duration`` s, then held (issue 23's geometry-consistent drift)."""
    u = prs.sat_ecef - r_ecef
    u /= np.linalg.norm(u, axis=1)[:, None]
    lat, lon = ORIGIN[0], ORIGIN[1]
    u_enu = u @ enu_rotation(lat, lon).T
    d = np.clip(prs.t - t0, 0.0, duration) * rate
    a = np.radians(az_deg)
    return replace(prs, pr=prs.pr - d * (u_enu[:, 0] * np.sin(a) + u_enu[:, 1] * np.cos(a)))


@pytest.mark.parametrize("seed", [0, 2, 4])
@pytest.mark.long
def test_a_drift_every_satellite_shares_is_caught_by_the_odometry(seed):
    """SIMULATED: a geometry-consistent drift (0.5 m/s for 120 s, then held) passes every
    per-satellite test and the filter follows it (~60 m); the drift branches of
    :mod:`selfnav.gnss.guard` catch it within 30 s and hold the odometry's track."""
    prs, odo, t, truth = simulated_drive(seed=seed, duration=300.0)
    t0, az = 40.0 + 20 * seed, 60.0 * seed
    bad = _drifted(prs, t0, az, geodetic_to_ecef(*ORIGIN))
    guarded = TightConfig(mixture=SIM_MIX, guard=GuardConfig())
    clean = run_tight(prs, odo, guarded)
    assert clean.stats["guard_episodes"] == []
    follow = run_tight(bad, odo, TightConfig(mixture=SIM_MIX))
    held = run_tight(bad, odo, guarded)
    _, e_follow = errors(follow, t, truth)
    _, e_held = errors(held, t, truth)
    after = held.t >= t0
    assert np.max(e_follow[after]) > 55.0
    ep = held.stats["guard_episodes"]
    assert len(ep) == 1 and 0.0 < ep[0]["start_s"] - t0 < 30.0 and ep[0]["branch_s"] <= t0
    assert np.max(e_held[after]) < 25.0


def test_a_drift_injected_into_the_real_record_is_held(berlin):
    """smartLoc Berlin (real pseudoranges) with the drift of issue 23 from 80 s towards the
    North: followed to ~62 m without the guard; held within 35 s, at most 22 m."""
    (prs, odo), truth = berlin["smartloc_berlin_potsdamer_platz_rtklib"]
    idx = np.clip(np.searchsorted(truth.t, prs.t), 0, len(truth.t) - 1)
    r = truth.ecef[idx]
    u = prs.sat_ecef - r
    u /= np.linalg.norm(u, axis=1)[:, None]
    from selfnav.earth import ecef_to_geodetic
    lat, lon, _ = ecef_to_geodetic(truth.ecef[0])
    north = (u @ enu_rotation(lat, lon).T)[:, 1]
    bad = replace(prs, pr=prs.pr - north * np.clip(prs.t - 80.0, 0.0, 120.0) * 0.5)
    follow = run_tight(bad, odo)
    held = run_tight(bad, odo, TightConfig(guard=GuardConfig()))
    from selfnav.sim.urban import horizontal_errors

    def err(res):
        return horizontal_errors(res.t, res.east, res.north, res.origin, truth)
    after = held.t >= 80.0
    assert np.max(err(follow)[after]) > 55.0
    ep = held.stats["guard_episodes"]
    assert len(ep) == 1 and ep[0]["start_s"] - 80.0 < 40.0
    assert np.max(err(held)[after]) < 25.0


def test_a_fixed_start_heading_replaces_the_bank():
    prs, odo, t, truth = simulated_drive(heading0_deg=75.0, duration=60.0)
    r = run_tight(prs, odo, replace(TightConfig(mixture=SIM_MIX)),
                  heading0=(np.radians(75.0), np.radians(2.0)))
    assert r.stats["bank_left"] == 1
    _, eh = errors(r, t, truth)
    assert np.sqrt(np.mean(eh[r.t >= 5.0] ** 2)) < 1.5


def test_navigate_gnss_raw_from_the_command_line(shared_data, tmp_path, capsys):
    import json

    from selfnav.io.csvio import read_table
    from selfnav.solution import read_solution
    from support import run_cli

    d = shared_data / "smartloc_berlin_potsdamer_platz"
    out, log = tmp_path / "sol.csv", tmp_path / "sats.csv"
    code, so, se = run_cli(["navigate", "--gnss-raw", d / "Berlin_Potsdamer_Platz_Input.txt",
                            "--out", out, "--fix-log", log, "--drift-guard", "--json"], capsys)
    assert code == 0, se
    js = json.loads(so)
    assert js["method"] == "tight" and js["epochs"] == 1372 and js["guard_episodes"] == []
    sol = read_solution(out)
    assert len(sol) == 1372 and np.all(np.isfinite(sol.columns["sigma_h_m"]))
    st = read_table(log, ("t", "residual_m"), numeric=False)
    assert len(st["t"]) == 20038
    code, so, se = run_cli(["evaluate", "--truth", d / "Berlin_Potsdamer_Platz_GT.txt",
                            "--solution", out, "--json"], capsys)
    assert code == 0 and json.loads(so)["horizontal_rms_m"] < 7.5


def test_navigate_gnss_raw_bad_combinations_are_one_line(shared_data, tmp_path, capsys):
    from support import run_cli

    android = shared_data / "android_raw_static_mtv" / "pseudoranges_log_2016_06_30_21_26_07.txt"
    code, _, se = run_cli(["navigate", "--gnss-raw", android, "--out", tmp_path / "o.csv"],
                          capsys)
    assert code == 2 and se.count("\n") == 1 and "no odometry" in se
    code, _, se = run_cli(["navigate", "--out", tmp_path / "o.csv"], capsys)
    assert code == 2 and "--imu" in se and "--gnss-raw" in se
    smart = shared_data / "smartloc_berlin_potsdamer_platz" / "Berlin_Potsdamer_Platz_Input.txt"
    code, _, se = run_cli(["navigate", "--gnss-raw", smart, "--gnss", android,
                           "--out", tmp_path / "o.csv"], capsys)
    assert code == 2 and "without --gnss" in se
    # with --imu it is the tightly coupled INS path: a file that is no IMU is named
    code, _, se = run_cli(["navigate", "--gnss-raw", smart, "--imu", android,
                           "--out", tmp_path / "o.csv"], capsys)
    assert code == 2 and se.count("\n") == 1 and android.name in se
    assert not (tmp_path / "o.csv").exists()


@pytest.mark.slow
@pytest.mark.long
def test_simulated_city_drives_beat_single_point_fixes():
    """SIMULATED city drives (selfnav.sim.urban: streets with buildings along the car,
    reflections, correlated multipath, odometry with scale and bias errors), not used while
    building the filter: the median drive's causal error a third of the SPP's or less, the
    smoother better still. The worst drives (5–8 satellites, docs/gnss.md) are not asserted."""
    from selfnav.gnss.spp import SppConfig, horizontal_error, spp_from_pseudoranges
    from selfnav.sim.urban import horizontal_errors, simulate_urban_drive

    spp, causal, smooth = [], [], []
    for seed in range(6):
        prs, odo, truth = simulate_urban_drive(seed)
        sp = spp_from_pseudoranges(prs, SppConfig(weighting="cn0"))
        spp.append(np.sqrt(np.nanmean(horizontal_error(sp, truth.t, truth.ecef) ** 2)))
        for out, sm in ((causal, False), (smooth, True)):
            r = run_tight(prs, odo, smooth=sm)
            e = horizontal_errors(r.t, r.east, r.north, r.origin, truth)
            out.append(np.sqrt(np.mean(e ** 2)))
    assert np.median(causal) < np.median(spp) / 3
    assert np.median(smooth) < np.median(causal)


def test_simulate_city_then_navigate_gnss_raw_end_to_end(tmp_path, capsys):
    """``selfnav simulate city`` writes smartLoc files that navigate --gnss-raw and evaluate
    read (SIMULATED), and the files round-trip the simulation."""
    import json

    from selfnav.io.smartloc import read_smartloc_input, read_smartloc_truth
    from selfnav.sim.urban import UrbanConfig, simulate_urban_drive
    from support import run_cli

    d = tmp_path / "city"
    code, so, se = run_cli(["simulate", "city", "--out", d, "--seed", "12", "--duration", "90",
                            "--json"], capsys)
    assert code == 0, se
    assert json.loads(so)["files"] == ["city_Input.txt", "city_GT.txt"]
    prs, odo = read_smartloc_input(d / "city_Input.txt")
    ref, ref_odo, ref_truth = simulate_urban_drive(12, replace(UrbanConfig(), duration=90.0))
    np.testing.assert_allclose(prs.pr, ref.pr, atol=1e-4)
    np.testing.assert_allclose(odo.yaw_rate, ref_odo.yaw_rate, atol=1e-8)
    np.testing.assert_allclose(read_smartloc_truth(d / "city_GT.txt").ecef, ref_truth.ecef,
                               atol=1e-4)
    out = tmp_path / "sol.csv"
    code, _, se = run_cli(["navigate", "--gnss-raw", d / "city_Input.txt", "--out", out],
                          capsys)
    assert code == 0, se
    code, so, se = run_cli(["evaluate", "--truth", d / "city_GT.txt", "--solution", out,
                            "--json"], capsys)
    assert code == 0, se
    # the command line gives what the library gives on the same files, and beats the
    # single-point fixes
    from selfnav.gnss.spp import SppConfig, horizontal_error, spp_from_pseudoranges
    from selfnav.sim.urban import horizontal_errors

    r = run_tight(prs, odo)
    e = horizontal_errors(r.t, r.east, r.north, r.origin, ref_truth)
    assert json.loads(so)["horizontal_rms_m"] == pytest.approx(np.sqrt(np.mean(e ** 2)), abs=0.01)
    sp = spp_from_pseudoranges(prs, SppConfig(weighting="cn0"))
    assert np.sqrt(np.mean(e ** 2)) < np.sqrt(np.nanmean(
        horizontal_error(sp, ref_truth.t, ref_truth.ecef) ** 2))


@pytest.mark.slow
@pytest.mark.long
def test_a_ramp_on_two_strong_satellites_is_excluded_within_10_s_in_city_drives():
    """SIMULATED city drives (σ0 1 m): the two strongest satellites at 120 s ramp at 1 m/s
    for 60 s (issue 23). Neither is used as line of sight after 10 s in any drive; the median
    drive's extra error stays below 1 m (docs/gnss.md: two of five drives then wander 4–6 m,
    the max-mixture choosing differently)."""
    from selfnav.sim.urban import horizontal_errors, simulate_urban_drive

    t0, extra = 120.0, []
    for seed in (1, 10, 12, 14, 22):
        prs, odo, truth = simulate_urban_drive(seed)
        keys = prs.system * 1000 + prs.sat_id
        at = np.abs(prs.t - t0) < 1e-6
        two = keys[at][np.argsort(-prs.cn0[at])][:2]
        hit = np.isin(keys, two) & (prs.t >= t0) & (prs.t < t0 + 60.0)
        bad = replace(prs, pr=prs.pr + np.where(hit, prs.t - t0, 0.0))
        clean, r = run_tight(prs, odo), run_tight(bad, odo)
        used_los = prs.t[hit][r.obs_component[hit] == 0]
        assert len(used_los) == 0 or used_los.max() - t0 < 10.0
        win = (r.t >= t0) & (r.t < t0 + 70.0)
        e = horizontal_errors(r.t, r.east, r.north, r.origin, truth)
        ec = horizontal_errors(clean.t, clean.east, clean.north, clean.origin, truth)
        extra.append(np.max(e[win] - ec[win]))
    assert np.median(extra) < 1.0
