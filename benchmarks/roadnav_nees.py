"""Issue 18: is each state's σ a promise? Error / σ of every state the causal navigator carries,
on the simulated road drives of the ``roadnav`` campaign (:mod:`selfnav.campaigns`; labelled
simulated).

Each drive runs through :func:`selfnav.api.navigator` with the defaults of ``selfnav navigate``,
fed one second at a time (``add_fix`` then ``add_imu``: the Navigator gives the same rows
however it is fed). After every second the filter's state ``M`` is compared with the
simulation's truth at the state's true time: position (ENU), velocity, attitude (the small
rotation ``ψ`` with ``C̃_b^n = (I − [ψ×]) C_b^n``), and the sensor errors the simulator drew —
gyro and accelerometer biases (turn-on, Gauss–Markov and random walk at that time), scale
factors and misalignment (``I + S + M`` of :func:`selfnav.ins.ekf.sensor_matrix`). Each error
is divided by the filter's own σ of that state (its diagonal of P; for position, velocity and
attitude with the time offset's share, as the rows count it: the state is compared at its own
true time, ``−(v, a, ω^n) δε`` off). While the heading hypotheses of a start are open, ``M`` is
the one the rows follow.

Seconds inside a GNSS fault window and the 60 s after it are left out (an undetected fault that
the filter fuses is not what its σ promises); outages count. Printed per grade: the pooled
RMS of error/σ of each state (1 for an honest σ) and the share of seconds beyond 3σ (0.3 %
for a Gaussian error).

    python benchmarks/roadnav_nees.py --runs 10 --seed 1 [--param grade=mixed ...]
        [--skip-start S]
"""
from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from selfnav import api, campaigns
from selfnav.earth import enu_offset
from selfnav.ins.ekf import OFFDIAG
from selfnav.montecarlo import run_seeds
from selfnav.roads.graph import read_roads
from selfnav.sim.scenarios import simulate

CORE = ["E", "N", "U", "vE", "vN", "vU", "psiE", "psiN", "psiU", "bgx", "bgy", "bgz",
        "bax", "bay", "baz"]
AXES = "xyz"
#: seconds after a fault window that still count as the fault's
AFTER_FAULT_S = 60.0


def _params(pairs):
    p = dict(campaigns.ROADNAV_DEFAULTS)
    for kv in pairs:
        k, _, v = kv.partition("=")
        p[k] = type(campaigns.ROADNAV_DEFAULTS[k])(v)
    return p


def _true_bias(c, t_imu, t):
    """Bias of one triad at time ``t``: turn-on + Gauss–Markov + random walk."""
    k = min(len(t_imu) - 1, int(np.searchsorted(t_imu, t)))
    b = np.array(c["bias"], dtype=float)
    for key in ("gauss_markov", "random_walk"):
        if key in c:
            b = b + c[key][k]
    return b


