"""Measurement models for the tightly coupled filter (selfnav.gnss.models): Jacobians against
finite differences; orbits (selfnav.gnss.ephemeris) against vis-viva and an independent ODE
solver; atmosphere models against their known magnitudes."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from selfnav.earth import OMEGA_EARTH, geodetic_to_ecef
from selfnav.gnss import ephemeris as ephm
from selfnav.gnss.atmosphere import klobuchar, saastamoinen
from selfnav.gnss.models import (doppler_model, ecef_to_enu_jacobian, ecef_to_geodetic_jacobian,
                                 pseudorange_model)
from selfnav.gnss.spp import C_LIGHT, sagnac_rotate
from selfnav.io.gnss_raw import GLONASS, GPS, Ephemerides
from selfnav.sim.satellites import ION_ALPHA, ION_BETA, walker_ephemerides

RNG = np.random.default_rng(7)
LAT, LON, HGT = np.radians(48.1), np.radians(11.6), 520.0
RX = geodetic_to_ecef(LAT, LON, HGT)


def sats(n=9):
    eph = walker_ephemerides(1.4e9)
    idx = np.arange(n)
    pos, vel, _, _ = ephm.satellite_states(eph, idx, np.full(n, 1.4e9 + 100.0))
    return pos, vel


def test_pseudorange_jacobian_matches_finite_differences():
    s, _ = sats()
    x = np.r_[RX, 1234.5]
    rho, H = pseudorange_model(x[:3], x[3], s)
    J = np.empty_like(H)
    for k in range(4):
        d = np.zeros(4)
        d[k] = 1.0
        rp, _ = pseudorange_model((x + d)[:3], (x + d)[3], s)
        rm, _ = pseudorange_model((x - d)[:3], (x - d)[3], s)
        J[:, k] = (rp - rm) / 2.0
    assert np.max(np.abs(J - H)) < 1e-7
    # the first-order Earth-rotation term agrees with the exact rotation to 2 mm
    exact = np.linalg.norm(sagnac_rotate(s, RX) - RX, axis=1) + 1234.5
    assert np.max(np.abs(rho - exact)) < 2e-3


def test_doppler_jacobian_matches_finite_differences():
    s, vs = sats()
    v = np.array([12.0, -3.0, 0.5])
    x = np.r_[RX, v, 45.0]

    def f(x):
        return doppler_model(x[:3], x[3:6], x[6], s, vs, 3.0)[0]

    rate, H = doppler_model(x[:3], x[3:6], x[6], s, vs, 3.0)
    J = np.empty_like(H)
    for k in range(7):
        d = np.zeros(7)
        d[k] = 10.0 if k < 3 else 1.0
        J[:, k] = (f(x + d) - f(x - d)) / (2 * d[k])
    assert np.max(np.abs(J[:, :3] - H[:, :3])) < 1e-9
    assert np.max(np.abs(J[:, 3:] - H[:, 3:])) < 1e-8
    # the model is the time derivative of the pseudorange model along the motion
    dt = 0.5
    r1, _ = pseudorange_model(RX - v * dt, 0.0, s - vs * dt)
    r2, _ = pseudorange_model(RX + v * dt, 0.0, s + vs * dt)
    assert np.max(np.abs((r2 - r1) / (2 * dt) - doppler_model(RX, v, 0.0, s, vs)[0])) < 2e-5


def test_models_broadcast_over_epochs_and_satellites():
    s, vs = sats(6)
    rx = np.broadcast_to(RX, (4, 6, 3))
    rho, H = pseudorange_model(rx, np.zeros((4, 6)), np.broadcast_to(s, (4, 6, 3)))
    assert rho.shape == (4, 6) and H.shape == (4, 6, 4)
    rate, Hd = doppler_model(rx, np.zeros((4, 6, 3)), 0.0, np.broadcast_to(s, (4, 6, 3)),
                             np.broadcast_to(vs, (4, 6, 3)))
    assert rate.shape == (4, 6) and Hd.shape == (4, 6, 7)


def test_enu_and_geodetic_jacobians():
    s, _ = sats()
    _, H = pseudorange_model(RX, 0.0, s)
    He = ecef_to_enu_jacobian(H[:, :3], LAT, LON)
    Hg = ecef_to_geodetic_jacobian(H[:, :3], LAT, LON, HGT)
    for k, (dlat, dlon, dh) in enumerate(((1e-7, 0, 0), (0, 1e-7, 0), (0, 0, 0.1))):
        rp = pseudorange_model(geodetic_to_ecef(LAT + dlat, LON + dlon, HGT + dh), 0.0, s)[0]
        rm = pseudorange_model(geodetic_to_ecef(LAT - dlat, LON - dlon, HGT - dh), 0.0, s)[0]
        step = dlat or dlon or dh
        assert np.allclose((rp - rm) / (2 * step), Hg[:, k], rtol=1e-5, atol=1e-5)
    # ENU: up is the line of sight's vertical part (−sin E)
    up = -np.einsum("ij,j->i", (s - RX) / np.linalg.norm(s - RX, axis=1)[:, None],
                    RX / np.linalg.norm(RX))
    assert np.corrcoef(He[:, 2], up)[0, 1] > 0.999


def test_kepler_orbits_obey_vis_viva_and_rotate_with_the_earth():
    eph = walker_ephemerides(1.4e9)
    n = len(eph)
    t = 1.4e9 + np.linspace(-3600, 3600, n)
    pos, vel, clk, drift = ephm.satellite_states(eph, np.arange(n), t)
    r = np.linalg.norm(pos, axis=1)
    v_inertial = vel + np.cross([0, 0, ephm.OMEGA_E_GPS], pos)
    a = eph.sqrt_a**2
    mu = np.where(eph.system == GPS, ephm.MU_GPS, ephm.MU_GAL)
    assert np.allclose(np.linalg.norm(v_inertial, axis=1), np.sqrt(mu * (2 / r - 1 / a)),
                       rtol=2e-5)
    assert np.all(np.abs(r - a) <= a * eph.e + 1)
    # relativistic clock term −2 r·v / c² (IS-GPS-200 20.3.3.3.3.1, equivalent form)
    rel = -2 * np.einsum("ij,ij->i", pos, v_inertial) / C_LIGHT**2
    assert np.allclose(clk - eph.af0 - eph.af1 * (t - eph.toc), rel, atol=2e-11)


def test_glonass_runge_kutta_matches_an_independent_ode_solver():
    row = dict(system=GLONASS, prn=3, toe=1.4e9, toc=1.4e9, glo_k=5, health=0.0,
               x=-1.4e7, y=1.7e7, z=1.2e7, vx=-1.2e3, vy=-2.1e3, vz=1.6e3,
               ax=1e-6, ay=-2e-6, az=-1.5e-6, tau_n=1e-5, gamma_n=1e-12)
    eph = Ephemerides.from_rows([row])

    def rhs(_, y):
        return ephm._glonass_accel(y[None], np.array([[1e-6, -2e-6, -1.5e-6]]))[0]

    for dt in (900.0, -900.0):
        ref = solve_ivp(rhs, (0, dt), [row[k] for k in ("x", "y", "z", "vx", "vy", "vz")],
                        method="DOP853", rtol=1e-12, atol=1e-6).y[:, -1]
        p, v = ephm.glonass_state(eph, [0], [1.4e9 + dt])
        assert np.linalg.norm(p[0] - ref[:3]) < 0.01
        assert np.linalg.norm(v[0] - ref[3:]) < 1e-5
    _, _, clk, drift = ephm.satellite_states(eph, [0], [1.4e9 + 100.0])
    assert np.isclose(clk[0], -1e-5 + 1e-10) and drift[0] == 1e-12


def test_atmosphere_magnitudes():
    # Saastamoinen zenith delay at sea level ≈ 2.3 m hydrostatic + ~0.1–0.3 m wet
    z = saastamoinen(np.radians(45), 0.0, np.pi / 2)
    assert 2.35 < z < 2.7
    assert saastamoinen(np.radians(45), 0.0, np.radians(10)) / z == pytest.approx(5.6, rel=0.05)
    # Klobuchar: at night the 5 ns floor times the slant factor; carrier scaling (f1/f)²
    t_night = 1.4e9 - np.mod(1.4e9, 86400) + 2 * 3600 + 43200 * np.radians(11.6) / np.pi * 0
    d1 = klobuchar(t_night, LAT, LON, 0.0, np.pi / 2, ION_ALPHA, ION_BETA)
    assert d1 == pytest.approx(C_LIGHT * 5e-9 * (1 + 16 * (0.53 - 0.5) ** 3), rel=1e-6)
    d5 = klobuchar(t_night, LAT, LON, 0.0, np.pi / 2, ION_ALPHA, ION_BETA, 1176.45e6)
    assert d5 / d1 == pytest.approx((1575.42 / 1176.45) ** 2)
    noon = t_night + 12 * 3600 - 2 * 3600 - 43200 * LON / np.pi
    assert klobuchar(noon, LAT, LON, 0.0, np.pi / 2, ION_ALPHA, ION_BETA) > 2 * d1
