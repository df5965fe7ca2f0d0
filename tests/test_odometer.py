"""Odometer (issue 15): the wheel-speed model, its file, the EKF's scale-factor state and update
(Jacobian against finite differences, estimation on a simulated drive), the navigator event,
``navigate --odometer`` and the seed loop (simulated data, labelled so)."""
import json

import numpy as np
import pytest

from selfnav import attitude as att
from selfnav import ins
from selfnav.errors import InputError
from selfnav.io.odometer import has_odometer, read_odometer
from selfnav.sensors import OdometerModel
from selfnav.sim.scenarios import simulate, write_simulation
from support import run_cli as run


def test_odometer_model_scale_quantum_and_sign():
    t = np.linspace(0.0, 60.0, 6001)
    v = 8.0 + 3.0 * np.sin(t / 5.0)
    m = OdometerModel(scale_factor_sigma=0.005, quantum_mps=0.01, rate_hz=10.0)
    to, vo, k = m.simulate(t, v, np.random.default_rng(3))
    assert np.allclose(np.diff(to), 0.1) and to[0] == 0.0
    exact = (1.0 + k) * np.interp(to, t, v)
    assert np.max(np.abs(vo - exact)) <= 0.005 + 1e-9           # half a quantum
    assert np.allclose(vo / 0.01, np.round(vo / 0.01))
    ks = [OdometerModel(0.005).simulate(t, v, s)[2] for s in range(400)]
    assert abs(np.std(ks) - 0.005) < 0.0006                      # σ of the scale factor
    _, neg, _ = OdometerModel(noise_mps=0.5).simulate(t, np.zeros_like(t), 1)
    assert np.all(neg >= 0.0)                                     # no direction signal


def test_simulated_odometer_file_round_trip(tmp_path):
    spec = {"scenario": {"kind": "car", "duration": 60.0, "map": "helsinki_centre"},
            "imu": {"grade": "consumer"}, "gnss": {"outliers": [], "spike_rate": 0.0},
            "odometer": {"enabled": True, "scale_factor_sigma": 0.01, "quantum_mps": 0.01}}
    sim = simulate(spec, seed=5)
    k = sim.odometer.meta["scale_factor"]
    paths = write_simulation(sim, tmp_path)
    assert tmp_path / "odometer.csv" in paths
    odo = read_odometer(tmp_path / "odometer.csv")
    assert np.allclose(odo.t, sim.odometer.t) and np.allclose(odo.speed_mps, sim.odometer.speed_mps)
    # the forward speed of the truth, scaled and quantised
    v = np.hypot(sim.truth.velocity_n[:, 0], sim.truth.velocity_n[:, 1])
    ref = (1.0 + k) * np.interp(odo.t, sim.truth.t, v)
    assert np.max(np.abs(odo.speed_mps - ref)) < 0.02
    assert "scale-factor" in (tmp_path / "odometer.csv").read_text().splitlines()[1]
    # without the section, no file and the other streams unchanged
    spec2 = {**spec, "odometer": {"enabled": False}}
    sim2 = simulate(spec2, seed=5)
    assert sim2.odometer is None
    assert np.array_equal(sim2.imu.f_ib_b, sim.imu.f_ib_b)
    assert np.array_equal(sim2.gnss.lat, sim.gnss.lat)


def test_odometer_reader_errors_and_imu_column(tmp_path):
    p = tmp_path / "odo.csv"
    p.write_text("t,speed_mps\n0,36\n1,40\n2,50\n")
    assert read_odometer(p).speed_mps[1] == 40.0
    p.write_text("t,speed_mps\n0,136\n1,140\n2,150\n")
    with pytest.raises(InputError, match="km/h"):
        read_odometer(p)
    p.write_text("t,speed\n0,1\n1,2\n")
    with pytest.raises(InputError, match="speed_mps"):
        read_odometer(p)
    imu = tmp_path / "imu.csv"
    imu.write_text("# a comment\nt,wx,wy,wz,fx,fy,fz,speed_mps\n0,0,0,0,0,0,9.8,1.5\n"
                   "0.01,0,0,0,0,0,9.8,1.6\n")
    assert has_odometer(imu) and not has_odometer(p)
    assert np.allclose(read_odometer(imu).speed_mps, [1.5, 1.6])


