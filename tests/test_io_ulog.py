"""PX4 ULog (issue 20 item 5) on the real pyulog samples: IMU + magnetometer, GNSS, barometer and
the autopilot's attitude, FRD/NED converted to RFU/ENU once; into latitude and allan."""
import json

import numpy as np
import pytest

from selfnav import attitude as att
from selfnav.errors import InputError
from selfnav.io.readers import read_baro, read_gnss, read_imu
from selfnav.io.ulog import read_ulog_attitude
from support import run_cli


@pytest.fixture(scope="module")
def px4(shared_data):
    return shared_data / "px4_ulog_samples"


def test_handheld_log_reads(px4):
    imu = read_imu(px4 / "sample.ulg")                    # auto: .ulg
    assert imu.meta["format"] == "ulog" and imu.meta["axes"] == "FRD"
    assert len(imu) == 17070 and 1 / imu.dt == pytest.approx(248.8, abs=2)
    # at rest PX4 reads FRD (1.1, -0.5, -9.6) m/s²: up is +z in RFU, about 9.6 m/s²
    f = imu.f_ib_b[imu.t < imu.t[0] + 1.5].mean(axis=0)
    assert f[2] == pytest.approx(9.62, abs=0.05) and abs(f[0]) < 0.7 and abs(f[1]) < 1.5
    # the magnetometer (sensor_combined, Gauss) in nT, pointing down at ~48 000 nT
    m = imu.mag_b.mean(axis=0)
    assert 40000 < np.linalg.norm(m) < 55000 and m[2] < -35000
    assert imu.meta["attitude_estimator"].startswith("attitude_estimator_q")
    assert imu.meta["declination_deg"] == 0.0
    with pytest.raises(InputError, match="no vehicle_gps_position or sensor_gps"):
        read_gnss(px4 / "sample.ulg")


def test_small_log_gnss_baro_and_mag(px4):
    p = px4 / "sample_log_small.ulg"
    g = read_gnss(p)
    assert len(g) == 32 and g.quality[0] == 5                  # a 3-D fix: RTKLIB "single"
    assert np.degrees(g.lat[0]) == pytest.approx(63.4170622, abs=1e-7)
    assert np.degrees(g.lon[0]) == pytest.approx(10.4082151, abs=1e-7)
    assert g.h[0] == pytest.approx(106.766)                     # alt_ellipsoid, mm -> m
    assert g.sigma_m[0] == pytest.approx(3.26, abs=0.01)
    # NED velocity (0.047, -0.059, 0.242) -> ENU (-0.059, 0.047, -0.242)
    np.testing.assert_allclose(g.velocity_n[0], [-0.059, 0.047, -0.242], atol=1e-6)
    b = read_baro(p)
    assert len(b) == 120 and b.altitude_m[0] == pytest.approx(86.15, abs=0.01)
    assert b.pressure_pa[0] == pytest.approx(100294.49, abs=0.01)
    imu = read_imu(p)
    assert imu.mag_b is not None and imu.meta["attitude_estimator"] == "ekf2"
    # imu and GNSS share the log's boot-time base
    assert imu.t[0] < g.t[0] < g.t[-1] < imu.t[-1]


def test_attitude_conversion_frd_ned_to_rfu_enu(px4):
    """PX4's quaternion (FRD body -> NED) becomes C_nb ENU -> RFU: its Euler angles are PX4's
    yaw-pitch-roll (ZYX of the NED/FRD rotation), heading = yaw."""
    from pyulog import ULog
    from scipy.spatial.transform import Rotation

    a = read_ulog_attitude(px4 / "sample.ulg")
    u = ULog(str(px4 / "sample.ulg"), ["vehicle_attitude"])
    d = u.get_dataset("vehicle_attitude").data
    q = np.column_stack([d[f"q[{i}]"] for i in range(4)])
    ypr = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_euler("ZYX")
    r, p, h = att.euler_from_dcm_nb(a.C_nb)
    np.testing.assert_allclose(np.angle(np.exp(1j * (h - ypr[:, 0]))), 0, atol=1e-6)
    np.testing.assert_allclose(p, ypr[:, 1], atol=1e-6)
    np.testing.assert_allclose(r, ypr[:, 2], atol=1e-6)
    # and its tilt agrees with the accelerometers at rest (RFU up = f/|f|)
    imu = read_imu(px4 / "sample.ulg")
    k = np.searchsorted(a.t, imu.t[100])
    f = imu.f_ib_b[:200].mean(axis=0)
    assert np.degrees(np.arccos(a.C_nb[k][:, 2] @ f / np.linalg.norm(f))) < 0.5


