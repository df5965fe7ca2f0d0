"""KF-GINS text formats (IMU increments FRD, GNSS with σ NED, .nav NED/ZYX) and NMEA RMC."""
import numpy as np
import pytest

from selfnav import attitude as att
from selfnav.errors import InputError
from selfnav.types import GnssData
from selfnav.types import ImuData
from selfnav.io.kfgins import (c_nb_enu_rfu, frd_to_rfu, kfgins_euler, read_kfgins_gnss,
                               read_kfgins_imu, read_kfgins_nav, write_kfgins_gnss,
                               write_kfgins_imu, write_kfgins_nav)
from selfnav.io.nmea_rmc import KNOT, read_nmea_rmc
from selfnav.types import Trajectory

D = np.pi / 180


# ------------------------------------------------------------------ frames on a known attitude
def test_known_attitude_ned_frd_to_enu_rfu():
    roll, pitch, yaw = 10 * D, 20 * D, 30 * D
    C_nb = c_nb_enu_rfu(roll, pitch, yaw)
    r, p, h = att.euler_from_dcm_nb(C_nb)
    assert np.allclose([r, p, h], [roll, pitch, yaw], atol=1e-12)
    # DESIGN §2 axis check: forward axis in ENU
    fwd = C_nb[1]
    assert np.allclose(fwd, [np.cos(pitch) * np.sin(yaw), np.cos(pitch) * np.cos(yaw), np.sin(pitch)])
    # right wing down for positive roll: the right axis has a negative Up component
    assert C_nb[0, 2] < 0
    assert np.allclose(C_nb @ C_nb.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(C_nb), 1.0)


def test_yaw_west_and_round_trip_euler():
    rng = np.random.default_rng(3)
    ang = np.column_stack([rng.uniform(-np.pi, np.pi, 50), rng.uniform(-1.4, 1.4, 50),
                           rng.uniform(-np.pi, np.pi, 50)])
    C = c_nb_enu_rfu(*ang.T)
    back = np.column_stack(kfgins_euler(C))
    assert np.allclose(back, ang, atol=1e-10)
    # yaw −90° (KF-GINS) is heading 270° (selfnav): forward points West
    C = c_nb_enu_rfu(0.0, 0.0, -90 * D)
    assert np.allclose(C[1], [-1, 0, 0], atol=1e-12)


def test_frd_to_rfu_vectors():
    g = 9.8
    # level at rest: FRD accelerometers read (0, 0, −g), RFU reads +g up
    assert np.allclose(frd_to_rfu([0, 0, -g]), [0, 0, g])
    # turning right (clockwise from above): FRD z-rate positive, RFU z-rate negative
    assert np.allclose(frd_to_rfu([0, 0, 0.1]), [0, 0, -0.1])
    # forward acceleration: FRD x → RFU y
    assert np.allclose(frd_to_rfu([1.0, 0, 0]), [0, 1.0, 0])
    v = np.arange(12.0).reshape(4, 3)
    assert np.allclose(frd_to_rfu(frd_to_rfu(v)), v)


# ------------------------------------------------------------------ round trips
def _imu(n=500, dt=0.005, t0=345600.0):
    rng = np.random.default_rng(1)
    t = t0 + dt * np.arange(1, n + 1)
    w = rng.normal(0, 0.05, (n, 3))
    f = rng.normal(0, 0.5, (n, 3)) + [0.0, 0.0, 9.8]
    return ImuData(t, w, f, source="simulated")


def test_imu_round_trip(tmp_path):
    imu = _imu()
    p = write_kfgins_imu(tmp_path / "imu.txt", imu)
    back = read_kfgins_imu(p)
    assert np.allclose(back.t, imu.t, rtol=0, atol=1e-9)
    assert np.allclose(back.omega_ib_b, imu.omega_ib_b, rtol=1e-12, atol=1e-15)
    assert np.allclose(back.f_ib_b, imu.f_ib_b, rtol=1e-12, atol=1e-12)
    # the file is FRD increments: column 7 (dv_down) ≈ −g·dt at rest-like data
    raw = np.loadtxt(p)
    assert raw.shape == (500, 7)
    assert np.isclose(raw[:, 6].mean(), -9.8 * 0.005, rtol=0.01)
    assert np.allclose(raw[:, 1], imu.omega_ib_b[:, 1] * 0.005)  # gyro x (front) = RFU y


