"""The navigator's self-calibration (issue 10): noise at rest, time offset, velocity lag, fix
chains, the online noise scale. Simulated data (labelled simulated), known truth."""
import numpy as np
import pytest

from selfnav.earth import enu_offset, offset_to_geodetic
from selfnav.ins import FilterConfig, InsGnssFilter, calibrate
from selfnav.ins.guard import FixChain, kinematic_consistent
from selfnav.sensors import imu_grade
from selfnav.sim.scenarios import simulate
from selfnav.units import DEG


@pytest.fixture(scope="module")
def parked_drive():
    """A car parked for 40 s, then driving 6 minutes (industrial IMU, 1 Hz GNSS σ 2 m)."""
    spec = {"scenario": {"kind": "car", "duration": 400.0, "map": "kotka_karhula", "dt": 0.01},
            "motion": {"hold_start": 40.0}, "imu": {"grade": "industrial"},
            "gnss": {"sigma_m": 2.0, "rate_hz": 1.0, "spike_rate": 0.0, "outliers": []}}
    return simulate(spec, seed=5)


def test_noise_measured_at_rest_is_the_simulated_one(parked_drive):
    sim = parked_drive
    g = sim.gnss.as_gnss()
    still = calibrate.still_mask(sim.imu, g)
    t_still = sim.imu.t[still]
    assert 30.0 <= still.sum() * sim.imu.dt <= 41.0 and t_still.max() < sim.imu.t[0] + 41.0
    m = calibrate.measure_noise(sim.imu, still)
    model = imu_grade("industrial")
    # the conservative white-noise density (max over 0.3–3 s) is within 30 % above the truth
    assert model.gyro.white <= 1.3 * m.arw and m.arw <= 1.3 * model.gyro.white
    assert model.accel.white <= 1.3 * m.vrw and m.vrw <= 1.3 * model.accel.white


def test_a_cruising_car_is_not_still(parked_drive):
    """Constant-speed stretches are quiet for an IMU; the GNSS says they are not still."""
    sim = parked_drive
    still = calibrate.still_mask(sim.imu, sim.gnss.as_gnss())
    speed = np.interp(sim.imu.t, sim.truth.t, np.linalg.norm(sim.truth.velocity_n, axis=1))
    assert speed[still].max() < 0.5


@pytest.mark.parametrize("shift", [-0.25, 0.12])
def test_time_offset_from_the_gyro_heading(parked_drive, shift):
    sim = parked_drive
    g = sim.gnss.as_gnss(velocity=True)
    off, sig = calibrate.estimate_time_offset(sim.imu.shifted(shift), g)
    assert off == pytest.approx(-shift, abs=0.01)
    assert sig < 0.01


@pytest.mark.parametrize("kind", ["white", "gm"])
def test_time_offset_from_positions_survives_unflagged_outliers(parked_drive, kind):
    """Positions only (4 Hz, σ 2 cm) with 90 s of unflagged 200 m outliers: the course from
    position differences keeps only car-like velocities and the misfit is truncated, so the
    outliers cannot pull the offset (drive_0708 had moved it by 0.3 s)."""
    from selfnav.sensors import with_outliers
    from selfnav.types import GnssData

    sim = parked_drive
    t = np.arange(sim.truth.t[0], sim.truth.t[-1], 0.25)
    lat = np.interp(t, sim.truth.t, sim.truth.lat)
    lon = np.interp(t, sim.truth.t, sim.truth.lon)
    g = GnssData.from_arrays(t, lat, lon, np.zeros(len(t)), 0.02)
    g = with_outliers(g, t[0] + 150.0, 90.0, kind=kind, seed=3, velocity="drop")
    off, _ = calibrate.estimate_time_offset(sim.imu.shifted(0.15), g)
    assert off == pytest.approx(-0.15, abs=0.02)


def test_velocity_lag_is_measured_and_removed(parked_drive):
    """A 4 Hz receiver that reports the velocity 0.2 s late (precise positions)."""
    sim = parked_drive
    t = np.arange(sim.truth.t[0], sim.truth.t[-1], 0.25)
    vel_true = np.column_stack([np.interp(t, sim.truth.t, sim.truth.velocity_n[:, k])
                                for k in range(3)])
    lat = np.interp(t, sim.truth.t, sim.truth.lat)
    lon = np.interp(t, sim.truth.t, sim.truth.lon)
    late = np.column_stack([np.interp(t - 0.2, sim.truth.t, sim.truth.velocity_n[:, k])
                            for k in range(3)])
    from selfnav.types import GnssData

    g = GnssData.from_arrays(t, lat, lon, np.zeros(len(t)), 0.02, late)
    lag = calibrate.estimate_velocity_lag(g)
    assert lag == pytest.approx(0.2, abs=0.02)
    fixed = calibrate.shift_velocity(g, lag)
    moving = np.linalg.norm(vel_true, axis=1) > 1.0
    err_before = np.sqrt(np.mean((late - vel_true)[moving] ** 2))
    err_after = np.sqrt(np.mean((fixed.velocity_n - vel_true)[moving] ** 2))
    assert err_after < 0.3 * err_before