def _filter(odometer=True, mount=True, lever=(0.2, -1.0, 0.1)):
    cfg = ins.FilterConfig.for_grade("industrial", odometer=odometer, mount_states=mount,
                                     nhc_lever_b=np.array(lever))
    C = att.dcm_nb_from_euler(0.02, -0.01, 0.7)
    f = ins.InsGnssFilter(cfg, 0.0, 1.0, 0.5, 10.0, np.array([6.0, 8.0, 0.2]), C)
    f._w_b = np.array([0.01, -0.02, 0.3])
    f.mu = np.array([0.01, -0.02])
    f.odo_scale = 0.01
    return f


def _h(f):
    from selfnav.ins.measurements import vehicle_velocity

    vv, _ = vehicle_velocity(f)
    return (1.0 + f.odo_scale) * vv[1]


def test_odometer_jacobian_matches_finite_differences():
    """H of update_odometer against the measurement model perturbed state by state
    (δx = estimated − true: the model at x̃ − δx)."""
    from types import SimpleNamespace

    f = _filter()
    f.ins = SimpleNamespace(C_nb=f.ins.C_nb.copy(), velocity_n=f.ins.velocity_n.copy())
    lay = f.layout
    cap = {}

    def kalman(r, H, R):
        cap["r"], cap["H"] = r, H
        return np.zeros(f.nx)

    from selfnav.ins.measurements import WheelSpeed

    m = WheelSpeed(7.0, 0.05).model(f)
    cap["r"], cap["H"] = m.r, m.H
    H = cap["H"][0]
    assert cap["r"][0] == pytest.approx(_h(f) - 7.0)
    h0 = _h(f)
    eps = 1e-6
    C0, v0, mu0, k0 = f.ins.C_nb.copy(), f.ins.velocity_n.copy(), f.mu.copy(), f.odo_scale
    for i in range(3):                       # velocity
        d = np.zeros(3); d[i] = eps
        f.ins.velocity_n = v0 - d
        assert (h0 - _h(f)) / eps == pytest.approx(H[3 + i], abs=1e-5)
        f.ins.velocity_n = v0
    for i in range(3):                       # attitude: the true C_bn = exp([ψ]) C̃_bn
        psi = np.zeros(3); psi[i] = eps
        f.ins.C_nb = (att.rotvec_to_dcm(psi) @ C0.T).T
        assert (h0 - _h(f)) / eps == pytest.approx(H[6 + i], abs=1e-5)
        f.ins.C_nb = C0
    for j, i in enumerate((0, 1)):           # mounting pitch, yaw (small-angle model, as the NHC)
        d = np.zeros(2); d[i] = eps
        f.mu = mu0 - d
        assert (h0 - _h(f)) / eps == pytest.approx(H[lay.mu.start + j], rel=2e-3)
        f.mu = mu0
    f.odo_scale = k0 - eps
    assert (h0 - _h(f)) / eps == pytest.approx(H[lay.odo.start], abs=1e-5)


def test_wheel_speed_is_compared_at_its_own_stamp_and_does_not_see_the_time_offset():
    """The wheel speed shares the IMU's clock: the model extrapolates the INS's forward speed
    from its own stamp to the sample's along the acceleration (analytic), and the IMU time
    offset against the fixes has no column (a −a·δε term had the odometer witness it)."""
    from selfnav.ins.measurements import WheelSpeed

    cfg = ins.FilterConfig.for_grade("industrial", odometer=True, time_offset=True)
    f = ins.InsGnssFilter(cfg, 5.0, 1.0, 0.5, 10.0, np.array([6.0, 8.0, 0.0]),
                          att.dcm_nb_from_euler(0.0, 0.0, 0.7))
    f._f_n = np.array([0.3, 0.4, 0.0]) + np.array([0.0, 0.0, f.gravity(1.0, 10.0)])
    now = WheelSpeed(7.0, 0.05).model(f)
    later = WheelSpeed(7.0, 0.05, stamp=f.ins.t + 0.2).model(f)
    fwd = f.ins.C_nb[1]                             # the body's forward axis in ENU
    a_f = float(fwd @ np.array([0.3, 0.4, 0.0]))
    assert later.r[0] - now.r[0] == pytest.approx((1.0 + f.odo_scale) * a_f * 0.2, rel=1e-6)
    assert f.layout.toff is not None
    assert later.H[0, f.layout.toff.start] == 0.0
    assert np.array_equal(later.H, now.H)


