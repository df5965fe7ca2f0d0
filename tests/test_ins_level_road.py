"""The level-road prior of a car (``VehicleConstraints.grade_sigma``): the pitch error a
consumer gyro bias drives after a start in motion, made visible through the vertical velocity."""
import math

import numpy as np
import pytest

import selfnav
from selfnav import attitude as att
from selfnav.ins.config import SLOW_PLATFORM, navigator_config
from selfnav.ins.ekf import InsGnssFilter
from selfnav.ins.measurements import LevelRoad, NonHolonomic


def _pitched_filter(pitch_err_deg, speed=11.0):
    """A car driving north on a level road, its INS pitched ``pitch_err_deg`` with the
    velocity pitched along (the NHC sees nothing: the drive of docs/realtime.md at 42 s)."""
    cfg = navigator_config("consumer", lever_arm_m=np.zeros(3))
    C_nb = att.dcm_nb_from_euler(0.0, math.radians(pitch_err_deg), 0.0)
    v_n = C_nb.T @ np.array([0.0, speed, 0.0])
    f = InsGnssFilter(cfg, 0.0, 0.7, 0.4, 10.0, v_n, C_nb)
    f.P[3:6, 3:6] = np.eye(3) * 1.0**2
    f.P[6:9, 6:9] = np.eye(3) * math.radians(4.0) ** 2
    return f, cfg


def _pitch_deg(f):
    return math.degrees(att.euler_from_dcm_nb(f.ins.C_nb)[1])


def test_the_nhc_alone_cannot_see_a_pitch_the_velocity_shares_and_the_level_prior_can():
    """10° of pitch with the velocity pitched along: the NHC's residual is zero and its
    update leaves the pitch; a level-road prior (σ 1 m/s for 11 m/s, the car's 0.08 grade)
    measures the 1.9 m/s vertical velocity and, through the NHC's coupling, the pitch: three
    seconds of it take the error from 10° to 5.2° at σ 2.4° (within 3σ)."""
    f, cfg = _pitched_filter(10.0)
    veh = cfg.vehicle
    nhc = NonHolonomic(veh.nhc_sigma, veh.nhc_sigma).model(f)
    assert np.max(np.abs(nhc.r)) < 1e-9
    f.update(nhc)
    assert abs(_pitch_deg(f) - 10.0) < 1e-6
    s_up = veh.grade_sigma * 11.0 + 0.1
    for _ in range(3):
        f.update(LevelRoad(s_up).model(f))
        f.update(NonHolonomic(veh.nhc_sigma, veh.nhc_sigma).model(f))
    err = _pitch_deg(f)
    C = f.ins.C_nb
    sigma_pitch = math.degrees(math.sqrt((C @ f.P[6:9, 6:9] @ C.T)[0, 0]))
    assert abs(err) < 6.0 and abs(err) < 3.0 * sigma_pitch, (err, sigma_pitch)


def test_a_car_has_the_prior_and_a_slow_platform_does_not():
    """Cars drive on roads: grades within 8 % (σ 0.08 of the speed), a grade holding over
    about 10 s (each second's prior carries a tenth of its information: at 1 s drive_0708's
    real 2–4 % grades pulled the pitch through its outages). A walker or a rover has no
    road to be level on."""
    car = navigator_config("auto").vehicle
    assert car.grade_sigma == 0.08 and car.grade_corr_s == 10.0
    assert navigator_config("auto", platform="pedestrian").vehicle.grade_sigma is None
    assert SLOW_PLATFORM["grade_sigma"] is None


@pytest.mark.long
def test_short_consumer_drives_started_in_motion_keep_their_sigma():
    """Three of the short consumer drives (benchmarks/short_consumer_drives.py; simulated, not
    tuned on): docs/realtime.md's (seed 1: a 2.5 °/s x-gyro bias, 12° of pitch in 6 s after
    its start), seed 17, and seed 32 (a 2.16 °/s yaw-rate bias: every heading hypothesis
    25–31° off at σ 8° within 15 s until the start split its yaw bias too): p95 of error/σ_h
    below 3 and RMS within 12 m / 9 m / 12 m. Measured with the yaw-bias split (stop 52):
    p95 1.45 / 1.41 / 2.32, RMS 5.9 / 7.9 / 9.5 m; without it (stop 51's code) 1.59 / 1.20 /
    4.29 and 6.4 / 4.0 / 15.8 m. Seed 17's bound was 6 m: the split costs that drive 3.9 m,
    while over the 200 drives the pooled RMS falls 27.5 → 20.7 m and none fails the σ test
    (one did)."""
    for seed, rms_max in ((1, 12.0), (17, 9.0), (32, 12.0)):
        sim = selfnav.simulate("car", seed=seed, grade="consumer", duration=120.0)
        sol = selfnav.navigate(sim.imu, sim.gnss.as_gnss())
        a, tr = sol.trajectory, sim.truth
        lat, lon = np.interp(a.t, tr.t, tr.lat), np.interp(a.t, tr.t, tr.lon)
        rm, rn = selfnav.earth.radii(lat)
        e = np.hypot((a.lat - lat) * rm, (a.lon - lon) * rn * np.cos(lat))
        p95 = np.percentile(e / sol.columns["sigma_h_m"], 95)
        assert p95 < 3.0 and np.sqrt(np.mean(e**2)) < rms_max, (seed, p95)
