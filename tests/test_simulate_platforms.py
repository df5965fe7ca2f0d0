"""Simulated platforms (issue 20 item 6): pedestrian, rover, boat, drone, each starting at rest or
moving; the motion each promises; the exact inverse strapdown round trip; files and CLI."""
import json

import numpy as np
import pytest

from selfnav import attitude as att
from selfnav import earth
from selfnav.ins import strapdown as sd
from selfnav.sim.scenarios import PLATFORMS, simulate
from support import run_cli

KINDS = PLATFORMS


def _speed(tr):
    return np.hypot(tr.velocity_n[:, 0], tr.velocity_n[:, 1])


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("start", ["rest", "moving"])
def test_exact_inverse_strapdown_round_trip(kind, start):
    """simulate → integrate the perfect IMU's increments → the same trajectory: the residual
    is the strapdown algorithm's own truncation (third order in dt, below), not the
    simulator's."""
    s = simulate({"scenario": {"kind": kind, "truth_hz": 0}}, seed=3, duration=120.0,
                 grade="perfect", start=start, dt=0.005)
    ex, tr = s.imu_exact, s.truth
    out = sd.integrate(ex.t, ex.meta["dtheta"], ex.meta["dv"], tr.lat[0], tr.lon[0], tr.h[0],
                       tr.velocity_n[0], tr.C_nb[0], t0=tr.t[0])
    r_phi, r_lam = earth.radii(tr.lat, tr.h)
    e = np.hypot((out.lat - tr.lat) * r_phi, (out.lon - tr.lon) * r_lam * np.cos(tr.lat))
    assert e.max() < 2e-3 and np.abs(out.h - tr.h).max() < 1e-3, e.max()
    da = att.dcm_to_rotvec(out.C_nb @ np.swapaxes(tr.C_nb, 1, 2))
    assert np.linalg.norm(da, axis=1).max() < 1e-6


def test_round_trip_residual_is_the_integrators_third_order_truncation():
    """The walker's 2 Hz steps at 100 Hz leave 8 mm in 2 min; halving dt divides it by ≈ 8:
    the integrator's error, so the increments themselves are exact."""
    errs = []
    for dt in (0.01, 0.005, 0.0025):
        s = simulate({"scenario": {"kind": "pedestrian", "truth_hz": 0}}, seed=3,
                     duration=120.0, grade="perfect", start="moving", dt=dt)
        ex, tr = s.imu_exact, s.truth
        out = sd.integrate(ex.t, ex.meta["dtheta"], ex.meta["dv"], tr.lat[0], tr.lon[0],
                           tr.h[0], tr.velocity_n[0], tr.C_nb[0], t0=tr.t[0])
        r_phi, r_lam = earth.radii(tr.lat, tr.h)
        errs.append(np.hypot((out.lat - tr.lat) * r_phi,
                             (out.lon - tr.lon) * r_lam * np.cos(tr.lat)).max())
    assert errs[0] / errs[1] > 6.0 and errs[1] / errs[2] > 6.0, errs


@pytest.mark.parametrize("kind,speed,rest", [("pedestrian", 1.4, 30.0), ("rover", 0.3, 30.0),
                                             ("boat", 1.0, 60.0), ("drone", 5.0, 20.0)])
def test_start_at_rest_or_moving(kind, speed, rest):
    at_rest = simulate(kind, seed=1, duration=200.0, grade="perfect")
    tr = at_rest.truth
    still = tr.t < rest - 0.5
    if kind == "boat":      # drifting in the waves: slow, but rocking
        assert _speed(tr)[still].max() < 0.2
    else:
        assert _speed(tr)[still].max() < 1e-6 and np.ptp(tr.h[still]) < 1e-6
    assert _speed(tr)[tr.t > rest + 10].max() > 0.9 * speed
    moving = simulate(kind, seed=1, duration=200.0, grade="perfect", start="moving")
    assert _speed(moving.truth)[:5].mean() > (0.8 * speed if kind != "drone" else 4.0)
    assert moving.config["scenario"]["start"] == "moving"


