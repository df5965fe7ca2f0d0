"""IMU records: gaps (found, bridged when short, segments otherwise) and plausibility checks."""
import warnings

import numpy as np
import pytest

from selfnav.errors import InputError, SelfnavWarning
from selfnav.io import imu as I
from selfnav.sim.static import static_imu
from selfnav.types import ImuData


def _ramp(n=1000, dt=0.01):
    t = dt * np.arange(1, n + 1)
    w = np.column_stack([np.sin(t), np.cos(t), t])
    f = np.column_stack([t, 2 * t, 9.8 + 0 * t])
    return ImuData(t, w, f, source="ramp")


def _cut(imu, a, b):
    keep = np.ones(len(imu), bool)
    keep[a:b] = False
    return imu.select(keep)


def test_gaps_found_with_their_length():
    imu = _cut(_ramp(), 300, 303)          # 3 samples missing
    imu = _cut(imu, 600, 700)              # 100 samples missing (1 s)
    gaps = I.imu_gaps(imu)
    assert [g.missing for g in gaps] == [3, 100]
    assert gaps[1].duration == pytest.approx(1.0, abs=1e-9)
    assert gaps[0].t_before == pytest.approx(3.00) and gaps[0].t_after == pytest.approx(3.04)
    assert "1 s IMU gap at t = " in gaps[1].describe()
    assert I.imu_gaps(imu, I.MAX_BRIDGE_SAMPLES + 1) == gaps[1:]
    # timing jitter is not a gap
    j = _ramp()
    j.t = j.t + np.random.default_rng(0).uniform(-0.002, 0.002, len(j.t))
    assert I.imu_gaps(j) == []


def test_short_gaps_bridged_exactly_on_linear_data_long_gaps_split():
    full = _ramp()
    imu = _cut(_cut(full, 300, 303), 600, 700)
    b = I.bridge_gaps(imu)
    assert len(b) == len(imu) + 3 and b.meta["bridged_samples"] == 3
    np.testing.assert_allclose(b.t[:600], full.t[:600], atol=1e-12)
    # the f columns are linear in t: the bridge reproduces them exactly
    np.testing.assert_allclose(b.f_ib_b[:600], full.f_ib_b[:600], atol=1e-12)
    segs = I.imu_segments(b)
    assert [(s.start, s.stop) for s in segs] == [(0, 603), (603, len(b))]   # rows 603-702 cut
    assert I.bridge_gaps(full) is full


def test_longest_stretch_says_so_in_one_warning():
    imu = _cut(_ramp(2000), 500, 6000 // 10)
    with pytest.warns(SelfnavWarning, match=r"IMU gap at t = .* uses the longest gap-free"):
        part = I.longest_stretch(imu, "the test")
    assert len(part) == 2000 - 600 + 0 and part.t[0] == pytest.approx(6.01)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert I.longest_stretch(_ramp()) is not None   # no gap, no warning


def test_rest_units_deg_per_s_warned():
    lat = np.radians(50.0)
    nav = static_imu(lat, 60.0, 0.01, arw=np.radians(0.002) / 60, vrw=1e-5, seed=1)
    consumer = static_imu(lat, 60.0, 0.01, arw=np.radians(0.42) / 60, vrw=1e-3, seed=2,
                          gyro_bias=(0.01, -0.005, 0.003))
    for imu in (nav, consumer):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            I.check_rest_units(imu)                          # rad/s: quiet
        degs = ImuData(imu.t, np.degrees(imu.omega_ib_b), imu.f_ib_b, source="degs")
        with pytest.warns(SelfnavWarning, match="deg/s"):
            I.check_rest_units(degs)


def test_rate_and_length_checks():
    imu = _ramp(2)
    with pytest.raises(InputError, match="has 2 samples over 0.01 s: navigate needs at least 5 s"):
        I.check_imu_rate(imu, "navigate", min_duration_s=5.0)
    coarse = ImuData(np.arange(100) * 5.0, np.zeros((100, 3)), np.tile([0, 0, 9.8], (100, 1)))
    with pytest.raises(InputError, match="too coarse.*in milliseconds"):
        I.check_imu_rate(coarse, "navigate", max_dt_s=0.2)
    # a 100 Hz record stamped in microseconds or nanoseconds: the guess names that unit
    for k, unit in ((1e6, "microseconds"), (1e9, "nanoseconds")):
        stamped = ImuData(np.arange(100) * 0.01 * k, np.zeros((100, 3)),
                          np.tile([0, 0, 9.8], (100, 1)))
        with pytest.raises(InputError, match=f"in {unit}"):
            I.check_imu_rate(stamped, "navigate", max_dt_s=0.2)
    mid = ImuData(np.arange(100) * 0.08, np.zeros((100, 3)), np.tile([0, 0, 9.8], (100, 1)))
    with pytest.warns(SelfnavWarning, match="coarse for navigate"):
        I.check_imu_rate(mid, "navigate", max_dt_s=0.2, warn_dt_s=0.05)
