"""The navigator's self-calibration (issue 10): noise at rest, time offset, velocity lag, fix
chains, the online noise scale. Simulated data (labelled simulated), known truth."""
import numpy as np
import pytest

from selfnav.earth import enu_offset, offset_to_geodetic
from selfnav.ins import FilterConfig, InsGnssFilter, calibrate
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


def test_noise_scale_rises_on_overconfidence_and_never_falls_below_one():
    from selfnav.ins.config import NoiseAdaptation

    cfg = FilterConfig.for_grade("industrial")
    flt = InsGnssFilter(cfg, 0.0, 0.9, 0.4, 10.0, np.zeros(3), np.eye(3))
    ad = calibrate.NoiseAdapter(NoiseAdaptation())
    for _ in range(200):
        ad.on_fix(flt, 40.0, 2)              # NIS 20 per dimension, fix after fix
    assert flt.q_scale > 5.0
    for _ in range(5000):
        ad.on_fix(flt, 0.1, 2)
    assert flt.q_scale == 1.0


def test_a_window_of_large_innovations_reopens_the_covariance_once():
    """The sums of the last 8, 16 and 32 trusted fixes' NIS are χ² tests of 16, 32 and 64
    dimensions at p 10⁻⁴ shared: honest innovations (χ²₂ draws) reopen P about once in
    25 000 fixes (sliding windows, correlated tests — at most 6 over 40 000 here); eight at
    NIS 8 (4 per dimension) scale P by 4 once, and the window begins again."""
    from selfnav.ins.config import NoiseAdaptation

    def filt():
        return InsGnssFilter(FilterConfig.for_grade("industrial"), 0.0, 0.9, 0.4, 10.0,
                             np.zeros(3), np.eye(3))

    false = 0
    for seed in range(20):
        ad = calibrate.NoiseAdapter(NoiseAdaptation(), 1e-4)
        flt = filt()
        for c in np.random.default_rng(seed).chisquare(2, 2000):
            ad.on_fix(flt, float(c), 2)
        false += ad.reopenings
    assert false <= 6
    flt = filt()
    P0 = flt.P.copy()
    ad = calibrate.NoiseAdapter(NoiseAdaptation(), 1e-4)
    for c in np.random.default_rng(0).chisquare(2, 40):
        ad.on_fix(flt, float(c), 2)
    ad.forget()
    for _ in range(8):
        ad.on_fix(flt, 8.0, 2)
    assert ad.reopenings == 1
    np.testing.assert_allclose(flt.P, 4.0 * P0)
    for _ in range(7):
        ad.on_fix(flt, 8.0, 2)
    assert ad.reopenings == 1


def test_reference_ratio_follows_the_dead_reckoning_errors_and_settles():
    """The references' variance ratio κ̂ from their χ² (mean over a memory in time): honest
    ≈ 1; errors with 4× the predicted variance ≈ 4; λ then moves to the λ that makes the
    references honest (a fixed point, not a ratchet)."""
    from selfnav.ins.config import NoiseAdaptation

    rng = np.random.default_rng(0)
    for kappa in (1.0, 4.0):
        ad = calibrate.NoiseAdapter(NoiseAdaptation())
        for k, c in enumerate(rng.chisquare(2, 3000) * kappa):
            ad.on_reference(float(k), c, 20.0, 1.0)
        assert ad.reference_ratio == pytest.approx(kappa, rel=0.35)
    ad = calibrate.NoiseAdapter(NoiseAdaptation())
    flt = InsGnssFilter(FilterConfig.for_grade("industrial"), 0.0, 0.9, 0.4, 10.0, np.zeros(3),
                        np.eye(3))
    lam = []
    for k in range(3000):
        # the references see 4× their variance while propagated with λ, 1× once λ ≈ 4
        ad.on_reference(float(k), rng.chisquare(2) * 4.0 / flt.q_scale, 20.0, flt.q_scale)
        ad.on_fix(flt, 2.0, 2)
        lam.append(flt.q_scale)
    assert np.median(lam[-500:]) == pytest.approx(4.0, rel=0.3)
    assert max(lam) < 8.0


def test_vibration_level_ignores_smooth_motion_and_sees_vibration():
    """The vibration level of a block: a ramp of acceleration or a steady turn adds nothing
    (second differences), white noise gives its variance, a kink does not decide (median)."""
    t = np.arange(200) * 0.01
    rng = np.random.default_rng(1)
    w = np.column_stack([0.3 * t, 0.1 * np.ones_like(t), 0.05 * t**2])
    f = np.column_stack([2.0 * t, np.ones_like(t), 9.8 + 0.0 * t])
    f[100:, 0] += 1.0                                      # a step in the specific force
    lv = calibrate.vibration_level(w, f)
    assert lv[0] < 1e-9 and lv[1] < 1e-9
    noisy = calibrate.vibration_level(w + rng.normal(0, 0.01, w.shape),
                                      f + rng.normal(0, 0.1, f.shape))
    assert noisy[0] == pytest.approx(1e-4, rel=0.3) and noisy[1] == pytest.approx(1e-2, rel=0.3)
    assert calibrate.vibration_scale(noisy, (1e-4, 1e-3), 100.0) == pytest.approx((1.0, 10.0), rel=0.3)
