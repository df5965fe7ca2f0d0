"""Exact inverse strapdown (issue 3): increments against independent oracles, round trips."""
import numpy as np
import pytest

from selfnav import attitude as att
from selfnav import earth
from selfnav.sim.inverse import TrajectorySpline, imu_from_trajectory
from selfnav.sim.static import static_imu
from selfnav.types import Trajectory

LAT0, LON0, H0 = np.radians(50.45), np.radians(30.52), 100.0
OMEGA_E = np.array([0.0, 0.0, earth.OMEGA_EARTH])


def _gauss(a, b, fun, nodes=5):
    """∫_a^b fun(t) dt per interval by Gauss-Legendre (the oracle's own quadrature)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    out = 0.0
    for xi, wi in zip(x, w):
        out = out + 0.5 * (b - a)[:, None] * wi * fun(0.5 * (a + b) + 0.5 * (b - a) * xi)
    return out


def _rate_from_dcm(C_nb_fun, t, h=1e-4):
    """Body rate of ``C_b^n(t)`` by a central difference of the rotation between t-h and t+h."""
    Cm, Cp = C_nb_fun(t - h), C_nb_fun(t + h)
    return att.dcm_to_rotvec(Cm @ np.swapaxes(Cp, -1, -2)) / (2 * h)


def test_static_matches_static_simulator():
    t = np.arange(0.0, 60.0 + 1e-9, 1.0)
    n = len(t)
    C = att.dcm_nb_from_euler(0.1, -0.05, 1.0)
    traj = Trajectory(t, np.full(n, LAT0), np.full(n, LON0), np.full(n, H0), np.zeros((n, 3)),
                      np.tile(C, (n, 1, 1)))
    imu = imu_from_trajectory(traj, 0.01)
    ref = static_imu(LAT0, 60.0, 0.01, roll=0.1, pitch=-0.05, heading=1.0, h=H0)
    assert len(imu) == len(ref) == 6000
    np.testing.assert_allclose(imu.t, ref.t, atol=1e-9)
    np.testing.assert_allclose(imu.omega_ib_b, ref.omega_ib_b, atol=1e-15)
    np.testing.assert_allclose(imu.f_ib_b, ref.f_ib_b, atol=1e-12)
    np.testing.assert_allclose(imu.meta["dtheta"], ref.omega_ib_b * 0.01, atol=1e-17)


def _coning_C_nb(t):
    """Coning motion: the body axis z precesses at 2 Hz with 2° half-angle, plus a slow yaw."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    a, w = np.radians(2.0), 2 * np.pi * 2.0
    rv = np.column_stack([a * np.cos(w * t), a * np.sin(w * t), np.zeros_like(t)])
    C_bn = np.einsum("ij,njk->nik", att.dcm_bn_from_euler(0.0, 0.0, 0.3),
                     att.rotvec_to_dcm(rv) @ att.rotvec_to_dcm(np.column_stack(
                         [np.zeros_like(t), np.zeros_like(t), 0.01 * t])))
    return np.swapaxes(C_bn, -1, -2)


def _integrate_attitude(dth, C_bn0, om_ie_n, dt, coning=True):
    """Body-frame rotation vector with the two-sample coning term; Earth rate in nav frame."""
    C_bn = C_bn0
    E = att.rotvec_to_dcm(-om_ie_n * dt)
    prev = np.zeros(3)
    for d in dth:
        C_bn = E @ C_bn @ att.rotvec_to_dcm(d + (np.cross(prev, d) / 12.0 if coning else 0.0))
        prev = d
    return C_bn