def drive_z(seed: int, params: dict, skip_s: float = 0.0):
    """``(names, z (n, k), grade, map)``: error / σ of each state, one row a second, of one
    drive (from ``skip_s`` after the start)."""
    spec, sim_seed, wins = campaigns.roadnav_scenario(seed, params)
    sim = simulate(spec, seed=sim_seed)
    use_map = int(params["map_aid"]) if int(params["map_aid"]) >= 0 else seed % 2
    nav = api.navigator(sim.imu, read_roads(sim.map_path) if use_map else None)
    imu, g, tr = sim.imu, sim.gnss.as_gnss(), sim.truth
    slerp = Slerp(tr.t, Rotation.from_matrix(np.swapaxes(tr.C_nb, 1, 2)))   # C_b^n
    errs = sim.imu_errors
    t_imu = imu.t
    faults = [(w.start, w.start + w.duration + AFTER_FAULT_S) for w in wins
              if w.kind != "outage"]
    rows, names = [], None
    k_fix = 0
    t_start = None
    edges = np.arange(imu.t[0], imu.t[-1] + 1.0, 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for a, b in zip(edges[:-1], edges[1:]):
            i0, i1 = np.searchsorted(imu.t, [a, b])
            if i1 <= i0:
                continue
            while k_fix < len(g.t) and g.t[k_fix] <= imu.t[i1 - 1]:
                nav.add_fix(g.t[k_fix], np.degrees(g.lat[k_fix]), np.degrees(g.lon[k_fix]),
                            g.h[k_fix], g.sigma_m[k_fix] if g.sigma_m is not None else None)
                k_fix += 1
            nav.add_imu(imu.t[i0:i1], imu.omega_ib_b[i0:i1], imu.f_ib_b[i0:i1])
            f = nav.flt
            if f is None:
                continue
            t = f.t_true
            t_start = t if t_start is None else t_start
            if t < t_start + skip_s or t < tr.t[0] or t > tr.t[-1] or any(s <= t <= e for s, e in faults):
                continue
            lat, lon, h = (np.interp(t, tr.t, x) for x in (tr.lat, tr.lon, tr.h))
            v = np.array([np.interp(t, tr.t, tr.velocity_n[:, j]) for j in range(3)])
            C_bn = slerp([t]).as_matrix()[0]
            A = np.eye(3) - f.ins.C_nb.T @ C_bn.T
            psi = 0.5 * np.array([A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1]])
            e = np.r_[enu_offset(lat, lon, h, f.ins.lat, f.ins.lon, f.ins.h),
                      f.ins.velocity_n - v, psi,
                      f.bg - _true_bias(errs["gyro"], t_imu, t),
                      f.ba - _true_bias(errs["accel"], t_imu, t)]
            var = np.diag(f.P)[:15].copy()
            if f.layout.toff is not None:
                # the state is compared at its own true time, which carries the time offset's
                # error δε: the position, velocity and attitude there are off by −(v, a, ω^n) δε
                # (as the rows' σ count it), so their σ does too
                j = f.layout.toff.start
                rate = np.r_[f.ins.velocity_n, f.acceleration_n, f.ins.C_nb.T @ f.omega_b]
                var[:9] += rate * rate * f.P[j, j] - 2.0 * rate * f.P[:9, j]
            var = list(var)
            nm = list(CORE)
            lay = f.layout
            for tri, est_s, est_m, sl_s, sl_m in (("g", f.sg, f.mg, lay.sg, lay.mg),
                                                  ("a", f.sa, f.ma, lay.sa, lay.ma)):
                T = errs["gyro" if tri == "g" else "accel"]["matrix"]
                if sl_s is not None:
                    e = np.r_[e, est_s - (np.diag(T) - 1.0)]
                    var += list(np.diag(f.P)[sl_s])
                    nm += [f"s{tri}{ax}" for ax in AXES]
                if sl_m is not None:
                    e = np.r_[e, [est_m[k] - T[r, c] for k, (r, c) in enumerate(OFFDIAG)]]
                    var += list(np.diag(f.P)[sl_m])
                    nm += [f"m{tri}{r}{c}" for r, c in OFFDIAG]
            if names is None:
                names = nm
            if nm != names:
                continue                      # a restart changed the layout: not compared
            var = np.array(var)
            z = np.where(var > 0, e / np.sqrt(np.maximum(var, 1e-300)), np.nan)
            rows.append(z)
    return names, np.array(rows), spec["imu"]["grade"], use_map


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--param", action="append", default=[],
                    help="campaign parameter k=v (selfnav.campaigns.ROADNAV_DEFAULTS)")
    ap.add_argument("--skip-start", type=float, default=0.0,
                    help="leave out the first S seconds after the start")
    a = ap.parse_args()
    params = _params(["kinds=white,gm,outage", "map_aid=-1", "grade=mixed"] + a.param)
    c0 = time.process_time()
    pooled = {}
    for s in run_seeds(a.seed, a.runs):
        names, Z, grade, use_map = drive_z(int(s), params, a.skip_start)
        if names is None or not len(Z):
            print(f"drive {s}: no state compared (no start)")
            continue
        key = (grade, tuple(names))
        pooled.setdefault(key, []).append(Z)
        rms = np.sqrt(np.nanmean(Z ** 2, axis=0))
        worst = np.argsort(-rms)[:3]
        print(f"drive {s} ({grade}, map {use_map}, {len(Z)} s): worst "
              + ", ".join(f"{names[i]} {rms[i]:.2f}" for i in worst))
    for (grade, names), Zs in pooled.items():
        Z = np.vstack(Zs)
        rms = np.sqrt(np.nanmean(Z ** 2, axis=0))
        out3 = np.nanmean(np.abs(Z) > 3.0, axis=0)
        print(f"\n{grade}: {len(Zs)} drives, {len(Z)} s (simulated; fault windows + "
              f"{AFTER_FAULT_S:g} s left out)")
        print("RMS error/σ: " + " ".join(f"{n}:{r:.2f}" for n, r in zip(names, rms)))
        print("beyond 3σ:   " + " ".join(f"{n}:{100 * o:.1f}%" for n, o in zip(names, out3)))
    print(f"\n{time.process_time() - c0:.0f} s CPU")


if __name__ == "__main__":
    main()
