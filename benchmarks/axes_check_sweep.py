"""Benchmark (run by hand): the IMU check of ``navigate`` alone over simulated campaign drives.

``navigate`` refuses gyros in deg/s or with flipped signs before it runs
(:func:`selfnav.axes_detect.imu_axes_report`). A refusal of a good record is a drive with no
solution, so every change to the check is swept here over the campaigns' drives (simulated,
each record as the campaign makes it, then the check alone: 100 drives in about a minute):

    python benchmarks/axes_check_sweep.py 1 2 5 7 11 103                # map campaign seeds
    python benchmarks/axes_check_sweep.py 19 23 29 --runs 40 --issue18   # issue 18's drives

Prints every refused drive and, per master seed, the count and the largest sideways
acceleration the gyros ask (the deg/s test refuses beyond 3 g).
"""
from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from selfnav import campaigns
from selfnav.axes_detect import imu_axes_report
from selfnav.errors import SelfnavError
from selfnav.montecarlo import run_seeds
from selfnav.sim.scenarios import simulate

ISSUE18 = {"map_aid": -1, "grade": "mixed", "kinds": "white,gm,outage"}


def sweep(master: int, runs: int, params: dict) -> int:
    refused, lat_g, t0 = 0, [], time.perf_counter()
    for rs in run_seeds(master, runs):
        spec, sim_seed, wins = campaigns.roadnav_scenario(int(rs), params)
        sim = simulate(spec, seed=sim_seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                rep = imu_axes_report(sim.imu, sim.gnss.as_gnss(), along_nose=True)
                lat_g.append(rep["forward"]["lateral_g95"])
            except SelfnavError as e:
                refused += 1
                w = "; ".join(f"{x.start:.0f}+{x.duration:.0f} s {x.kind}" for x in wins)
                print(f"REFUSED run {rs} ({w}): {e}", flush=True)
    print(f"master seed {master}: {runs} drives, {refused} refused; lateral g95 at most "
          f"{np.nanmax(lat_g):.2f} g ({time.perf_counter() - t0:.0f} s)", flush=True)
    return refused


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seeds", type=int, nargs="+", help="master seeds")
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--issue18", action="store_true", help="issue 18's mixed-windows drives")
    a = ap.parse_args()
    params = {**campaigns.ROADNAV_DEFAULTS, **(ISSUE18 if a.issue18 else {})}
    total = sum(sweep(m, a.runs, params) for m in a.seeds)
    print(f"refused in all: {total}")


if __name__ == "__main__":
    main()
