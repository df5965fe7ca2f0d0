"""Benchmark (issue 3): one hour of 200 Hz car data (trajectory on a real OSM map, exact inverse
strapdown, industrial-MEMS errors, magnetometer, GNSS with outliers). Target: under 10 s.

Run: ``python benchmarks/bench_simulate.py [--write DIR]``. Reported, not a timed test.
"""
from __future__ import annotations

import argparse
import os
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=3600.0)
    ap.add_argument("--dt", type=float, default=0.005)
    ap.add_argument("--write", default=None, help="also time writing the files to this folder")
    a = ap.parse_args()
    from selfnav.sim.scenarios import simulate, write_simulation

    simulate("car", seed=0, duration=10.0, dt=a.dt)     # warm-up: imports, map parsing caches
    stages = {}
    last = [time.perf_counter()]

    def progress(name):
        now = time.perf_counter()
        stages[name] = now
        last[0] = now

    t0 = time.perf_counter()
    sim = simulate("car", seed=1, duration=a.duration, dt=a.dt, progress=progress)
    t1 = time.perf_counter()
    names = list(stages)
    marks = [stages[n] for n in names] + [t1]
    print(f"simulated {len(sim.imu)} IMU samples ({a.duration:.0f} s at {1 / a.dt:.0f} Hz, car "
          f"on {sim.map_path.name}), {len(sim.gnss.t)} GNSS fixes on {os.cpu_count()} cores:")
    for n, s, e in zip(names, marks[:-1], marks[1:]):
        print(f"  {n:18s} {e - s:6.2f} s")
    print(f"  total              {t1 - t0:6.2f} s  (target < 10 s)")
    if a.write:
        t2 = time.perf_counter()
        write_simulation(sim, a.write)
        print(f"  writing CSV files  {time.perf_counter() - t2:6.2f} s")


if __name__ == "__main__":
    main()