def _chain_fixes(n=120, dt=0.25, speed=12.0, sigma=0.01, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    p = np.column_stack([speed * t, 0.5 * np.sin(0.1 * t)]) + rng.normal(0, sigma, (n, 2))
    v = np.column_stack([np.full(n, speed), 0.05 * np.cos(0.1 * t)]) + rng.normal(0, 0.05, (n, 2))
    return t, p, v


def test_fix_chain_anchors_clean_fixes_and_breaks_at_a_jump_or_a_drift():
    t, p, v = _chain_fixes()
    chain = FixChain()
    anchored = [chain.add(t[k], p[k], v[k], 0.01, 0.05, True)[1] for k in range(len(t))]
    assert all(anchored[1:])
    # a 3 m jump breaks the chain at once
    chain = FixChain()
    q = p.copy()
    q[60:] += [3.0, 0.0]
    links = [chain.add(t[k], q[k], v[k], 0.01, 0.05, True)[0] for k in range(len(t))]
    assert not links[60] and all(links[60 + 21:])     # again once the 5 s window is past it
    # a drift of 0.3 m/s that the velocity does not show breaks the long link within seconds
    chain = FixChain()
    d = p.copy()
    d[40:] += np.outer(t[40:] - t[40], [0.3, 0.0])
    links = [chain.add(t[k], d[k], v[k], 0.01, 0.05, True)[0] for k in range(len(t))]
    assert not all(links[40:60])
    # a change of the receiver's quality flag (RTK fixed -> float) breaks the chain
    chain = FixChain()
    qual = np.where(np.arange(len(t)) < 50, 1, 2)
    links = [chain.add(t[k], p[k], v[k], 0.01, 0.05, True, qual[k])[0] for k in range(len(t))]
    assert all(links[1:50]) and not links[50] and links[51]
    # no velocity: never anchored
    chain = FixChain()
    assert not any(chain.add(t[k], p[k], None, 0.01, 0.05, True)[1] for k in range(10))


def test_kinematic_consistency_separates_white_outliers():
    rng = np.random.default_rng(3)
    t = np.arange(12.0)
    track = np.column_stack([10.0 * t, 0.3 * t**2])
    sig = np.full(12, 3.0)
    assert kinematic_consistent(t, track + rng.normal(0, 3.0, (12, 2)), sig)
    assert not kinematic_consistent(t, track + rng.normal(0, 200.0, (12, 2)), sig)
    assert not kinematic_consistent(t[:5], track[:5], sig[:5])      # too short to tell


def test_noise_scale_rises_on_overconfidence_and_never_falls_below_one():
    cfg = FilterConfig.for_grade("industrial")
    flt = InsGnssFilter(cfg, 0.0, 0.9, 0.4, 10.0, np.zeros(3), np.eye(3))
    ad = calibrate.NoiseAdapter()
    for _ in range(200):
        ad.on_fix(flt, 40.0, 2)              # NIS 20 per dimension, fix after fix
    assert flt.q_scale > 50.0
    for _ in range(5000):
        ad.on_fix(flt, 0.1, 2)
    assert flt.q_scale == 1.0
    # the shadows' variance ratio from the share of χ² beyond the median: honest ≈ 1, errors
    # with 4× the predicted variance ≈ 4 (robust to a heavy tail)
    rng = np.random.default_rng(0)
    for kappa in (1.0, 4.0):
        ad = calibrate.NoiseAdapter()
        for c in rng.chisquare(2, 3000) * kappa:
            ad.on_shadow(c, 2)
        assert ad.dr_ratio == pytest.approx(kappa, rel=0.35)
        assert ad.shadow_scale == pytest.approx(2.0 * np.sqrt(max(kappa, 1.0)), rel=0.2)


def test_output_trajectory_moves_rows_to_the_antenna_and_to_true_time():
    """The row at stamp t is the INS at t + ε̂ shifted back by v ε̂, plus C_b^n l̂."""
    from selfnav.ins.navigator import FilterResult, output_trajectory
    from selfnav.types import Trajectory

    n = 3
    lat, lon = np.full(n, 0.9), np.full(n, 0.4)
    v = np.tile([10.0, 0.0, 0.0], (n, 1))
    tr = Trajectory(np.arange(n, dtype=float), lat, lon, np.zeros(n), v, np.tile(np.eye(3), (n, 1, 1)))
    res = FilterResult(tr, *[np.zeros((n, 3))] * 5, np.zeros(0), np.zeros(0), np.zeros((0, 3)),
                       np.zeros(0), np.zeros(0), lever_arm=np.tile([0.0, 1.0, 0.0], (n, 1)),
                       time_offset=np.full(n, 0.1))
    out = output_trajectory(res, antenna=True)
    d = enu_offset(0.9, 0.4, 0.0, out.lat[0], out.lon[0], out.h[0])
    # C_nb = I: body y (forward) is North; the INS leads by 0.1 s at 10 m/s East
    assert d == pytest.approx([-1.0, 1.0, 0.0], abs=1e-6)
    lat2, lon2, _ = offset_to_geodetic(0.9, 0.4, 0.0, np.array([1.0, 0.0, 0.0]))
    assert lat2 == pytest.approx(0.9) and lon2 > 0.4
    assert DEG > 0
