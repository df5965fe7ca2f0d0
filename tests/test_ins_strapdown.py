"""Strapdown mechanization (seed 004 fast loop): analytic cases, Schuler, vertical, round trip."""
import numpy as np
import pytest
from scipy.optimize import curve_fit

from selfnav import attitude as att
from selfnav.earth import OMEGA_EARTH, WGS84, earth_rate_n, normal_gravity, radii
from selfnav.errors import SelfnavError
from selfnav.ins.strapdown import (Strapdown, _gravity, _params, increments_from_rates, integrate,
                               slow_period_speed)

G0 = 9.80665


def horizontal_error(tr, lat, lon, h):
    R_M, R_N = radii(lat, h)
    return np.hypot((tr.lat - lat) * R_M, (tr.lon - lon) * R_N * np.cos(lat))


def attitude_error(C_a, C_b):
    """Angle (rad) of C_a C_b^T for stacks of nav->body DCMs."""
    return np.linalg.norm(att.dcm_to_rotvec(np.einsum("nij,nkj->nik", C_a, C_b)), axis=1)


def static_increments(lat, h, C_nb, dt, n, *, f_extra=(0.0, 0.0, 0.0), g_h=None):
    """Exact increments at rest: ω = C_nb Ω_n, f = C_nb (0, 0, γ) (+ an error in body axes)."""
    w = C_nb @ earth_rate_n(lat)
    up = np.array([0.0, 0.0, float(normal_gravity(lat, h))]) if g_h is None else np.asarray(g_h)
    f = C_nb @ up + np.asarray(f_extra)
    t = dt * np.arange(1, n + 1)
    return t, np.tile(w * dt, (n, 1)), np.tile(f * dt, (n, 1))


# --------------------------------------------------------------------------------------------
# An analytic rotating-and-accelerating trajectory on the ellipsoid (complex-step derivatives)
# --------------------------------------------------------------------------------------------
A, E2 = WGS84.a, WGS84.e2
LAT0, LON0, H0 = np.radians(50.0), np.radians(30.0), 150.0
R_TURN, W_TURN, DRIFT = 300.0, 0.07, 4.0 / 6.37e6


def _radii_c(lat, h):
    w = np.sqrt(1.0 - E2 * np.sin(lat) ** 2)
    return A * (1 - E2) / w**3 + h, A / w + h


def geodetic(t):
    lat = LAT0 + R_TURN / 6.37e6 * np.sin(W_TURN * t) + DRIFT * t
    dlat = R_TURN / 6.37e6 * W_TURN * np.cos(W_TURN * t) + DRIFT
    k = R_TURN / (6.37e6 * np.cos(LAT0))
    lon = LON0 + k * (1 - np.cos(W_TURN * t)) + 0.5 * DRIFT * t
    dlon = k * W_TURN * np.sin(W_TURN * t) + 0.5 * DRIFT
    h = H0 + 5.0 * np.sin(0.05 * t)
    dh = 0.25 * np.cos(0.05 * t)
    return lat, lon, h, dlat, dlon, dh


