"""Tightly coupled INS/GNSS (selfnav.ins.tight; issue 23, part 3).

The real PSINS record (200 Hz IMU + GPS pseudoranges, Doppler, ephemerides; no independent
truth) checks the start at rest, agreement with the receiver's own least-squares fixes and
causality; SIMULATED car drives (labelled so) check the error against the truth, error/σ, a
receiver clock jump and three satellites for 60 s against the INS alone.
"""
import warnings
from dataclasses import replace

import numpy as np
import pytest

from selfnav.earth import enu_offset, enu_rotation, geodetic_to_ecef
from selfnav.gnss.raw import C_LIGHT, RawSppConfig, spp_raw
from selfnav.ins.config import FilterConfig
from selfnav.ins.ekf import InsGnssFilter
from selfnav.ins.tight import TightInsConfig, run_tight_ins
from selfnav.io.psins_gnss import read_psins_gnss
from selfnav.io.readers import read_imu
from selfnav.sim.faults import only_satellites
from selfnav.sim.satellites import SatSimConfig, simulate_raw_drive
from selfnav.types import ImuData


@pytest.fixture(scope="module")
def psins(shared_data):
    p = shared_data / "psins_insgpseo_tc" / "insgpseo_tc.mat"
    if not p.exists():
        pytest.skip("PSINS insgpseo_tc.mat not in ../shared/data")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return p, read_imu(p), read_psins_gnss(p)


