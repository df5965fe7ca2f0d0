"""Sensor error models (issue 3): statistics against their specification, GNSS, magnetometer."""
import numpy as np
import pytest
from pyproj import Geod

from selfnav import attitude as att
from selfnav import sensors as S
from selfnav.errors import SelfnavError
from selfnav.types import Trajectory

LAT0, LON0 = np.radians(60.52), np.radians(26.95)


def test_grade_presets_apply_and_order():
    n, dt = 2000, 0.01
    t = dt * np.arange(1, n + 1)
    w = np.tile([0.0, 0.0, 1e-4], (n, 1))
    f = np.tile([0.0, 0.0, 9.81], (n, 1))
    arw = []
    for g in ("navigation", "tactical", "industrial", "consumer"):
        m = S.imu_grade(g)
        wm, fm = m.apply(t, w, f, 1)
        assert wm.shape == w.shape and np.all(np.isfinite(fm))
        arw.append(np.mean(np.asarray(m.gyro.white)))
    assert arw == sorted(arw)            # navigation < tactical < industrial < consumer
    wp, fp = S.imu_grade("perfect").apply(t, w, f, 1)
    np.testing.assert_array_equal(wp, w)
    np.testing.assert_array_equal(fp, f)
    with pytest.raises(SelfnavError):
        S.imu_grade("military")


def test_white_noise_density_and_constants():
    dt, n = 0.005, 200000
    tr = S.SensorTriad(white=1e-3, bias=0.0, scale_factor=1e-3, misalignment=1e-3)
    x = np.tile([0.1, -0.2, 0.3], (n, 1))
    y, c = tr.apply(dt, x, np.random.default_rng(3))
    err = y - x @ c["matrix"].T - c["bias"]
    # per-sample σ of a rate-averaged white noise of density N is N/√dt
    np.testing.assert_allclose(err.std(0), 1e-3 / np.sqrt(dt), rtol=0.01)
    # turn-on constants: σ of 4000 draws within 5 %
    rng = np.random.default_rng(5)
    tr2 = S.SensorTriad(bias=2e-3, scale_factor=1e-4, misalignment=3e-4)
    draws = [tr2.realize(rng) for _ in range(4000)]
    b = np.array([d["bias"] for d in draws])
    M = np.array([d["matrix"] for d in draws])
    np.testing.assert_allclose(b.std(0), 2e-3, rtol=0.05)
    np.testing.assert_allclose(np.std(M[:, [0, 1, 2], [0, 1, 2]], 0), 1e-4, rtol=0.05)
    off = M[:, [0, 0, 1, 1, 2, 2], [1, 2, 0, 2, 0, 1]]
    np.testing.assert_allclose(off.std(0), 3e-4, rtol=0.06)


def test_gauss_markov_bias_statistics():
    dt, tau, B = 0.1, 20.0, 1e-5
    tr = S.SensorTriad(bias_instability=B, bias_tau=tau)
    _, c = tr.apply(dt, np.zeros((400000, 3)), np.random.default_rng(2))
    gm = c["gauss_markov"]
    sig = B * S.FLICKER_FLOOR / S.GM_ALLAN_PEAK
    np.testing.assert_allclose(gm.std(0), sig, rtol=0.08)
    r1 = np.mean(gm[1:] * gm[:-1], 0) / np.mean(gm * gm, 0)
    np.testing.assert_allclose(r1, np.exp(-dt / tau), atol=2e-3)
    assert abs(S.GM_ALLAN_PEAK - 0.617) < 0.002    # IEEE 952 C.1.7 peak (0.6174 at T/τ ≈ 1.89)


def test_rate_random_walk_and_quantisation():
    dt, K = 0.01, 1e-5
    tr = S.SensorTriad(random_walk=K)
    y, _ = tr.apply(dt, np.zeros((100000, 3)), np.random.default_rng(4))
    steps = np.diff(y, axis=0)
    np.testing.assert_allclose(steps.std(0), K * np.sqrt(dt), rtol=0.02)
    q = 1e-6
    x = np.tile([3.3e-5, -1.7e-4, 5e-3], (5000, 1))
    y, _ = S.SensorTriad(quantum=q).apply(dt, x, np.random.default_rng(0))
    inc = y * dt / q
    np.testing.assert_allclose(inc, np.round(inc), atol=1e-6)          # whole quanta
    drift = np.cumsum(y * dt, 0) - np.cumsum(x * dt, 0)
    assert np.abs(drift).max() <= q * (1 + 1e-9)                        # residual carried