def _frame_rot(axis, a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    rows = {0: [[o, z, z], [z, c, s], [z, -s, c]], 1: [[c, z, -s], [z, o, z], [s, z, c]],
            2: [[c, s, z], [-s, c, z], [z, z, o]]}[axis]
    return np.stack([np.stack(r, -1) for r in rows], -2)


def C_nb_true(t):
    """Heading turning at 0.07 rad/s, pitch 3° at 0.7 Hz, roll 4° at 0.9 Hz: a coning motion."""
    heading = 0.3 + W_TURN * t
    pitch = np.radians(3.0) * np.sin(2 * np.pi * 0.7 * t)
    roll = np.radians(4.0) * np.sin(2 * np.pi * 0.9 * t + 1.0)
    return _frame_rot(1, roll) @ _frame_rot(0, pitch) @ _frame_rot(2, -heading)


def velocity_true(t):
    lat, lon, h, dlat, dlon, dh = geodetic(t)
    R_M, R_N = _radii_c(lat, h)
    return np.stack([dlon * R_N * np.cos(lat), dlat * R_M, dh], -1)


def _cstep(fun, t, eps=1e-20):
    return np.imag(fun(t + 1j * eps)) / eps


def true_rates(t):
    """ω_ib^b = ω_nb^b + C_nb ω_in^n and f^b = C_nb (V̇ + (2ω_ie + ω_en) × V − g^n)."""
    lat, lon, h, dlat, dlon, dh = geodetic(t)
    C = C_nb_true(t)
    W = C @ np.swapaxes(_cstep(C_nb_true, t), -1, -2)  # [ω_nb^b] = C_nb dC_bn/dt
    w_nb = att.vee(W)
    wie = np.stack([0 * lat, OMEGA_EARTH * np.cos(lat), OMEGA_EARTH * np.sin(lat)], -1)
    wen = np.stack([-dlat, dlon * np.cos(lat), dlon * np.sin(lat)], -1)
    v = velocity_true(t)
    g = np.stack([0 * lat, 0 * lat, -normal_gravity(lat, h)], -1)
    fn = _cstep(velocity_true, t) + np.cross(2 * wie + wen, v) - g
    return (w_nb + np.einsum("...ij,...j->...i", C, wie + wen),
            np.einsum("...ij,...j->...i", C, fn))


def true_increments(edges, nodes=6):
    """Exact increments over each [t_{k-1}, t_k] by Gauss-Legendre quadrature."""
    x, wq = np.polynomial.legendre.leggauss(nodes)
    a, b = edges[:-1], edges[1:]
    half = 0.5 * (b - a)
    tt = (0.5 * (a + b))[:, None] + half[:, None] * x[None, :]
    w, f = true_rates(tt.reshape(-1))
    w, f = w.reshape(len(a), nodes, 3), f.reshape(len(a), nodes, 3)
    return (np.einsum("k,nkj->nj", wq, w) * half[:, None],
            np.einsum("k,nkj->nj", wq, f) * half[:, None])


@pytest.fixture(scope="module")
def analytic_run():
    dt, T = 0.01, 600.0
    te = np.arange(0.0, T + dt / 2, dt)
    dth, dv = true_increments(te)
    return te, dth, dv


def _run_analytic(te, dth, dv, **kw):
    lat, lon, h, *_ = geodetic(te)
    tr = integrate(te[1:], dth, dv, lat[0], lon[0], h[0], velocity_true(te[:1])[0],
                   C_nb_true(te[:1])[0], t0=0.0, **kw)
    return (horizontal_error(tr, lat, lon, h).max(), np.abs(tr.h - h).max(),
            np.abs(tr.velocity_n - velocity_true(te)).max(),
            attitude_error(tr.C_nb, C_nb_true(te)).max())


# --------------------------------------------------------------------------------------------
def test_kernel_gravity_is_earth_normal_gravity():
    lat = np.radians(np.linspace(-89, 89, 37))
    for seed in (False, True):
        prm = _params(WGS84, seed, "free", True, True)
        for h in (-400.0, 0.0, 3000.0, 12000.0):
            ref = normal_gravity(lat, h, seed_constants=seed)
            got = np.array([_gravity(x, h, *prm[:6]) for x in lat])
            np.testing.assert_allclose(got, ref, rtol=1e-15)


def test_static_one_hour_stays_within_a_millimetre():
    lat, lon, h = np.radians(50.0), np.radians(30.0), 300.0
    C = att.dcm_nb_from_euler(np.radians(2.0), np.radians(-1.0), np.radians(123.0))
    t, dth, dv = static_increments(lat, h, C, 0.01, 360_000)
    tr = integrate(t, dth, dv, lat, lon, h, np.zeros(3), C, t0=0.0)
    assert tr.t[-1] == pytest.approx(3600.0)
    assert horizontal_error(tr, lat, lon, h).max() < 1e-3
    assert np.abs(tr.velocity_n[:, :2]).max() < 1e-6
    assert attitude_error(tr.C_nb, np.broadcast_to(C, tr.C_nb.shape)).max() < 1e-9


@pytest.mark.parametrize("lat_deg", [0.0, 45.0])
def test_schuler_period_of_a_resting_navigation_grade_imu(lat_deg):
    """A 50 µg East accelerometer error: V_E = (b/ω_s) sin(ω_s t), period 2π√(R/g) ≈ 84.4 min."""
    lat, h = np.radians(lat_deg), 0.0
    C = att.dcm_nb_from_euler(0.0, 0.0, 0.0)
    b = 50e-6 * G0
    t, dth, dv = static_increments(lat, h, C, 0.1, 144_000, f_extra=(b, 0.0, 0.0))
    tr = integrate(t, dth, dv, lat, 0.3, h, np.zeros(3), C, t0=0.0, vertical="fixed")
    model = lambda t, a, c, w, d: a * np.sin(w * t) + c * np.cos(w * t) + d  # noqa: E731
    p, _ = curve_fit(model, tr.t, tr.velocity_n[:, 0], p0=[0.4, 0.0, 2 * np.pi / 5064, 0.0])
    period = 2 * np.pi / p[2]
    assert period / 60.0 == pytest.approx(84.4, rel=0.01)
    R_N = radii(lat, h)[1]
    g = normal_gravity(lat, h)
    if lat_deg == 0.0:  # no Foucault term at the equator: the period is the local Schuler one
        assert period == pytest.approx(2 * np.pi * np.sqrt(R_N / g), rel=1e-4)
        assert np.hypot(p[0], p[1]) == pytest.approx(b / np.sqrt(g / R_N), rel=1e-3)


def test_vertical_channel_diverges_and_height_aiding_holds_it():
    lat, h = np.radians(45.0), 200.0
    C = np.eye(3)
    b = 50e-6 * G0
    t, dth, dv = static_increments(lat, h, C, 0.1, 18_000, f_extra=(0.0, 0.0, b))
    free = integrate(t, dth, dv, lat, 0.3, h, np.zeros(3), C, t0=0.0)
    eps = 1e-3
    k2 = -(normal_gravity(lat, h + eps) - normal_gravity(lat, h - eps)) / (2 * eps)  # ≈ 2g/R
    k = np.sqrt(k2)
    pred = b / k2 * (np.cosh(k * free.t) - 1.0)
    assert free.h[-1] - h > 1000.0  # 30 min: ~1.7 km from a 50 µg error
    assert (free.h[-1] - h) / pred[-1] == pytest.approx(1.0, abs=0.01)
    fixed = integrate(t, dth, dv, lat, 0.3, h, np.zeros(3), C, t0=0.0, vertical="fixed")
    assert np.all(fixed.h == h)
    assert np.abs(fixed.velocity_n).max() < 1e-6


def test_seed_gravity_constants_open_the_vertical_channel():
    """Seed 004 (4) rounded γe, γp read ~20-30 mGal low: tens of metres in 10 min (DESIGN §7)."""
    lat, h = np.radians(55.75), 150.0
    C = np.eye(3)
    t, dth, dv = static_increments(lat, h, C, 0.1, 6000)
    exact = integrate(t, dth, dv, lat, 0.0, h, np.zeros(3), C, t0=0.0)
    seed = integrate(t, dth, dv, lat, 0.0, h, np.zeros(3), C, t0=0.0, seed_gravity=True)
    assert np.abs(exact.h - h).max() < 1e-3
    dg = float(normal_gravity(lat, h) - normal_gravity(lat, h, seed_constants=True))
    assert 18e-5 < dg < 33e-5
    eps = 1e-3
    k2 = -(normal_gravity(lat, h + eps) - normal_gravity(lat, h - eps)) / (2 * eps)
    pred = dg / k2 * (np.cosh(np.sqrt(k2) * 600.0) - 1.0)
    assert seed.h[-1] - h == pytest.approx(pred, rel=0.01)
    assert seed.h[-1] - h > 40.0


def test_deflection_of_the_vertical_sign_and_effect():
    """A plumb line deflected by ξ = −20″ (to the North): gravity has a northward component."""
    lat, h = np.radians(40.0), 0.0
    xi, eta = np.radians(-20 / 3600), np.radians(8 / 3600)
    gam = float(normal_gravity(lat, h))
    C = att.dcm_nb_from_euler(0.01, 0.02, 0.5)
    # specific force at rest is −g^n = (γη, γξ, γ) with g^n = (−γη, −γξ, −γ)
    t, dth, dv = static_increments(lat, h, C, 0.05, 72_000, g_h=(gam * eta, gam * xi, gam))
    ok = integrate(t, dth, dv, lat, 0.0, h, np.zeros(3), C, t0=0.0, vertical="fixed",
                   deflection=(xi, eta))
    assert horizontal_error(ok, lat, 0.0, h).max() < 1e-3
    ignored = integrate(t, dth, dv, lat, 0.0, h, np.zeros(3), C, t0=0.0, vertical="fixed")
    # unmodelled: a Schuler oscillation about R_φ ξ away, i.e. up to 2 R ξ ≈ 1.2 km
    assert horizontal_error(ignored, lat, 0.0, h).max() > 500.0
    wrong_sign = integrate(t, dth, dv, lat, 0.0, h, np.zeros(3), C, t0=0.0, vertical="fixed",
                           deflection=(-xi, -eta))
    assert horizontal_error(wrong_sign, lat, 0.0, h).max() > 1000.0


def test_analytic_turning_coning_trajectory(analytic_run):
    """10 min of a 21 m/s turn with 3-4° pitch/roll oscillations, exact increments at 100 Hz."""
    te, dth, dv = analytic_run
    hor, dh, dvel, datt = _run_analytic(te, dth, dv)
    assert hor < 0.05  # measured 0.010 m
    assert dh < 0.01  # free vertical channel
    assert dvel < 1e-3
    assert datt < 2e-7
    # the corrections matter: without coning the attitude error is ~500x larger ...
    assert _run_analytic(te, dth, dv, coning=False)[3] > 100 * datt
    # ... and without the rotation/sculling terms the position error is metres
    assert _run_analytic(te, dth, dv, sculling=False)[0] > 1.0


def test_batch_and_streaming_are_identical(analytic_run):
    te, dth, dv = analytic_run
    n = 3000
    lat, lon, h, *_ = geodetic(te[:1])
    v0, C0 = velocity_true(te[:1])[0], C_nb_true(te[:1])[0]
    batch = integrate(te[1:n + 1], dth[:n], dv[:n], lat[0], lon[0], h[0], v0, C0, t0=0.0)
    ins = Strapdown(lat[0], lon[0], h[0], v0, C0, t=0.0)
    states = [ins.update(dth[k], dv[k], te[k + 1] - te[k]) for k in range(n)]
    assert np.array_equal(batch.lat[1:], [s.lat for s in states])
    assert np.array_equal(batch.lon[1:], [s.lon for s in states])
    assert np.array_equal(batch.h[1:], [s.h for s in states])
    assert np.array_equal(batch.velocity_n[1:], np.array([s.velocity_n for s in states]))
    assert np.array_equal(batch.C_nb[1:], np.array([s.C_nb for s in states]))
    # and in chunks
    ins2 = Strapdown(lat[0], lon[0], h[0], v0, C0, t=0.0)
    a = ins2.run(te[1:1001], dth[:1000], dv[:1000])
    b = ins2.run(te[1001:n + 1], dth[1000:n], dv[1000:n])
    assert np.array_equal(np.concatenate([a.lat, b.lat]), batch.lat[1:])
    assert np.array_equal(np.concatenate([a.C_nb, b.C_nb]), batch.C_nb[1:])
    assert ins.t == pytest.approx(te[n])


def test_rate_input_equals_increments():
    lat, h = np.radians(30.0), 0.0
    C = att.dcm_nb_from_euler(0.1, 0.2, 0.3)
    t, dth, dv = static_increments(lat, h, C, 0.02, 500)
    rng = np.random.default_rng(1)
    dth = dth + rng.normal(size=dth.shape) * 1e-4
    dv = dv + rng.normal(size=dv.shape) * 1e-3
    a = integrate(t, dth, dv, lat, 0.0, h, np.zeros(3), C, t0=0.0)
    b = integrate(t, dth / 0.02, dv / 0.02, lat, 0.0, h, np.zeros(3), C, t0=0.0, rates=True)
    np.testing.assert_allclose(b.lat, a.lat, rtol=0, atol=1e-15)
    np.testing.assert_allclose(b.velocity_n, a.velocity_n, rtol=0, atol=1e-12)
    w, f, t0 = increments_from_rates(t, dth / 0.02, dv / 0.02)
    assert t0 == pytest.approx(0.0)


def test_slow_period_speed_reads_the_erratum(analytic_run):
    """Seed 004 (11): mean speed over the slow period, not T0·|n| (which carries gravity)."""
    te, dth, dv = analytic_run
    n = 2000
    v = velocity_true(te[:n + 1])
    C = C_nb_true(te[:n + 1])
    k_m = 100
    by_v = slow_period_speed(v, k_m)
    assert by_v.shape == (n // k_m,)
    ref = np.linalg.norm(v[1:], axis=1).reshape(-1, k_m).mean(axis=1)
    np.testing.assert_allclose(by_v, ref)
    lat, _, h, *_ = geodetic(te[:n])
    by_acc = slow_period_speed(v, k_m, dv=dv[:n], C_nb=C, dt=np.diff(te[:n + 1]),
                               g=normal_gravity(lat, h))
    np.testing.assert_allclose(by_acc, by_v, atol=0.02)  # Coriolis and lateral terms neglected
    # the printed formula gives ~|g|, not a speed
    printed = np.linalg.norm(dv[:n], axis=1).reshape(-1, k_m).mean(axis=1) / 0.01
    assert np.all(printed > 9.0)


def test_bad_input_is_refused():
    C = np.eye(3)
    with pytest.raises(SelfnavError, match="increase"):
        integrate([0.1, 0.1], np.zeros((2, 3)), np.zeros((2, 3)), 0.5, 0.0, 0.0, np.zeros(3), C,
                  t0=0.0)
    with pytest.raises(SelfnavError, match="vertical"):
        Strapdown(0.5, 0.0, 0.0, np.zeros(3), C, vertical="damped")
    with pytest.raises(SelfnavError, match="rotation"):
        Strapdown(0.5, 0.0, 0.0, np.zeros(3), 2 * C)


def test_round_trip_of_a_simulated_road_drive():
    """Issue 3 round trip: a 10-min car drive, exact inverse strapdown at 200 Hz, < 0.1 m."""
    from selfnav.roads.graph import packaged_map, read_roads
    from selfnav.sim.car import car_trajectory
    from selfnav.sim.inverse import imu_from_trajectory

    graph = read_roads(packaged_map("kotka_karhula"))
    traj = car_trajectory(graph, duration=600.0, dt=0.01, seed=3)
    imu, truth = imu_from_trajectory(traj, 0.005, return_truth=True)
    m = imu.meta
    sol = integrate(imu.t, m["dtheta"], m["dv"], truth.lat[0], truth.lon[0], truth.h[0],
                    truth.velocity_n[0], truth.C_nb[0], t0=m["t0"])
    hor = horizontal_error(sol, truth.lat, truth.lon, truth.h)
    assert hor.max() < 0.1  # measured 0.062 m (free vertical channel, too)
    assert np.abs(sol.h - truth.h).max() < 0.01  # measured 1.4 mm