def test_pedestrian_steps_turns_and_hand():
    s = simulate("pedestrian", seed=2, duration=300.0, grade="perfect", start="moving")
    tr = s.truth
    sp = _speed(tr)
    assert 1.1 < sp.mean() < 1.5
    # steps: the vertical velocity oscillates at 1.7-2 Hz
    vu = tr.velocity_n[:, 2] - tr.velocity_n[:, 2].mean()
    f = np.fft.rfftfreq(len(vu), np.median(np.diff(tr.t)))
    peak = f[np.argmax(np.abs(np.fft.rfft(vu)))]
    assert 1.6 < peak < 2.1
    # tight turns, and the unit's heading is not the walking direction
    course = np.unwrap(np.arctan2(tr.velocity_n[:, 0], tr.velocity_n[:, 1]))
    assert np.degrees(np.ptp(course)) > 180.0
    _, _, hd = att.euler_from_dcm_nb(tr.C_nb)
    off = np.degrees(np.angle(np.exp(1j * (hd - course))))
    assert np.std(off) > 0.5
    assert s.imu.mag_b is not None


def test_rover_slips_sideways_in_turns():
    s = simulate("rover", seed=4, duration=400.0, grade="perfect", start="moving")
    tr = s.truth
    course = np.unwrap(np.arctan2(tr.velocity_n[:, 0], tr.velocity_n[:, 1]))
    _, _, hd = att.euler_from_dcm_nb(tr.C_nb)
    rate = np.gradient(np.unwrap(hd), tr.t)
    slip = np.angle(np.exp(1j * (course - np.unwrap(hd))))
    turning = np.abs(rate) > np.radians(5.0)
    assert turning.any()
    k = np.polyfit(rate[turning], slip[turning], 1)[0]
    assert 0.3 < k < 0.7                                          # slip_s = 0.5 s
    assert 0.2 < _speed(tr).max() < 0.32
    assert 1 / s.imu.dt == pytest.approx(200.0, rel=1e-6)
    g = s.gnss
    assert 1 / np.median(np.diff(g.t)) == pytest.approx(20.0)
    # stand-alone GPS: the error drifts (correlated over a minute), not white
    e = g.error_enu[:, 0]
    assert np.corrcoef(e[:-20], e[20:])[0, 1] > 0.5


def test_drone_tilts_into_its_accelerations():
    """A multirotor's accelerometers see the thrust only: in flight the horizontal body
    components of the specific force stay small while the vehicle accelerates."""
    s = simulate("drone", seed=6, duration=200.0, grade="perfect")
    tr, imu = s.truth, s.imu_exact
    acc = np.gradient(tr.velocity_n, tr.t, axis=0)
    flying = tr.h > tr.h[0] + 5.0
    assert np.hypot(acc[flying, 0], acc[flying, 1]).max() > 1.5
    k = np.searchsorted(tr.t, imu.t)
    fl = flying[np.clip(k, 0, len(tr.t) - 1)]
    fh = np.hypot(imu.f_ib_b[fl, 0], imu.f_ib_b[fl, 1])
    assert np.percentile(fh, 99) < 0.3                          # jitter only
    assert imu.f_ib_b[:1000, 2].mean() == pytest.approx(9.81, abs=0.02)   # on the ground


def test_cli_simulate_platform_and_start(tmp_path, capsys):
    code, out, err = run_cli(["simulate", "pedestrian", "--out", tmp_path / "p", "--start",
                              "moving", "--duration", "60", "--json"], capsys)
    assert code == 0, err
    r = json.loads(out)
    assert r["kind"] == "pedestrian" and r["start"] == "moving" and r["simulated"]
    assert {"imu.csv", "mag.csv", "gnss.csv", "truth.csv"} <= set(r["files"])
    assert "mx,my,mz" in (tmp_path / "p" / "imu.csv").read_text().splitlines()[2]
    code, out, err = run_cli(["simulate", "car", "--out", tmp_path / "c", "--start", "moving"],
                             capsys)
    assert code == 2 and "--start is for the platforms" in err
    code, out, err = run_cli(["simulate", "rover", "--out", tmp_path / "r", "--imu-axes", "FRU"],
                             capsys)
    assert code == 2 and "left-handed" in err and len(err.strip().splitlines()) == 1