def _track(duration=3000.0, dt=0.1):
    t = np.arange(0.0, duration + 1e-9, dt)
    n = len(t)
    v = np.tile([10.0, 5.0, 0.0], (n, 1))
    R = 6.38e6
    lat = LAT0 + 5.0 * t / R
    lon = LON0 + 10.0 * t / (R * np.cos(LAT0))
    return Trajectory(t, lat, lon, np.full(n, 50.0), v, np.tile(np.eye(3), (n, 1, 1)))


def test_gnss_error_statistics_match_sigma():
    tr = _track(6000.0)
    g = S.GnssModel(rate_hz=2.0, sigma_h=10.0, sigma_v=15.0).simulate(tr, 11)
    assert np.allclose(np.diff(g.t), 0.5)
    # independent oracle: geodesic distance (pyproj) between fix and true position
    lat_t = np.interp(g.t, tr.t, tr.lat)
    lon_t = np.interp(g.t, tr.t, tr.lon)
    az, _, d = Geod(ellps="WGS84").inv(np.degrees(lon_t), np.degrees(lat_t), np.degrees(g.lon),
                                       np.degrees(g.lat))
    n = len(g.t)
    # d²/σ² is chi-square with 2 degrees of freedom: mean 2, sd 2/√n
    z = np.mean(d**2) / 10.0**2
    assert abs(z - 2.0) < 4 * 2.0 / np.sqrt(n)
    e = d * np.sin(np.radians(az))
    nn = d * np.cos(np.radians(az))
    np.testing.assert_allclose([e.std(), nn.std()], 10.0, rtol=0.05)
    dh = g.h - 50.0
    np.testing.assert_allclose(dh.std(), 15.0, rtol=0.05)
    np.testing.assert_allclose(np.hypot(e, nn), np.hypot(*g.error_enu[:, :2].T), atol=1e-3)
    assert not g.outlier.any() and not g.spike.any()


def test_outlier_windows_are_where_the_scenario_says():
    tr = _track(3000.0)
    wins = [S.OutlierWindow(0.0, 300.0, 200.0, "gm", tau=60.0),        # from start-up
            S.OutlierWindow(1500.0, 240.0, 200.0, "white")]
    g = S.GnssModel(rate_hz=5.0, sigma_h=10.0, outliers=wins, outages=[(2500.0, 2600.0)],
                    spike_rate=0.01, spike_sigma=50.0).simulate(tr, 7)
    inside = ((g.t >= 0) & (g.t < 300)) | ((g.t >= 1500) & (g.t < 1740))
    np.testing.assert_array_equal(g.outlier, inside)
    assert not np.any((g.t >= 2500) & (g.t < 2600))                      # outage
    h = np.hypot(*g.error_enu[:, :2].T)
    clean = ~g.outlier & ~g.spike
    white = (g.t >= 1500) & (g.t < 1740)
    rms = lambda m: np.sqrt(np.mean(g.error_enu[m, :2] ** 2))  # noqa: E731
    assert 9.0 < rms(clean) < 11.0
    assert 170.0 < rms(white) < 230.0                                     # 2400 samples
    # the drifting window is slow: successive errors barely differ (a = e^{-0.2/60})
    gm = g.error_enu[(g.t < 300), :2]
    assert np.std(np.diff(gm, axis=0)) < 0.15 * 200.0
    assert np.all(g.sigma_m == 10.0)                                      # unflagged
    assert h[g.spike & ~g.outlier].std() > 2 * rms(clean)


def test_random_outlier_windows():
    rng = np.random.default_rng(1)
    for _ in range(20):
        w = S.random_outlier_windows(0.0, 3600.0, 3, rng, startup=True)
        assert w[0].start == 0.0
        for a, b in zip(w[:-1], w[1:]):
            assert a.end <= b.start
        assert all(0 < x.duration <= 300.0 and x.sigma == 200.0 for x in w)
        assert all(x.end <= 3600.0 for x in w)


