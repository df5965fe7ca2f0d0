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