def test_imu_extra_columns_and_comments(tmp_path):
    p = tmp_path / "imu.txt"
    p.write_text("# sow dth dv odo\n100.000 0.001 0 0 0 0 -0.049 0.1\n100.005 0.001 0 0 0 0 -0.049 0.1\n"
                 "100.010 0.001 0 0 0 0 -0.049 0.1\n")
    imu = read_kfgins_imu(p)
    assert imu.meta["extra_columns"] == 1
    assert np.allclose(imu.omega_ib_b[:, 1], 0.2)
    assert np.allclose(imu.f_ib_b[:, 2], 9.8)


def test_gnss_round_trip(tmp_path):
    n = 20
    t = 345600.0 + np.arange(n)
    lat = np.radians(30.5 + 1e-5 * np.arange(n))
    lon = np.radians(114.3 - 2e-5 * np.arange(n))
    h = 20.0 + 0.1 * np.arange(n)
    std = np.column_stack([np.full(n, 0.02), np.full(n, 0.03), np.full(n, 0.05)])  # E, N, U
    g = GnssData(t, lat, lon, h, np.full(n, 0.03), None, None, "simulated")
    p = write_kfgins_gnss(tmp_path / "gnss.txt", g, std)
    raw = np.loadtxt(p)
    assert np.allclose(raw[0, 4:7], [0.03, 0.02, 0.05])  # file order σN, σE, σD
    back, s = read_kfgins_gnss(p, return_std=True)
    assert np.allclose(back.t, t)
    assert np.allclose(back.lat, lat, rtol=0, atol=1e-13)
    assert np.allclose(back.lon, lon, rtol=0, atol=1e-13)
    assert np.allclose(back.h, h, atol=1e-6)
    assert np.allclose(s, std)
    assert np.allclose(back.sigma_m, 0.03)


def test_nav_round_trip(tmp_path):
    n = 30
    rng = np.random.default_rng(7)
    t = 345600.0 + 0.1 * np.arange(n)
    C = att.dcm_nb_from_euler(rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n),
                              rng.uniform(0, 2 * np.pi, n))
    v = rng.normal(0, 10, (n, 3))
    tr = Trajectory(t, np.radians(30.5 + 1e-6 * np.arange(n)), np.radians(114.3 + np.zeros(n)),
                    np.full(n, 20.0), v, C)
    p = write_kfgins_nav(tmp_path / "truth.nav", tr, week=2200)
    raw = np.loadtxt(p)
    assert np.allclose(raw[:, 5], v[:, 1], atol=1e-8)   # vN
    assert np.allclose(raw[:, 7], -v[:, 2], atol=1e-8)  # vD
    back = read_kfgins_nav(p)
    assert np.allclose(back.t, t, atol=1e-9)
    assert np.allclose(back.velocity_n, v, atol=1e-8)
    assert np.allclose(back.C_nb, C, atol=1e-12)
    assert np.allclose(back.lat, tr.lat, atol=1e-13)


def test_nav_known_row(tmp_path):
    p = tmp_path / "ref.nav"
    p.write_text("0 100.0 30.0 114.0 20.0 3.0 4.0 -1.0 2.0 5.0 -45.0\n"
                 "0 100.1 30.0 114.0 20.0 3.0 4.0 -1.0 2.0 5.0 315.0\n")
    tr = read_kfgins_nav(p)
    assert np.allclose(tr.velocity_n[0], [4.0, 3.0, 1.0])
    r, pt, h = att.euler_from_dcm_nb(tr.C_nb)
    assert np.allclose(np.degrees([r[0], pt[0], h[0]]), [2.0, 5.0, 315.0])
    assert np.isclose(np.degrees(h[1]), 315.0)