def test_datum_output_pz90():
    tr = _track(100.0)
    g84 = S.GnssModel(sigma_h=0.0, sigma_v=0.0).simulate(tr, 1)
    gpz = S.GnssModel(sigma_h=0.0, sigma_v=0.0, datum="pz90").simulate(tr, 1)
    from selfnav import datum

    lat, lon, h = datum.convert(g84.lat, g84.lon, g84.h, "wgs84", "pz90")
    np.testing.assert_allclose(gpz.lat, lat, atol=1e-12)
    assert np.abs(gpz.lat - g84.lat).max() > 0   # the datum changed something


def test_dipole_field_pole_and_declination_of_igrf_package():
    # tilted dipole: at the geomagnetic north pole the field points straight down, 2·B0
    g10, g11, h11 = S._G10, S._G11, S._H11
    b0 = np.sqrt(g10**2 + g11**2 + h11**2)
    m = -np.array([g11, h11, g10]) / b0
    lat, lon = np.arcsin(m[2]), np.arctan2(m[1], m[0])
    b = S.earth_field_n(lat, lon, 0.0, model="dipole")
    _, inc = S.declination_inclination(b)
    assert np.degrees(inc) > 89.99
    np.testing.assert_allclose(np.linalg.norm(b), 2 * b0, rtol=1e-9)
    # on the geomagnetic equator the field is horizontal, B0
    lon_e = lon + np.pi / 2
    lat_e = np.arctan2(-m[0] * np.cos(lon_e) - m[1] * np.sin(lon_e), m[2])
    b = S.earth_field_n(lat_e, lon_e, 0.0, model="dipole")
    assert abs(np.degrees(S.declination_inclination(b)[1])) < 1e-6
    np.testing.assert_allclose(np.linalg.norm(b), b0, rtol=1e-9)


def test_magnetic_heading_recovers_true_heading():
    rng = np.random.default_rng(3)
    n = 500
    roll, pitch = rng.uniform(-0.5, 0.5, n), rng.uniform(-0.4, 0.4, n)
    heading = rng.uniform(0, 2 * np.pi, n)
    C_nb = att.dcm_nb_from_euler(roll, pitch, heading)
    mag = S.MagnetometerModel(field_model="dipole")
    lat, lon = np.full(n, LAT0), np.full(n, LON0)
    m_b = mag.measure(lat, lon, np.zeros(n), C_nb, 0)
    dec, inc = S.declination_inclination(S.earth_field_n(LAT0, LON0, 0.0, model="dipole"))
    hdg = S.magnetic_heading(m_b, roll, pitch, dec)
    d = np.angle(np.exp(1j * (hdg - heading)))
    assert np.abs(d).max() < 1e-10
    # hard iron shifts the reading by its vector; noise has its σ
    mag2 = S.MagnetometerModel(hard_iron=(300.0, -200.0, 50.0), noise=100.0, field_model="dipole")
    m2 = mag2.measure(lat, lon, np.zeros(n), C_nb, 0)
    r = m2 - m_b - np.array([300.0, -200.0, 50.0])
    np.testing.assert_allclose(r.mean(0), 0.0, atol=4 * 100.0 / np.sqrt(n))
    np.testing.assert_allclose(r.std(0), 100.0, rtol=0.1)


def test_mean_heading_is_wrap_safe():
    h = np.radians([359.0, 1.0, 358.0, 2.0, 10.0, 12.0])
    m = S.mean_heading(h, 2)
    np.testing.assert_allclose(np.degrees(np.angle(np.exp(1j * m))), [0.0, 0.0, 11.0], atol=1e-9)


def test_apply_increments_equals_apply_on_rates():
    dt, n = 0.01, 1000
    t = dt * np.arange(1, n + 1)
    w = np.tile([0.01, 0.02, -0.03], (n, 1))
    f = np.tile([0.1, 0.2, 9.8], (n, 1))
    m = S.imu_grade("consumer")
    dth, dv = m.apply_increments(t, w * dt, f * dt, 9)
    w2, f2 = m.apply(t, w, f, 9)
    np.testing.assert_allclose(dth, w2 * dt, rtol=1e-12)
    np.testing.assert_allclose(dv, f2 * dt, rtol=1e-12)
