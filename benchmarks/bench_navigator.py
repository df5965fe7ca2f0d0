"""Navigator speed against real time: 200 Hz IMU + 1 Hz GNSS (issue 5 target: > 100×).

Simulated 600 s car drive on the Kotka map (consumer IMU + magnetometer, σ 10 m GNSS); times
``run_seed`` (matcher seed and mht) and :func:`selfnav.navigate` (the causal
:class:`selfnav.Navigator`) with and without the road map, plus
GNSS-only HMM matching in fixes per second (target > 10,000/s).

Run: ``python benchmarks/bench_navigator.py [--duration 600]``
"""
from __future__ import annotations

import argparse
import time

import selfnav
from selfnav.roads.hmm import match_gnss
from selfnav.roads.graph import read_roads
from selfnav.seed004 import SeedConfig, run_seed
from selfnav.sim.scenarios import simulate


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0)
    a = ap.parse_args()
    sim = simulate({"scenario": {"kind": "car", "duration": a.duration, "dt": 0.005,
                                 "map": "kotka_karhula"}, "imu": {"grade": "consumer"},
                    "mag": {"enabled": True}, "gnss": {"outliers": [], "spike_rate": 0.0}}, seed=3)
    g = sim.gnss
    gd = g.as_gnss(source="simulated")
    graph = read_roads(sim.map_path)
    span = float(sim.imu.t[-1] - sim.imu.t[0])
    run_seed(sim.imu, gd, graph, SeedConfig(matcher="mht"))   # warm the numba caches
    jobs = {
        "seed loop (seed)": lambda: run_seed(sim.imu, gd, graph, SeedConfig(matcher="seed")),
        "seed loop (mht)": lambda: run_seed(sim.imu, gd, graph, SeedConfig(matcher="mht")),
        "EKF (Navigator)": lambda: selfnav.navigate(sim.imu, gd),
        "EKF + map": lambda: selfnav.navigate(sim.imu, gd, graph),
    }
    print(f"{len(sim.imu.t)} IMU samples at {1 / sim.imu.dt:.0f} Hz, {len(gd.t)} fixes, {span:.0f} s")
    for name, f in jobs.items():
        t0 = time.perf_counter()
        f()
        el = time.perf_counter() - t0
        print(f"{name:18s} {el:6.2f} s  {span / el:7.0f}× real time")
    t0 = time.perf_counter()
    match_gnss(graph, gd.t, gd.lat, gd.lon, sigma=gd.sigma_m)
    el = time.perf_counter() - t0
    print(f"{'GNSS-only HMM':18s} {el:6.2f} s  {len(gd.t) / el:7.0f} fixes/s")


if __name__ == "__main__":
    main()
