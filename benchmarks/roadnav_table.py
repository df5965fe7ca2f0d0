"""Issue 5 comparison table: seed 004 loop, EKF, EKF + map, GNSS-only matching, raw GNSS.

Simulated drives (labelled so) on both shipped OpenStreetMap extracts: consumer MEMS IMU
(BMI160 preset) + magnetometer (typical car: 500 nT hard iron, 2 % soft iron), GNSS at 1 Hz with
σ 10 m and unflagged outlier windows of up to 5 min at 200 m σ, white and drifting (Gauss-Markov),
the first at start-up. Errors are along- and cross-track in the truth's heading frame over the
epochs each method outputs (also inside the outlier windows); the navigators start after the
start-up window (first run of healthy fixes), and the GNSS-only rows are evaluated over the same
span (matched over the whole record, then cut); "on road" is the share of epochs
within 5 m of the centre line actually driven, "wrong run" the longest run of epochs farther
than that (s); "× RT" is processing speed against real time.

Run: ``python benchmarks/roadnav_table.py [--duration 600] [--seeds 1 2 3] [--no-outliers]
[--breakdown]`` (``--breakdown``: the EKF + map errors by part of the drive — start-up, turns,
outlier windows, the rest — pooled over all epochs).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from selfnav import sensors
import selfnav
from selfnav.evaluation import evaluate
from selfnav.roads.hmm import match_gnss
from selfnav.roads.graph import project_to_polyline, read_roads
from selfnav.seed004 import SeedConfig, run_seed
from selfnav.sim.scenarios import simulate
from selfnav.types import Trajectory


def scenario(map_name, duration, seed, outliers=True):
    rng = np.random.default_rng(1000 + seed)
    wins = sensors.random_outlier_windows(0.0, duration, 2, rng, max_duration=300.0,
                                          startup=True) if outliers else []
    return {"scenario": {"kind": "car", "duration": duration, "map": map_name, "dt": 0.005},
            "imu": {"grade": "consumer"}, "mag": {"enabled": True},
            "gnss": {"sigma_m": 10.0, "rate_hz": 1.0, "spike_rate": 0.0,
                     "outliers": [{"start": w.start, "duration": w.duration, "sigma_m": 200.0,
                                   "kind": w.kind} for w in wins]}}, wins


def road_share(graph, route, t_route, traj, t_sol):
    """Share of epochs within 5 m of the driven centre line, and the longest run beyond (s)."""
    x, y = graph.to_local(traj.lat, traj.lon)
    s_true = np.interp(t_sol, t_route, route.s)
    _, cross, _ = project_to_polyline(np.column_stack([x, y]), route.centerline,
                                      near_s=s_true, window=60.0)
    on = np.abs(cross) <= 5.0
    worst, run = 0, 0
    for o in on:
        run = 0 if o else run + 1
        worst = max(worst, run)
    dt = float(np.median(np.diff(t_sol))) if len(t_sol) > 1 else 1.0
    return float(on.mean()), worst * dt


def metrics(sim, graph, traj, seconds, t_min=None):
    if t_min is not None:      # the same epochs as the navigators (after their start)
        k = traj.t >= t_min
        traj = Trajectory(traj.t[k], traj.lat[k], traj.lon[k], traj.h[k], traj.velocity_n[k],
                          traj.C_nb[k], traj.source)
    ev = evaluate(sim.truth, traj)
    t_route = np.arange(len(sim.route.s)) * float(sim.config["scenario"]["dt"])
    share, wrong = road_share(graph, sim.route, t_route, traj, ev.t)
    m = ev.metrics
    span = float(sim.imu.t[-1] - sim.imu.t[0])
    return {"along_rms": m["along_track_rms_m"], "along_max": m["along_track_max_m"],
            "cross_rms": m["cross_track_rms_m"], "cross_max": m["cross_track_max_m"],
            "on_road": share, "wrong_s": wrong, "start_s": float(ev.t[0]),
            "rt": span / max(seconds, 1e-9), "ev": ev}


def breakdown(sim, wins, ev):
    """Per epoch: which part of the drive (for ``--breakdown``): the first 30 s after the
    start, within 3 s of a turn of more than 30° (truth heading over ±3 s), inside an outlier
    window, the rest."""
    t = ev.t
    v = sim.truth.velocity_n
    hdg = np.unwrap(np.arctan2(v[:, 0], v[:, 1]))
    turn = np.abs(np.interp(t + 3, sim.truth.t, hdg) - np.interp(t - 3, sim.truth.t, hdg))
    inwin = np.zeros(len(t), bool)
    for w in wins:
        inwin |= (t >= w.start) & (t < w.start + w.duration)
    part = np.full(len(t), "rest", dtype=object)
    part[inwin] = "outlier window"
    part[turn > np.radians(30.0)] = "turn > 30° ± 3 s"
    part[t - t[0] < 30.0] = "first 30 s"
    return part


def run_one(map_name, duration, seed, outliers=True):
    spec, wins = scenario(map_name, duration, seed, outliers)
    sim = simulate(spec, seed=seed)
    graph = read_roads(sim.map_path)
    g = sim.gnss
    gd = g.as_gnss(source="simulated")
    rows = {"windows": wins, "sim": sim}
    for name, matcher in (("seed loop", "seed"), ("seed loop + mht", "mht")):
        t0 = time.perf_counter()
        r = run_seed(sim.imu, gd, graph, SeedConfig(matcher=matcher))
        rows[name] = metrics(sim, graph, r.trajectory, time.perf_counter() - t0)
    for name, roads in (("EKF", None), ("EKF + map", graph)):
        t0 = time.perf_counter()
        # the causal Navigator with the defaults of selfnav navigate (--map: the road aid)
        res = selfnav.navigate(sim.imu, gd, roads)
        rows[name] = metrics(sim, graph, res.trajectory, time.perf_counter() - t0)
    t_start = rows["EKF + map"]["start_s"]
    t0 = time.perf_counter()
    mm = match_gnss(graph, gd.t, gd.lat, gd.lon, sigma=gd.sigma_m)
    el = time.perf_counter() - t0
    n = len(mm.t)
    blank = np.zeros((n, 3))
    rows["GNSS-only HMM"] = metrics(sim, graph, Trajectory(mm.t, mm.lat, mm.lon, gd.h, blank,
                                                           np.broadcast_to(np.eye(3), (n, 3, 3)),
                                                           "hmm"), el, t_start)
    rows["raw GNSS"] = metrics(sim, graph, Trajectory(gd.t, gd.lat, gd.lon, gd.h, blank,
                                                      np.broadcast_to(np.eye(3), (n, 3, 3)),
                                                      "raw"), 1e-9, t_start)
    return rows, wins


def print_breakdown(runs):
    """EKF + map: where the error comes from (pooled over the runs' epochs)."""
    parts, al, cr = [], [], []
    for rows in runs:
        ev = rows["EKF + map"]["ev"]
        parts.append(breakdown(rows["sim"], rows["windows"], ev))
        al.append(ev.along)
        cr.append(ev.cross)
    parts, al, cr = np.concatenate(parts), np.concatenate(al), np.concatenate(cr)
    sa, sc = np.sum(al**2), np.sum(cr**2)
    print("\nEKF + map, pooled over all epochs: where the error comes from\n")
    print("| part of the drive | epochs | along RMS m | share of along MSE | cross RMS m | "
          "share of cross MSE |")
    print("| --- | --- | --- | --- | --- | --- |")
    for k in ("first 30 s", "turn > 30° ± 3 s", "outlier window", "rest"):
        m = parts == k
        print(f"| {k} | {100 * m.mean():.0f} % | {np.sqrt(np.mean(al[m]**2)):.1f} | "
              f"{100 * np.sum(al[m]**2) / sa:.0f} % | {np.sqrt(np.mean(cr[m]**2)):.2f} | "
              f"{100 * np.sum(cr[m]**2) / sc:.0f} % |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--maps", nargs="+", default=["kotka_karhula", "helsinki_centre"])
    ap.add_argument("--no-outliers", action="store_true", help="nominal GNSS only")
    ap.add_argument("--breakdown", action="store_true",
                    help="also break the EKF + map errors down by part of the drive")
    a = ap.parse_args()
    allrows = {}
    runs = []
    for m in a.maps:
        for s in a.seeds:
            rows, wins = run_one(m, a.duration, s, not a.no_outliers)
            runs.append(rows)
            rows = {k: v for k, v in rows.items() if k not in ("windows", "sim")}
            w = ", ".join(f"{x.start:.0f}+{x.duration:.0f}s {x.kind}" for x in wins)
            print(f"# {m} seed {s}: outlier windows {w}", flush=True)
            for k, v in rows.items():
                allrows.setdefault(k, []).append(v)
                print(f"#   {k:16s} along {v['along_rms']:8.1f}/{v['along_max']:8.1f}  cross "
                      f"{v['cross_rms']:8.1f}/{v['cross_max']:8.1f}  on-road {100 * v['on_road']:5.1f} %"
                      f"  wrong {v['wrong_s']:5.0f} s  start {v['start_s']:5.0f} s", flush=True)
    print(f"\n{len(a.maps)} maps × {len(a.seeds)} seeds × {a.duration:.0f} s; RMS over all runs "
          "pooled as the root of the mean square, max the largest\n")
    print("| method | along RMS m | along max m | cross RMS m | cross max m | on right road | "
          "longest wrong s | first output s | × real time |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for k, vs in allrows.items():
        f = lambda key: float(np.sqrt(np.mean([v[key] ** 2 for v in vs])))  # noqa: E731
        g = lambda key: float(np.max([v[key] for v in vs]))  # noqa: E731
        rt = np.median([v["rt"] for v in vs])
        rts = "—" if rt > 1e6 else f"{rt:.0f}"
        print(f"| {k} | {f('along_rms'):.1f} | {g('along_max'):.0f} | {f('cross_rms'):.1f} | "
              f"{g('cross_max'):.0f} | {100 * np.mean([v['on_road'] for v in vs]):.1f} % | "
              f"{g('wrong_s'):.0f} | {np.mean([v['start_s'] for v in vs]):.0f} | {rts} |")
    if a.breakdown:
        print_breakdown(runs)


if __name__ == "__main__":
    main()