def test_given_axes_describe_the_file_columns(px4):
    """--imu-axes on a ULog describes its columns: FRD (its own) gives the default reading;
    'detect' leaves them as logged."""
    base = read_imu(px4 / "sample_log_small.ulg")
    same = read_imu(px4 / "sample_log_small.ulg", axes="FRD")
    np.testing.assert_array_equal(same.f_ib_b, base.f_ib_b)
    raw = read_imu(px4 / "sample_log_small.ulg", axes="detect")
    assert raw.meta["axes_source"] == "detect"
    np.testing.assert_array_equal(raw.f_ib_b[:, 2], -base.f_ib_b[:, 2])
    np.testing.assert_array_equal(raw.f_ib_b[:, 0], base.f_ib_b[:, 1])


def test_bad_files_are_one_line(tmp_path):
    p = tmp_path / "x.ulg"
    p.write_bytes(b"not a ulog file at all")
    with pytest.raises(InputError, match="is not a PX4 ULog file"):
        read_imu(p)
    p.write_bytes(b"ULog\x01\x12\x35" + b"\x00" * 40)
    with pytest.raises(InputError, match="no logged messages"):
        read_imu(p)


def test_latitude_on_six_seconds_reports_low_confidence(px4, capsys):
    """6.5 s of a consumer IMU cannot gyrocompass: the answer says so (σ 90°, low), it does
    not claim a latitude (the log is at 63.4° N)."""
    code, out, err = run_cli(["latitude", px4 / "sample_log_small.ulg", "--json"], capsys)
    assert code == 0, err
    r = json.loads(out)
    assert r["confidence"] == "low" and r["sigma_deg"] >= 45.0
    assert r["sigma_heading_deg"] >= 90.0
    assert "does not determine the latitude" in err


def test_allan_reads_ulog(px4, capsys):
    code, out, err = run_cli(["allan", px4 / "sample.ulg", "--json"], capsys)
    assert code == 0, err
    r = json.loads(out)
    assert len(r["arw_deg_per_sqrt_h"]) == 3


def test_the_navigator_starts_at_rest_on_the_small_log(px4, tmp_path, capsys):
    """Real data (issue 20): 6.5 s at rest with GPS. The car's start never came (exit 2, "no
    run ... faster than 5.0 m/s"); as a drone it starts at rest, levelled within 0.1° of PX4's
    own attitude. Its heading is the uncalibrated magnetometer's: 18° from PX4's, inside the
    start's σ (≥ 20°), as selfnav's attitude filter on this log (15° RMS)."""
    p = px4 / "sample_log_small.ulg"
    out = tmp_path / "sol.csv"
    code, so, err = run_cli(["navigate", "--imu", p, "--gnss", p, "--out", out, "--platform",
                             "drone", "--json"], capsys)
    assert code == 0, err
    js = json.loads(so)
    assert js["start_kind"] == "rest" and js["start_heading"] == "magnetometer"
    from selfnav import read_solution

    sol = read_solution(out).trajectory
    ref = read_ulog_attitude(p)
    k = (ref.t >= sol.t[0]) & (ref.t <= sol.t[-1])
    r_ref, p_ref, h_ref = (np.degrees(a[k]).mean() for a in att.euler_from_dcm_nb(ref.C_nb))
    r, pi, h = (np.degrees(a).mean() for a in att.euler_from_dcm_nb(sol.C_nb))
    assert abs(r - r_ref) < 0.3 and abs(pi - p_ref) < 0.3
    assert abs((h - h_ref + 180) % 360 - 180) < 30.0
