"""The run test's hypotheses (selfnav.ins.runtest): a dead reckoning whose heading is far
off and still turning should be "the INS lost" (xfail), a receiver's smooth drift is not,
clean fixes of a sharp dead reckoning are healthy — synthetic runs of 30 fixes at 1 Hz, 10 m σ."""
import math

import numpy as np
import pytest

from selfnav.ins.config import Integrity
from selfnav.ins.runtest import run_evidence

SIGMA = 10.0
N = 31


def _path():
    """A car's 30 s: 10 m/s, two 90° turns (ENU, m, at 1 Hz)."""
    t = np.arange(N, dtype=float)
    rate = np.where(((t > 5) & (t < 11)) | ((t > 20) & (t < 26)), np.radians(15.0), 0.0)
    course = np.cumsum(rate)
    v = 10.0 * np.column_stack([np.sin(course), np.cos(course)])
    p = np.vstack([[0.0, 0.0], np.cumsum(v[:-1], axis=0)])
    return t, p, v


def _rot(a):
    return np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])


def _evidence(t, o, p_ins, P_pos=30.0, P_vel=1.0, P_psi=math.radians(3.0)):
    P = np.diag([P_pos**2, P_pos**2, P_vel**2, P_vel**2, P_psi**2])
    return run_evidence(t, o, np.full(len(t), SIGMA), p_ins, P, 0.1, 0.01, Integrity(),
                        fix_sigma=SIGMA, fault_age=60.0)


def _lost_margin(ev):
    return ev["lost"] - max(ev["healthy"], ev["fault"])


@pytest.mark.xfail(reason="issue 19 open: the lost hypothesis' heading term is linear; the two "
                   "stronger models tried (path turned and scaled; a mixture over turns) made "
                   "drive_0708's drags or second-order drift look like a lost INS "
                   "(docs/ekf.md)", strict=False)
@pytest.mark.parametrize("seed", range(5))
def test_a_dead_reckoning_turned_far_off_and_still_turning_is_lost(seed):
    """The INS's heading 110° off and drifting 1 °/s (a consumer yaw bias the filter had
    wrong), through two turns: its path is the true one turned by an angle that grows — the
    fixes are healthy and the INS is lost, by twice ln(1/α) (the linear model: +0.4 to +12
    on these five runs; a simulated consumer drive refused 70 s of clean fixes 330–900 m
    off)."""
    t, p, v = _path()
    rng = np.random.default_rng(seed)
    psi = math.radians(110.0) + math.radians(1.0) * (t - t[-1])
    v_ins = np.array([_rot(a) @ vv for a, vv in zip(psi, v)])
    p_ins = np.vstack([[0.0, 0.0], np.cumsum(v_ins[:-1], axis=0)]) + [400.0, -250.0]
    fixes = p + rng.normal(0.0, SIGMA, p.shape)
    ev = _evidence(t, fixes - p_ins, p_ins)
    assert _lost_margin(ev) > -2.0 * math.log(Integrity().p_false_alarm), _lost_margin(ev)


def test_clean_fixes_of_a_sharp_dead_reckoning_are_healthy_not_lost():
    t, p, v = _path()
    rng = np.random.default_rng(2)
    p_ins = p + rng.normal(0.0, 3.0, 2)           # a DR error well inside P (30 m)
    fixes = p + rng.normal(0.0, SIGMA, p.shape)
    ev = _evidence(t, fixes - p_ins, p_ins)
    assert ev["healthy"] > ev["lost"]
    assert ev["healthy"] > ev["fault"] - 3.0


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_a_receiver_drifting_smoothly_is_a_fault_not_a_lost_ins(seed):
    """A receiver that drifts off at 3 m/s with a rate that turns slowly (a spoofer's smooth
    drag), the INS right: "lost" must not explain it better than the drift fault by
    ln(1/α)."""
    t, p, v = _path()
    rng = np.random.default_rng(seed)
    ang = rng.uniform(0, 2 * math.pi) + 0.02 * (t - t[0])
    drift = np.cumsum(3.0 * np.column_stack([np.cos(ang), np.sin(ang)]), axis=0) + 180.0
    p_ins = p + rng.normal(0.0, 3.0, 2)
    fixes = p + drift + rng.normal(0.0, SIGMA, p.shape)
    ev = _evidence(t, fixes - p_ins, p_ins)
    assert _lost_margin(ev) < -math.log(Integrity().p_false_alarm), _lost_margin(ev)