def test_rotation_only_coning_increments_and_attitude_round_trip():
    dt, T = 0.01, 20.0
    t = np.arange(0.0, T + 1e-9, 0.002)          # trajectory at 500 Hz, IMU at 100 Hz
    n = len(t)
    traj = Trajectory(t, np.full(n, LAT0), np.full(n, LON0), np.full(n, H0), np.zeros((n, 3)),
                      _coning_C_nb(t))
    imu = imu_from_trajectory(traj, dt)
    dth = imu.meta["dtheta"]
    # oracle: ω_ib^b = ω_nb^b + C_n^b ω_ie^n at a fixed position, integrated over each interval
    om_ie_n = earth.earth_rate_n(LAT0)
    a, b = imu.t - dt, imu.t
    ref = _gauss(a, b, lambda s: _rate_from_dcm(_coning_C_nb, s) + _coning_C_nb(s) @ om_ie_n)
    np.testing.assert_allclose(dth, ref, atol=2e-9)   # |Δθ| up to 1e-2 rad
    # integrated with the two-sample coning algorithm, the increments do as well as the
    # oracle's exact integrals (the rest is the algorithm's own error for 2 Hz coning)
    C0 = _coning_C_nb(0.0)[0].T
    C_true = _coning_C_nb(imu.t[-1])[0]
    e_ours = att.dcm_to_rotvec(_integrate_attitude(dth, C0, om_ie_n, dt) @ C_true)
    e_ref = att.dcm_to_rotvec(_integrate_attitude(ref, C0, om_ie_n, dt) @ C_true)
    e_noconing = att.dcm_to_rotvec(_integrate_attitude(dth, C0, om_ie_n, dt, False) @ C_true)
    assert np.linalg.norm(e_ours - e_ref) < 2e-7
    assert np.linalg.norm(e_ours) < 3e-6
    assert np.linalg.norm(e_noconing) > 30 * np.linalg.norm(e_ours)