@pytest.mark.slow
@pytest.mark.parametrize("offset_s", [0.0, 0.25])
def test_imu_and_wheel_speed_on_one_clock_the_offset_is_learnt_honestly(drive, offset_s):
    """IMU and wheel speed logged on one clock ``offset_s`` behind the fixes' (both stamps
    shifted): the offset the navigator reports is within 3σ of it. Measured (seed 11, 300 s,
    consumer IMU): 0.046 ± 0.139 s and 0.264 ± 0.139 s; before stop 64 the odometer was
    modelled as stamped in true time and both read 0.07 s at σ 2 ms (33σ and 83σ off)."""
    from dataclasses import replace

    from selfnav import api

    imu = replace(drive.imu, t=drive.imu.t - offset_s)
    odo = replace(drive.odometer, t=drive.odometer.t - offset_s)
    sol = api.navigate(imu, drive.gnss.as_gnss(), odometer=odo)
    eps, s = sol.stats["imu_time_offset_s"], sol.stats["imu_time_offset_sigma_s"]
    assert abs(eps - offset_s) < 3.0 * s, (eps, s)
    assert s < 0.3                                  # below its prior: learnt, not assumed


def test_wheel_speed_after_the_start_without_its_state_warns_once():
    """The odometer state is made at the start when wheel speed arrived before it; samples
    that come only later are dropped with one warning (not silently)."""
    from selfnav.errors import SelfnavWarning

    nav = ins.Navigator(init={"t": 0.0, "lat": 1.0, "lon": 0.5, "h": 0.0,
                              "velocity_n": np.zeros(3), "C_nb": np.eye(3)})
    nav.add_imu(np.array([0.01, 0.02]), np.zeros((2, 3)), np.tile([0.0, 0.0, 9.8], (2, 1)))
    assert nav.started and nav.flt.layout.odo is None
    with pytest.warns(SelfnavWarning, match="no odometer state"):
        nav.add_odometer(1.0, 3.0)
        nav.add_odometer(2.0, 3.0)


@pytest.fixture(scope="module")
def drive():
    spec = {"scenario": {"kind": "car", "duration": 300.0, "map": "kotka_karhula"},
            "imu": {"grade": "consumer"}, "gnss": {"outliers": [], "spike_rate": 0.0},
            "odometer": {"enabled": True, "scale_factor_sigma": 0.02, "quantum_mps": 0.01}}
    return simulate(spec, seed=11)


@pytest.mark.slow
def test_ekf_estimates_the_odometer_scale_factor(drive):
    """300 s of clean GNSS: the scale factor learnt to better than 0.3 % (σ; the drive's own
    factor is drawn with σ 2 %), and the estimate within 3σ of the truth. Measured: σ 0.17 %,
    error/σ 2.07 on this drive (seed 11), 0.61 and 0.75 on seeds 12 and 13 (a bound of 0.3 %
    on the error alone asked for 1.8σ, and this drive failed it by 0.05 %)."""
    from selfnav import api

    sol = api.navigate(drive.imu, drive.gnss.as_gnss(), odometer=drive.odometer)
    k_true = drive.odometer.meta["scale_factor"]
    k = sol.stats["odometer_scale_factor"]
    s = sol.stats["odometer_scale_factor_sigma"]
    assert s < 0.003, s
    assert abs(k - k_true) < 3.0 * s, (k, k_true, s)
    assert sol.stats["states"] >= 16


def test_cli_navigate_with_odometer(drive, tmp_path, capsys):
    d = tmp_path / "sim"
    write_simulation(drive, d)
    sol = tmp_path / "sol.csv"
    code, out, err = run(["navigate", "--imu", d / "imu.csv", "--gnss", d / "gnss.csv",
                          "--odometer", d / "odometer.csv", "--out", sol, "--json"], capsys)
    assert code == 0, err
    assert "odometer_scale_factor" in json.loads(out)
    bad = tmp_path / "bad.csv"
    bad.write_text("t,speed_mps\n0,100\n1,200\n2,300\n")
    code, out, err = run(["navigate", "--imu", d / "imu.csv", "--gnss", d / "gnss.csv",
                          "--odometer", bad, "--out", tmp_path / "x.csv"], capsys)
    assert code == 2 and "bad.csv" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.csv").exists()


def test_seed_loop_takes_the_odometer(drive):
    from selfnav import api

    sol = api.navigate(drive.imu, drive.gnss.as_gnss(), drive.map_path, method="seed",
                       odometer=drive.odometer)
    k_true = drive.odometer.meta["scale_factor"]
    assert abs(sol.stats["odometer_scale_factor"] - k_true) < 0.01