def _run(imu, raw, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_tight_ins(imu, raw, TightInsConfig(**kw))


def test_the_clock_state_carries_the_bias_by_its_drift():
    """Two clock states: over T s with no measurement, var(b) grows by T² var(ḃ) plus the
    random walks (an analytic case)."""
    cfg = FilterConfig.for_grade("tactical", receiver_clock=True, time_offset=False)
    flt = InsGnssFilter(cfg, 0.0, 0.6, 0.5, 100.0, np.zeros(3), np.eye(3))
    i = flt.layout.clk.start
    st = cfg.states
    flt.rx_drift = 2.0
    T = 5.0
    flt.propagate_covariance(T)
    assert flt.rx_clock == pytest.approx(2.0 * T)
    # sub-steps add the random walks; the shear over the whole span
    expect_b = st.receiver_clock_sigma**2 + st.receiver_clock_rw**2 * T
    expect_d = st.receiver_drift_sigma**2 + st.receiver_drift_rw**2 * T
    assert flt.P[i + 1, i + 1] == pytest.approx(expect_d)
    assert flt.P[i, i] == pytest.approx(expect_b + T**2 * expect_d, rel=1e-9)
    assert flt.P[i, i + 1] == pytest.approx(T * expect_d)


def test_the_pseudorange_jacobian_matches_a_finite_difference(psins):
    """∂ρ/∂δr (ENU) of :class:`Pseudoranges` against moving the INS by 1 m East / North / Up."""
    from selfnav.ins.measurements import Pseudoranges

    cfg = FilterConfig.for_grade("tactical", receiver_clock=True, time_offset=False)
    lat, lon, h = np.radians(34.0256), np.radians(108.7617), 406.0
    flt = InsGnssFilter(cfg, 0.0, lat, lon, h, np.zeros(3), np.eye(3))
    r0 = geodetic_to_ecef(lat, lon, h)
    up = enu_rotation(lat, lon).T
    sat = r0 + np.array([[1e7, 2e7, 1.5e7], [-2e7, 0.5e7, 1.8e7], [0.3e7, -2.1e7, 1.2e7]]) @ up.T
    m = Pseudoranges(0.0, np.zeros(3), sat, np.ones(3)).model(flt)
    for axis in range(3):
        d = np.zeros(3)
        d[axis] = 1.0
        moved = r0 + up @ d
        num = np.linalg.norm(sat - moved, axis=1) - np.linalg.norm(sat - r0, axis=1)
        assert np.allclose(m.H[:, axis], num, atol=2e-3)
    assert np.all(m.H[:, flt.layout.clk.start] == 1.0)


def test_psins_record_starts_at_rest_and_follows_its_fixes(psins):
    """Real record: the start at rest gyrocompasses (a FOG-class IMU), then the rows stay
    within 0.5 m RMS (2 m at most) of the receiver's own least-squares fix of each epoch (no
    truth: the fixes, with 0.2 m residuals, are the reference), under 2 % of the satellites
    excluded (none with the defaults; 8 of 609 with the clock noise learnt)."""
    path, imu, raw = psins
    r = _run(imu, raw)
    assert r.start["method"].startswith("at rest")
    assert r.stats["excluded"] <= 0.02 * (r.n_used.sum() + r.n_excluded.sum())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = spp_raw(raw, RawSppConfig(smoothing_s=0.0)).spp
    k = np.searchsorted(s.t, r.t)
    d = enu_offset(s.lat[k], s.lon[k], s.h[k], r.lat, r.lon, r.h)
    eh = np.hypot(d[:, 0], d[:, 1])
    assert len(r.t) > 80
    assert np.sqrt(np.mean(eh**2)) < 0.5
    assert eh.max() < 2.0


def test_psins_record_is_causal(psins):
    """Cut the IMU and the observations at T: the rows up to T are those of the whole record."""
    path, imu, raw = psins
    full = _run(imu, raw)
    T = full.t[0] + 60.0
    m = imu.t <= T
    cut_imu = ImuData(imu.t[m], imu.omega_ib_b[m], imu.f_ib_b[m], source=imu.source)
    cut_raw = replace(raw, obs=raw.obs.select(raw.obs.t <= T))
    part = _run(cut_imu, cut_raw)
    n = np.searchsorted(full.t, T, side="right")
    assert len(part.t) == n
    d = enu_offset(full.lat[:n], full.lon[:n], full.h[:n], part.lat, part.lon, part.h)
    assert np.abs(d).max() < 1e-3


def test_a_receiver_drift_moves_the_least_squares_fix_as_asked(psins):
    """``sim.faults.receiver_drift`` (an oracle for the drift tests): 0.5 m/s North for 40 s,
    held — the receiver's own least-squares fixes move 20 m North, within 0.5 m."""
    from selfnav.sim.faults import receiver_drift

    path, imu, raw = psins
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        clean = spp_raw(raw, RawSppConfig(smoothing_s=0.0)).spp
        ref = (float(np.nanmedian(clean.lat)), float(np.nanmedian(clean.lon)),
               float(np.nanmedian(clean.h)))
        moved = spp_raw(receiver_drift(raw, imu.t[0] + 85.0, 40.0, 0.5, (0, 1, 0), ref),
                        RawSppConfig(smoothing_s=0.0)).spp
    k = np.flatnonzero(clean.t >= imu.t[0] + 130.0)
    d = enu_offset(clean.lat[k], clean.lon[k], clean.h[k], moved.lat[k], moved.lon[k],
                   moved.h[k])
    assert np.allclose(np.median(d, axis=0), [0.0, 20.0, 0.0], atol=0.5)


@pytest.mark.filterwarnings("ignore::selfnav.errors.SelfnavWarning")
def test_a_car_constraint_the_imu_refuses_is_not_forced(psins):
    """Real record: its IMU's y axis is 90° off the car's motion. With ``platform="car"`` the
    non-holonomic constraint is refused by its χ² test (it had taken the rows 11 m off) and
    the rows stay as without it; with the mounting given (``--imu-mount 0,0,90``) it is taken."""
    path, imu, raw = psins
    r = _run(imu, raw, platform="car")
    assert r.stats["nhc_refused"] > 500
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = spp_raw(raw, RawSppConfig(smoothing_s=0.0)).spp
        mounted = read_imu(path, axes="RFU", mount="0,0,90")
    k = np.searchsorted(s.t, r.t)
    d = enu_offset(s.lat[k], s.lon[k], s.h[k], r.lat, r.lon, r.h)
    assert np.sqrt(np.mean(d[:, 0] ** 2 + d[:, 1] ** 2)) < 0.5
    r2 = _run(mounted, raw, platform="car")
    assert r2.stats["nhc_refused"] < 10


@pytest.mark.filterwarnings("ignore::selfnav.errors.SelfnavWarning")
def test_cli_navigates_the_psins_record_tightly(psins, tmp_path):
    from typer.testing import CliRunner

    from selfnav.cli import app
    from selfnav.solution import read_solution

    path, _, _ = psins
    out, log = tmp_path / "tc.csv", tmp_path / "sats.csv"
    res = CliRunner().invoke(app, ["navigate", "--gnss-raw", str(path), "--imu", str(path),
                                   "--out", str(out), "--fix-log", str(log)])
    assert res.exit_code == 0, res.output
    assert "tightly coupled INS" in res.output
    sol = read_solution(out)
    assert len(sol) > 80
    rows = log.read_text().splitlines()
    assert rows[0] == "t,sat,z,status,clock_jump_m"
    assert len(rows) - 1 == int(sol.columns["n_sats"].sum() + sol.columns["n_excluded"].sum())


# ---------------------------------------------------------------- SIMULATED drives
def simulated_drive(seed, grade="industrial", duration=300.0):
    """SIMULATED car (the built-in scenario) with simulated GPS + Galileo along its truth."""
    cfg = SatSimConfig(seed=seed)
    tr, raw, imu = simulate_raw_drive("car", seed=seed, grade=grade, duration=duration, cfg=cfg)
    return tr, raw, imu, cfg.t0


def horizontal_error(r, tr, t0):
    tt = r.t - t0
    la, lo, hh = (np.interp(tt, tr.t, x) for x in (tr.lat, tr.lon, tr.h))
    d = enu_offset(la, lo, hh, r.lat, r.lon, r.h)
    return tt, np.hypot(d[:, 0], d[:, 1]), np.hypot(r.sigma_enu[:, 0], r.sigma_enu[:, 1])


def partial_sky(raw, t0, a, b, n):
    return replace(raw, obs=only_satellites(raw.obs, t0 + a, t0 + b, n))


@pytest.fixture(scope="module")
def drive11():
    return simulated_drive(11)


def test_simulated_car_error_and_sigma(drive11):
    """SIMULATED: industrial MEMS, a start in motion (no gyrocompass): RMS under 1.5 m,
    error/σ RMS near 1."""
    tr, raw, imu, t0 = drive11
    r = _run(imu, raw, grade="industrial")
    assert r.start["method"].startswith("in motion")
    tt, eh, sh = horizontal_error(r, tr, t0)
    assert np.sqrt(np.mean(eh**2)) < 1.5
    assert 0.5 < np.sqrt(np.mean((eh / sh) ** 2)) < 1.6


def test_three_satellites_for_a_minute_beat_the_ins_alone(drive11):
    """SIMULATED: 60 s with three satellites: the error stays under half that of the same
    filter with none (what a loosely coupled filter, with no fix, has)."""
    tr, raw, imu, t0 = drive11
    a, b = 150.0, 210.0
    worst = {}
    for n in (3, 0):
        r = _run(imu, partial_sky(raw, t0, a, b, n), grade="industrial")
        tt, eh, sh = horizontal_error(r, tr, t0)
        w = (tt >= a) & (tt < b)
        worst[n] = eh[w].max()
        assert np.sqrt(np.mean((eh[w] / sh[w]) ** 2)) < 2.0
    assert worst[0] > 5.0
    assert worst[3] <= 0.5 * worst[0]


def test_a_second_constellation_with_its_own_clock_offset_is_used():
    """SIMULATED: Galileo 25 m late against GPS in the receiver: the offset is a state (found
    within 1 m), the clean error as without it, and both constellations are used."""
    from selfnav.io.gnss_raw import GALILEO

    cfg = SatSimConfig(seed=11, system_offset_m={GALILEO: 25.0})
    tr, raw, imu = simulate_raw_drive("car", seed=11, grade="industrial", cfg=cfg)
    r = _run(imu, raw, grade="industrial")
    assert r.stats["systems"] == "GE"
    assert r.stats["inter_system_m"]["E"] == pytest.approx(25.0, abs=1.0)
    assert np.median(r.n_used) > 12           # GPS and Galileo satellites together
    tt, eh, sh = horizontal_error(r, tr, cfg.t0)
    assert np.sqrt(np.mean(eh[tt > 30] ** 2)) < 1.0
    assert 0.5 < np.sqrt(np.mean((eh / sh) ** 2)) < 1.6


def test_a_cars_constraints_hold_three_satellites_closer(drive11):
    """SIMULATED: with ``platform="car"`` (non-holonomic, level road) the 60 s with three
    satellites stay within half the error of the unconstrained filter with none."""
    tr, raw, imu, t0 = drive11
    a, b = 150.0, 210.0
    worst = {}
    for n, platform in ((3, "car"), (0, "auto")):
        r = _run(imu, partial_sky(raw, t0, a, b, n), grade="industrial", platform=platform)
        tt, eh, sh = horizontal_error(r, tr, t0)
        w = (tt >= a) & (tt < b)
        worst[n] = eh[w].max()
        if n == 3:
            assert r.stats["nhc_refused"] < 0.05 * 3000
            assert np.sqrt(np.mean((eh[w] / sh[w]) ** 2)) < 1.6
    assert worst[3] <= 0.5 * worst[0]


def test_the_mixture_option_takes_reflections_for_what_they_are():
    """SIMULATED street (buildings 20 m high and 20 m apart, half the hidden satellites
    reflected, 20 m late on average), industrial IMU, seed 107: with the mixture of line of
    sight and delayed components (opt-in) the error is a third of the plain filter's, and
    some satellites are called delayed."""
    from selfnav.sim.satellites import StreetCanyon

    cfg = SatSimConfig(seed=107, canyon=StreetCanyon(azimuth_deg=30.0, width_m=20.0,
                                                     height_m=20.0, p_nlos=0.5,
                                                     nlos_bias_m=20.0))
    tr, raw, imu = simulate_raw_drive("car", seed=107, grade="industrial", cfg=cfg)
    rms = {}
    for mix in (False, True):
        r = _run(imu, raw, grade="industrial", mixture=mix)
        tt, eh, _ = horizontal_error(r, tr, cfg.t0)
        rms[mix] = np.sqrt(np.mean(eh[tt > 30] ** 2))
    assert rms[True] < 0.35 * rms[False]
    assert sum(len(d.delayed) for d in r.decisions) > 0


def test_a_receiver_clock_jump_is_taken_by_the_clock(drive11):
    """SIMULATED: a 1 ms step of the receiver clock (300 km on every pseudorange, as u-blox
    receivers do) moves the clock, not the position."""
    tr, raw, imu, t0 = drive11
    o = raw.obs
    pr = o.pseudorange.copy()
    pr[o.t - t0 >= 120.0] += 1e-3 * C_LIGHT
    o2 = replace(o)
    o2.pseudorange = pr
    r = _run(imu, replace(raw, obs=o2), grade="industrial")
    assert r.stats["clock_jumps"] >= 1
    tt, eh, _ = horizontal_error(r, tr, t0)
    assert np.sqrt(np.mean(eh**2)) < 1.5