# ------------------------------------------------------------------ bad input
def test_bad_inputs(tmp_path):
    p = tmp_path / "imu.txt"
    p.write_text("100.00 0 0 0 0 0 -9.8\n100.01 0 0 0 0 0 -9.8\n100.02 0 0 0 0 0 -9.8\n")
    with pytest.raises(InputError, match="specific force"):
        read_kfgins_imu(p)
    p.write_text("100.00 0 0 0 0 0 -0.05\n100.01 0 0 0 0 -0.05\n")
    with pytest.raises(InputError, match="line 2"):
        read_kfgins_imu(p)
    p.write_text("100.00 0 0 0 0 0 -0.05\n100.01 0 0 0 0 0 -0.05\n100.005 0 0 0 0 0 -0.05\n")
    with pytest.raises(InputError, match="line 3.*backwards"):
        read_kfgins_imu(p)
    g = tmp_path / "gnss.txt"
    g.write_text("100 30.5 114.3 20 0.1 0.1 0.2\n101 3050.0 114.3 20 0.1 0.1 0.2\n")
    with pytest.raises(InputError, match="line 2.*latitude"):
        read_kfgins_gnss(g)
    g.write_text("sow lat lon h sn se sd\n100 30.5 114.3 20 0.1 0.1 0.2\n")
    with pytest.raises(InputError, match="line 1.*header"):
        read_kfgins_gnss(g)


# ------------------------------------------------------------------ NMEA RMC
def _cs(body):
    x = 0
    for ch in body:
        x ^= ord(ch)
    return f"${body}*{x:02X}"


def test_rmc(tmp_path):
    lines = [
        _cs("GPRMC,235959.00,A,4807.038,N,01131.000,E,10.0,90.0,311224,3.1,W,A"),
        _cs("GNRMC,000000.00,A,4807.038,S,01131.000,W,10.0,180.0,010125,,,D"),
        _cs("GPRMC,000001.00,V,,,,,,,010125,,,N"),
        "$GPRMC,000002.00,A,4807.038,N,01131.000,E,0.0,,010125,,,A*00",   # bad checksum
        _cs("GPRMC,000003.00,A,4807.038,N,01131.000,E,0.0,,010125,,,A"),
        _cs("GPGGA,000003.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),
    ]
    p = tmp_path / "log.nmea"
    p.write_text("\n".join(lines) + "\n")
    r = read_nmea_rmc(p)
    assert len(r) == 3
    assert r.rejected == {"status V (void)": 1, "checksum": 1}
    assert np.allclose(np.degrees(r.lat), [48.1173, -48.1173, 48.1173])
    assert np.allclose(np.degrees(r.lon), [11.516666667, -11.516666667, 11.516666667])
    assert np.allclose(r.velocity_n[0, :2], [10 * KNOT, 0.0], atol=1e-12)
    assert np.allclose(r.velocity_n[1, :2], [0.0, -10 * KNOT], atol=1e-12)
    assert np.allclose(r.velocity_n[2, :2], 0.0) and np.isnan(r.velocity_n[:, 2]).all()
    assert np.allclose(r.t, [86399.0, 86400.0, 86403.0])  # unwrapped over midnight by the date
    assert r.unix_utc[1] == 1735689600.0  # 2025-01-01T00:00:00Z
    assert np.isclose(np.degrees(r.mag_variation[0]), -3.1)
    assert list(r.mode) == ["A", "D", "A"]
    g = r.to_gnss(5.0)
    assert g.velocity_n.shape == (3, 3) and np.isnan(g.h).all()


def test_rmc_errors(tmp_path):
    p = tmp_path / "x.nmea"
    p.write_text(_cs("GPRMC,1200xx,A,4807.038,N,01131.000,E,1.0,10.0,010125,,,A") + "\n")
    with pytest.raises(InputError, match="line 1.*malformed"):
        read_nmea_rmc(p)
    p.write_text("hello\n")
    with pytest.raises(InputError, match="no valid RMC"):
        read_nmea_rmc(p)
