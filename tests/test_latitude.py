"""Static latitude (seed 000): seed values, the Cramér–Rao bound, honesty of sigma, real data."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from selfnav import latitude as L
from selfnav.io.readers import read_imu
from selfnav.sim.static import multiposition_imu, rocking, static_imu

DEGH = L.DEG_PER_H
ARCSEC = np.radians(1 / 3600)


def dms(d, m, s):
    return np.radians(d + m / 60 + s / 3600)


def test_seed_kyiv_example_reproduced():
    # seed 000 (3.1): printed result 50°36'14"
    w = np.array([9.426, 11.663, -1.055]) * DEGH
    f = np.array([-0.0437, 9.8117, -0.0070])
    phi = L.latitude_seed(w, f)
    assert abs(phi - dms(50, 36, 14)) < 10 * ARCSEC
    # the normalized form with the measured norms (DESIGN §3): 50°37'53"
    wn, fn = np.linalg.norm(w), np.linalg.norm(f)
    assert abs(L.latitude_seed(w, f, omega=wn, g=fn) - dms(50, 37, 53)) < 2 * ARCSEC
    assert abs(L.latitude_angle(w, f) - dms(50, 37, 53)) < 2 * ARCSEC


def test_seed_kharkiv_erratum_documented():
    # seed 000 (3.2): printed 49°43'30" is NOT reproduced; the data give 49°45'55"
    w = np.array([9.556, 11.460, 0.057]) * DEGH
    f = np.array([0.0236, 9.8092, 0.0626])
    phi = L.latitude_seed(w, f)
    assert abs(phi - dms(49, 45, 56)) < 3 * ARCSEC
    assert abs(phi - dms(49, 43, 30)) > 120 * ARCSEC
    assert np.linalg.norm(w) / DEGH == pytest.approx(14.921, abs=1e-3)  # printed 14.942


def test_invariance_to_orientation():
    lat = np.radians(-37.0)
    for R in Rotation.random(20, random_state=0).as_matrix():
        w = R @ np.array([0, L.OMEGA_EARTH * np.cos(lat), L.OMEGA_EARTH * np.sin(lat)])
        f = R @ np.array([0, 0, 9.79])
        assert L.latitude_angle(w, f) == pytest.approx(lat, abs=1e-12)


def test_requirements_table_reproduces_seed():
    tab = L.requirements_table(L.SEED_TABLE_DPHI_DEG, 60.0, seed_constants=True)
    assert tab["gyro_drift_deg_per_h"][0] == pytest.approx(5.88577e-05, rel=2e-6)
    assert tab["accel_error_g"][0] == pytest.approx(3.92384e-06, rel=3e-6)
    assert tab["dphi_arcmin"][0] == pytest.approx(0.026992053, rel=2e-6)
    assert tab["gyro_drift_deg_per_h"][-1] == pytest.approx(0.002354307, rel=2e-6)
    assert tab["accel_error_g"][-1] == pytest.approx(0.000156954, rel=3e-6)
    # seed (4.5) text example: Δφ = 1°, φ = 60°, Ω = 15.04 → 0.13 °/h
    r = L.requirements(np.radians(1.0), np.radians(60.0))
    assert r["gyro_drift_deg_per_h"] == pytest.approx(0.13, abs=0.005)


def test_error_model_matches_finite_difference():
    lat = np.radians(60)
    C = Rotation.random(random_state=3).as_matrix()
    w = C @ np.array([0, L.OMEGA_EARTH * np.cos(lat), L.OMEGA_EARTH * np.sin(lat)])
    f = C @ np.array([0, 0, 9.81])
    dw = np.array([1e-9, -2e-9, 3e-9])
    df = np.array([2e-5, 1e-5, -3e-5])
    pred = L.latitude_error(w, f, dw, df)
    num = L.latitude_seed(w + dw, f + df, omega=L.OMEGA_EARTH, g=9.81) - lat
    assert pred == pytest.approx(num, rel=1e-3)
    # (4.4) level north-aligned case
    w0 = np.array([0, L.OMEGA_EARTH * np.cos(lat), L.OMEGA_EARTH * np.sin(lat)])
    f0 = np.array([0, 0, 9.81])
    d = L.latitude_error(w0, f0, np.array([0, 0, 1e-8]), np.array([0, 0, 0]))
    assert d == pytest.approx(-(-9.81 * 1e-8) / (L.OMEGA_EARTH * 9.81 * np.cos(lat)), rel=1e-9)


def _noise_levels():
    arw = np.radians(0.01) / 60  # 0.01 °/√h
    vrw = 9.80665 * arw / L.OMEGA_EARTH / 3.0
    return arw, vrw


@pytest.mark.filterwarnings("ignore:.*near the pole:selfnav.errors.SelfnavWarning")  # expected here
def test_optimal_estimator_reaches_cramer_rao_bound_monte_carlo():
    rng = np.random.default_rng(42)
    arw, vrw = _noise_levels()
    T, dt = 300.0, 0.1
    bound = L.cramer_rao_bound(arw, vrw, T, g=9.8)
    z, zs, zseed = [], [], []
    for k in range(200):
        lat = rng.uniform(np.radians(-89), np.radians(89))
        r, p, h = Rotation.random(random_state=rng.integers(2**31)).as_euler("YXZ")
        imu = static_imu(lat, T, dt, roll=r, pitch=np.clip(p, -1.5, 1.5), heading=h, arw=arw,
                         vrw=vrw, seed=int(rng.integers(2**31)))
        res = L.estimate_latitude(imu)
        z.append((res.latitude - lat) / bound)
        zs.append((res.latitude - lat) / res.sigma)
        zseed.append(L.latitude_seed(imu.omega_ib_b.mean(0), imu.f_ib_b.mean(0)) - lat)
    z = np.asarray(z)
    rms = np.sqrt(np.mean(z**2))
    assert 0.8 <= rms <= 1.25, rms
    assert abs(np.mean(z)) < 0.25
    # sigma from the data's own scatter is honest
    rms_s = np.sqrt(np.mean(np.asarray(zs) ** 2))
    assert 0.7 <= rms_s <= 1.4, rms_s
    # the seed's arcsin form is much worse near the poles (1/cos φ)
    assert np.sqrt(np.mean(np.asarray(zseed) ** 2)) > 3 * bound


@pytest.mark.filterwarnings("ignore:.*off Earth rate:selfnav.errors.SelfnavWarning")  # expected here
def test_sigma_widened_for_gyro_scale_error():
    arw, vrw = _noise_levels()
    lat = np.radians(45)
    imu = static_imu(lat, 600, 0.1, arw=arw / 10, vrw=vrw / 10, gyro_bias=(0, 0.2 * DEGH, 0), seed=1)
    res = L.estimate_latitude(imu)
    assert res.sigma > 3 * res.sigma_noise
    assert any("Earth rate" in w for w in res.warnings)
    assert abs(res.latitude - lat) < 2 * res.sigma


@pytest.mark.filterwarnings("ignore:.*disturbed rest:selfnav.errors.SelfnavWarning")  # expected here
@pytest.mark.filterwarnings("ignore:.*off Earth rate:selfnav.errors.SelfnavWarning")  # expected here
def test_disturbed_rest_compensated():
    arw, vrw = np.radians(0.003) / 60, 2e-5
    lat = np.radians(50)
    errs_plain, errs_comp, z = [], [], []
    for s in range(6):
        imu = static_imu(lat, 600, 0.01, roll=0.1, pitch=-0.2, heading=1.0, arw=arw, vrw=vrw,
                         disturbance=lambda t: rocking(t, rng=s), seed=10 + s)
        a = L.estimate_latitude(imu, rest="still")
        b = L.estimate_latitude(imu)
        assert b.disturbance_compensated
        errs_plain.append(a.latitude - lat)
        errs_comp.append(b.latitude - lat)
        z.append((b.latitude - lat) / b.sigma)
    assert np.sqrt(np.mean(np.square(errs_plain))) > np.radians(0.5)
    assert np.sqrt(np.mean(np.square(errs_comp))) < 2.5 * L.cramer_rao_bound(arw, vrw, 600)
    assert np.sqrt(np.mean(np.square(z))) < 2.0


@pytest.mark.filterwarnings("ignore:.*disturbed rest:selfnav.errors.SelfnavWarning")  # expected here
def test_noise_free_disturbed_is_exact():
    lat = np.radians(-20)
    imu = static_imu(lat, 300, 0.01, roll=0.3, pitch=0.1, heading=4.0,
                     disturbance=lambda t: rocking(t, rng=3))
    res = L.estimate_latitude(imu, rest="disturbed")
    # exact up to second-order small-angle terms of the 0.2° tilt (about 0.4")
    assert abs(res.latitude - lat) < np.radians(5e-4)
    assert res.heading == pytest.approx(4.0, abs=np.radians(0.01))


def test_heading_pitch_roll_recovered():
    lat = np.radians(30)
    imu = static_imu(lat, 100, 0.1, roll=np.radians(3), pitch=np.radians(-7), heading=np.radians(250))
    res = L.estimate_latitude(imu)
    assert np.degrees(res.heading) == pytest.approx(250, abs=1e-6)
    assert np.degrees(res.pitch) == pytest.approx(-7, abs=1e-6)
    assert np.degrees(res.roll) == pytest.approx(3, abs=1e-6)


def test_multiposition_removes_bias_error():
    lat = np.radians(50)
    bg = np.array([0.005, -0.004, 0.005]) * DEGH
    ba = np.array([50, -40, 50]) * 1e-6 * 9.80665
    single, multi, z = [], [], []
    for s in range(4):
        imu = multiposition_imu(lat, np.radians([0, 90, 180, 270]), 900, 0.1, roll=np.radians(2),
                                pitch=np.radians(1), arw=np.radians(0.0005) / 60, vrw=5e-6,
                                gyro_bias=bg, accel_bias=ba, seed=s)
        r = L.estimate_latitude_multiposition(imu)
        one = L.estimate_latitude(imu.select(imu.position == 0))
        single.append(one.latitude - lat)
        multi.append(r.latitude - lat)
        z.append((r.latitude - lat) / r.sigma)
        # vertical gyro bias recovered through the Earth-rate magnitude
        assert abs(r.gyro_bias_b[2] - bg[2]) < 3 * r.gyro_bias_sigma[2]
    rms_single = np.sqrt(np.mean(np.square(single)))
    rms_multi = np.sqrt(np.mean(np.square(multi)))
    assert rms_single > np.radians(0.015)  # bias-limited: 0.005 °/h / (Ω cos φ)
    assert rms_multi < rms_single / 4
    assert np.sqrt(np.mean(np.square(z))) < 2.0


@pytest.mark.filterwarnings("ignore:.*disturbed rest:selfnav.errors.SelfnavWarning")  # expected here
def test_real_xian_recording(shared_data):
    imu = read_imu(shared_data / "psins_lasergyro_static" / "lasergyro.imu", "psins")
    assert len(imu) == 184718
    site = np.radians(34.246048)
    plain = L.estimate_latitude(imu, rest="still")
    assert abs(np.degrees(plain.latitude - site) - 0.38) < 0.01  # the plain estimate
    res = L.estimate_latitude(imu)
    assert res.disturbance_compensated
    assert abs(res.latitude - site) < np.radians(0.1)
    assert abs(res.latitude - site) < 2 * res.sigma  # honest sigma
    assert np.degrees(res.sigma) < 0.2
    # heading: the header's coarse yaw is -90.6° (CCW) = heading 90.6°
    assert np.degrees(res.heading) == pytest.approx(90.6, abs=0.2)