@pytest.mark.parametrize("seed", range(11, 23))
def test_a_second_order_drift_of_rtk_fixes_is_a_fault_not_a_lost_ins(seed):
    """An RTK receiver (fixes of 0.1 m at 4 Hz; the fault floor 1 m) whose positions drift off
    as a critically damped second-order Gauss–Markov error (σ 50 m, τ 60 s: what
    ``selfnav.sensors.drift_errors`` makes), a run of 27 fixes over 6.5 s 20–60 s into the
    drift, the INS right (a sharp dead reckoning: 0.2 m, 0.03 m/s): the drift's rate wanders
    as a random walk, which a quadratic with a 1 m wander cannot follow at 0.1 m — the lost
    INS had won by up to 15 nats, and drive_0708, its velocities clean, was restarted on such a
    drift and ran 53 m off for minutes after it. The drift must beat it decisively: by
    ln(1/α)."""
    from selfnav.sensors import drift_errors

    dt, sig, n = 0.25, 0.1, 27
    rng = np.random.default_rng(seed)
    start = int(rng.integers(80, 240))                    # 20-60 s into the drift
    e = drift_errors(start + n, dt, 50.0, 60.0, rng)[start:]
    t = np.arange(n) * dt
    course = np.radians(30.0) + np.cumsum(np.where(t > 3.0, np.radians(2.0), 0.0))
    p = np.vstack([[0.0, 0.0], np.cumsum(8.0 * dt * np.column_stack(
        [np.sin(course), np.cos(course)])[:-1], axis=0)])
    p_ins = p + rng.normal(0.0, 0.2, 2)
    fixes = p + e + rng.normal(0.0, sig, p.shape)
    P = np.diag([0.2**2, 0.2**2, 0.03**2, 0.03**2, math.radians(0.4) ** 2])
    ev = run_evidence(t, fixes - p_ins, np.full(n, sig), p_ins, P, 0.1, 1e-4, Integrity(),
                      fix_sigma=Integrity().fault_min_m, fault_age=start * dt)
    assert _lost_margin(ev) < math.log(Integrity().p_false_alarm), _lost_margin(ev)
    assert ev["fault"] > ev["healthy"]


def _track(rate, seed, n=40, dt=0.25, sigma=0.1):
    """An episode's fixes (``t, offset, sigma``): offsets from M moving at ``rate`` m/s."""
    from types import SimpleNamespace

    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    o = np.outer(t, rate) + rng.normal(0.0, sigma, (n, 2)) + 30.0
    return [SimpleNamespace(t=a, offset=b, sigma=sigma) for a, b in zip(t, o)]


@pytest.mark.parametrize("seed", range(5))
def test_a_velocity_moving_with_the_refused_positions_is_part_of_the_fault(seed):
    """While an episode refuses the fixes (their offsets from M moving at a spoofer's 1.2 m/s),
    a GNSS velocity whose offset from M's is that rate moves with them and is refused; a clean
    Doppler's (M's own velocity error, ~0) is not — it is what kept drive_0708 within 0.8 m
    through windows of faulty positions; with the offsets standing still the two cannot be
    told apart and the velocity is kept."""
    from types import SimpleNamespace

    from selfnav.ins.hypotheses import FaultBank

    rng = np.random.default_rng(100 + seed)
    S = np.eye(2) * 0.25 ** 2
    rate = np.array([0.4, -1.1])
    bank = SimpleNamespace(episode=SimpleNamespace(track=_track(rate, seed)), run=[])
    spoofed = rate + rng.normal(0.0, 0.25, 2)
    clean = rng.normal(0.0, 0.25, 2)
    assert FaultBank.velocity_moves_with_fault(bank, spoofed, S)
    assert not FaultBank.velocity_moves_with_fault(bank, clean, S)
    still = SimpleNamespace(episode=SimpleNamespace(track=_track(np.zeros(2), seed)), run=[])
    assert not FaultBank.velocity_moves_with_fault(still, np.array([0.02, -0.01]), S)
    short = SimpleNamespace(episode=SimpleNamespace(track=_track(rate, seed)[:3]), run=[])
    assert not FaultBank.velocity_moves_with_fault(short, spoofed, S)
