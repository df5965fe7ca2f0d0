"""Shadow dead reckoning against smoothly drifting GNSS errors; IMU mounting-angle states."""
import numpy as np
import pytest

from selfnav import attitude as att
from selfnav import ins
from selfnav.ins import ekf
from selfnav.ins.guard import clone_filter, track_agrees
from selfnav.types import ImuData
from selfnav.sensors import OutlierWindow, drift_errors

from support import simulated_drive as _drive, errors as _errors, window_metrics as _window_metrics


@pytest.fixture(scope="module")
def graph(karhula):
    return karhula


def test_drift_errors_statistics():
    """Second-order Gauss–Markov: steady-state σ and rate σ·β, smooth from fix to fix."""
    rng = np.random.default_rng(3)
    runs = [drift_errors(4000, 0.25, 200.0, 60.0, rng, start="stationary") for _ in range(20)]
    assert np.std(np.concatenate(runs)) == pytest.approx(200.0, rel=0.15)
    rate = np.concatenate([np.diff(e, axis=0) / 0.25 for e in runs])
    assert np.std(rate) == pytest.approx(200.0 / 60.0, rel=0.15)
    z = drift_errors(100, 0.25, 200.0, 60.0, 1)
    assert np.all(z[0] == 0.0) and np.max(np.abs(np.diff(z, axis=0))) < 2.0  # metres per step


def test_track_agrees():
    t = np.arange(0.0, 10.0, 0.25)
    rng = np.random.default_rng(0)
    P = np.eye(2) * 0.2**2
    still = rng.normal(size=(len(t), 2)) * 0.1 + [30.0, -4.0]
    assert track_agrees(t, still, 0.1, P)
    moving = still + np.outer(t, [3.0, 0.0])          # a drift of 3 m/s
    assert not track_agrees(t, moving, 0.1, P)
    assert not track_agrees(t[:3], still[:3], 0.1, P)  # too short to tell
    # a 10 m receiver over 2 s cannot tell 3 m/s from 0: not enough to re-acquire
    assert not track_agrees(t[:8], still[:8] * 100, 10.0, P)


def test_clone_is_independent(graph):
    imu, g, truth = _drive(graph, 1, duration=120.0)
    cfg = ins.FilterConfig.for_grade("industrial")
    flt = ekf.InsGnssFilter(cfg, imu.t[0], truth.lat[0], truth.lon[0], truth.h[0],
                            truth.velocity_n[0], truth.C_nb[0])
    sh = clone_filter(flt)
    dt = np.diff(imu.t[:101])
    flt.predict(imu.t[1:101], imu.omega_ib_b[1:101] * dt[:, None], imu.f_ib_b[1:101] * dt[:, None])
    flt.update_nhc()
    assert sh.ins.t == imu.t[0] and sh.ins.lat == truth.lat[0]
    assert np.all(sh.P == ekf.InsGnssFilter(cfg, imu.t[0], truth.lat[0], truth.lon[0], truth.h[0],
                                            truth.velocity_n[0], truth.C_nb[0]).P)


@pytest.mark.slow
def test_smooth_drift_is_caught_by_the_shadow_dead_reckoning(graph):
    """Simulated drive (labelled simulated), consumer MEMS, 5 min of a smooth 200 m σ drift.

    Without the shadows the filter follows the drift (measured 306 m RMS in the window, 47 m
    after it); with them it dead-reckons as through white outliers (measured 14.6 / 31 m,
    3.7 m after: the consumer IMU's first minutes after alignment)."""
    for kind in ("drift", "drift-jump"):
        win = OutlierWindow(200.0, 300.0, 200.0, kind, tau=60.0)
        imu, g, truth = _drive(graph, 3, duration=700.0, outliers=[win], grade="consumer")
        out = {}
        for guard in (True, False):
            cfg = ins.FilterConfig.for_grade("consumer", scale_factors=False, use_shadows=guard)
            out[guard] = _window_metrics(ins.run_filter(imu, g, cfg), truth, win)
        assert out[True][0] < 18.0 and out[True][1] < 40.0 and out[True][2] < 5.0, (kind, out)
        assert out[False][0] > 5 * out[True][0], (kind, out)


@pytest.mark.slow
def test_mounting_angles_are_estimated(graph):
    """An IMU pitched 1.5° and yawed −2.5° against the car (simulated): the NHC states find it."""
    imu, g, truth = _drive(graph, 2, duration=600.0)
    mu = np.radians([1.5, -2.5])
    C_vb = att.rotvec_to_dcm(np.array([mu[0], 0.0, mu[1]]))
    imu_m = ImuData(imu.t, imu.omega_ib_b @ C_vb, imu.f_ib_b @ C_vb, source="simulated, mounted")
    cfg = ins.FilterConfig.for_grade("industrial", nhc_sigma=0.1, mount_states=True)
    res = ins.run_filter(imu_m, g, cfg)
    est = res.mounting[-1]
    assert np.degrees(np.abs(est - mu)).max() < 0.3, np.degrees(est)
    # without the states the NHC fights the 2.5° yaw: the position is worse
    res0 = ins.run_filter(imu_m, g, ins.FilterConfig.for_grade("industrial", nhc_sigma=0.1))
    rms = []
    for r in (res, res0):
        t, dp, *_ = _errors(r, truth)
        late = t > t[0] + 120
        rms.append(float(np.sqrt(np.mean(np.sum(dp[late] ** 2, 1)))))
    assert rms[0] < rms[1], (np.degrees(est), rms)


def test_window_test_allows_the_acceleration_error_the_covariance_admits():
    """Six fixes whose offset from the INS displacement grows as ½ a t² (a levelling error of
    a fresh start): inconsistent for a test that knows only a velocity error, consistent once
    the covariance's acceleration σ enters — and still inconsistent for a 20 m jump."""
    from types import SimpleNamespace

    from selfnav.earth import offset_to_geodetic
    from selfnav.ins.guard import window_consistent

    lat0, lon0 = np.radians(60.0), np.radians(25.0)
    a = 0.3
    fixes, buf = [], []
    for k in range(6):
        t = float(k)
        la, lo, h = offset_to_geodetic(lat0, lon0, 0.0, np.array([10.0 * t, 0.0, 0.0]))
        fixes.append(SimpleNamespace(t=t, lat=la, lon=lo, h=h, sigma_h=0.3, sigma_v=0.5))
        buf.append((k, np.array([10.0 * t - 0.5 * a * t * t, 0.0, 0.0])))
    assert not window_consistent(buf, fixes, 0.05)
    assert window_consistent(buf, fixes, 0.05, s_acc=a)
    la, lo, h = offset_to_geodetic(lat0, lon0, 0.0, np.array([70.0, 0.0, 0.0]))
    fixes[-1] = SimpleNamespace(t=5.0, lat=la, lon=lo, h=h, sigma_h=0.3, sigma_v=0.5)
    assert not window_consistent(buf, fixes, 0.05, s_acc=a)