@pytest.mark.slow
def test_rotation_only_slow_motion_returns_attitude():
    """Slow tumbling (0.05 Hz): the coning algorithm is then exact enough to see our error."""
    def C_nb(t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        rv = np.column_stack([0.3 * np.sin(0.3 * t), 0.2 * np.cos(0.2 * t), 0.05 * t])
        return np.swapaxes(att.rotvec_to_dcm(rv), -1, -2)

    dt = 0.01
    t = np.arange(0.0, 120.0 + 1e-9, dt)
    n = len(t)
    imu = imu_from_trajectory(Trajectory(t, np.full(n, LAT0), np.full(n, LON0), np.full(n, H0),
                                         np.zeros((n, 3)), C_nb(t)), dt)
    C = _integrate_attitude(imu.meta["dtheta"], C_nb(0.0)[0].T, earth.earth_rate_n(LAT0), dt)
    assert np.linalg.norm(att.dcm_to_rotvec(C @ C_nb(imu.t[-1])[0])) < 1e-9


class _Circle:
    """A constant-rate level turn (radius 200 m, 20 m/s) defined in ECEF, with a 0.2 rad bank."""

    E = earth.enu_rotation(LAT0, LON0)
    r0 = earth.geodetic_to_ecef(LAT0, LON0, H0)
    R, w = 200.0, 0.1

    def ecef(self, t):
        t = np.asarray(t, dtype=float)[:, None]
        c, s = np.cos(self.w * t), np.sin(self.w * t)
        r = self.r0 + self.R * ((c - 1) * self.E[0] + s * self.E[1])
        v = self.R * self.w * (-s * self.E[0] + c * self.E[1])
        a = -self.R * self.w ** 2 * (c * self.E[0] + s * self.E[1])
        return r, v, a

    def state(self, t):
        r, v, a = self.ecef(t)
        lat, lon, h = earth.ecef_to_geodetic(r)
        C_en = np.stack([earth.enu_rotation(la, lo) for la, lo in zip(lat, lon)])
        vn = np.einsum("nij,nj->ni", C_en, v)
        hd = np.arctan2(vn[:, 0], vn[:, 1])
        pt = np.arcsin(vn[:, 2] / np.linalg.norm(vn, axis=1))
        C = att.dcm_nb_from_euler(np.full_like(hd, 0.2), pt, hd)
        return lat, lon, h, vn, C, C_en, r, v, a

    def sensors(self, t):
        """ω_ib^b and f^b from the ECEF formulation: f = r̈ + 2Ω×ṙ − g, an independent path."""
        lat, lon, h, vn, C, C_en, r, v, a = self.state(t)
        f_e = a + 2 * np.cross(OMEGA_E, v) + earth.normal_gravity(lat, h)[:, None] * C_en[:, 2]
        f_b = np.einsum("nij,njk,nk->ni", C, C_en, f_e)
        C_eb = lambda s: np.einsum("nij,njk->nik", self.state(s)[4], self.state(s)[5])  # noqa
        om_eb_b = _rate_from_dcm(C_eb, t)
        return om_eb_b + np.einsum("nij,j->ni", C_eb(t), OMEGA_E), f_b


def test_constant_rate_turn_matches_ecef_oracle():
    c = _Circle()
    dt = 0.01
    t = np.arange(0.0, 60.0 + 1e-9, dt)
    lat, lon, h, vn, C, *_ = c.state(t)
    imu, truth = imu_from_trajectory(Trajectory(t, lat, lon, h, vn, C), dt, return_truth=True)
    k = np.arange(0, len(imu), 53)
    a, b = imu.t[k] - dt, imu.t[k]
    ref_w = _gauss(a, b, lambda s: c.sensors(s)[0])
    ref_f = _gauss(a, b, lambda s: c.sensors(s)[1])
    np.testing.assert_allclose(imu.meta["dtheta"][k], ref_w, atol=1e-10)
    np.testing.assert_allclose(imu.meta["dv"][k], ref_f, atol=1e-6)   # 1e-5 of |Δv| ≈ 0.098
    # truth from the spline equals the analytic motion
    np.testing.assert_allclose(truth.velocity_n, vn, atol=2e-6)
    np.testing.assert_allclose(truth.lat, lat, atol=1e-13)


@pytest.mark.slow
def test_round_trip_through_strapdown_turn_and_aircraft():
    from selfnav.ins import strapdown as sd
    from selfnav.sim.aircraft import aircraft_trajectory

    c = _Circle()
    t = np.arange(0.0, 600.0 + 1e-9, 0.01)
    lat, lon, h, vn, C, *_ = c.state(t)
    cases = [Trajectory(t, lat, lon, h, vn, C),
             aircraft_trajectory(900.0, 0.01, LAT0, LON0, 500.0, seed=1)]
    for traj in cases:
        imu, tr = imu_from_trajectory(traj, 0.01, return_truth=True)
        out = sd.integrate(imu.t, imu.meta["dtheta"], imu.meta["dv"], tr.lat[0], tr.lon[0],
                           tr.h[0], tr.velocity_n[0], tr.C_nb[0], t0=tr.t[0])
        R_phi, R_lam = earth.radii(tr.lat, tr.h)
        e = np.hypot((out.lat - tr.lat) * R_phi, (out.lon - tr.lon) * R_lam * np.cos(tr.lat))
        assert e.max() < 1e-3, e.max()                  # < 1 mm after 10-15 min
        assert np.abs(out.h - tr.h).max() < 1e-3


def test_static_hour_round_trip_below_a_millimetre():
    from selfnav.ins import strapdown as sd
    t = np.arange(0.0, 3600.0 + 1e-9, 10.0)
    n = len(t)
    C = att.dcm_nb_from_euler(0.02, 0.01, 2.0)
    traj = Trajectory(t, np.full(n, LAT0), np.full(n, LON0), np.full(n, H0), np.zeros((n, 3)),
                      np.tile(C, (n, 1, 1)))
    imu = imu_from_trajectory(traj, 0.01)
    out = sd.integrate(imu.t, imu.meta["dtheta"], imu.meta["dv"], LAT0, LON0, H0, np.zeros(3),
                       C, t0=0.0)
    R_phi, R_lam = earth.radii(LAT0, H0)
    e = np.hypot((out.lat - LAT0) * R_phi, (out.lon - LON0) * R_lam * np.cos(LAT0))
    assert e.max() < 1e-3


def test_spline_kinematics_are_consistent():
    """Velocity from the spline is the derivative of its position (central difference)."""
    from selfnav.sim.aircraft import aircraft_trajectory

    sp = TrajectorySpline(aircraft_trajectory(300.0, 0.05, LAT0, LON0, 500.0))
    ts = np.linspace(10, 290, 50)
    k = sp.kinematics(ts)
    hh = 1e-3
    kp, km = sp.kinematics(ts + hh, rates=False), sp.kinematics(ts - hh, rates=False)
    R_phi, R_lam = earth.radii(k["lat"], k["h"])
    v_num = np.column_stack([(kp["lon"] - km["lon"]) / (2 * hh) * R_lam * np.cos(k["lat"]),
                             (kp["lat"] - km["lat"]) / (2 * hh) * R_phi,
                             (kp["h"] - km["h"]) / (2 * hh)])
    np.testing.assert_allclose(k["velocity_n"], v_num, atol=1e-5)
    a_num = (kp["velocity_n"] - km["velocity_n"]) / (2 * hh)
    np.testing.assert_allclose(k["accel_n"], a_num, atol=1e-5)
