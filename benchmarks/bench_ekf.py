"""Benchmark (run by hand): the INS/GNSS filter on 1 h of 200 Hz IMU with 1 Hz GNSS.

Target (issues 4, 10): under 10 s on one core with the default states of ``selfnav navigate``
(consumer prior: 15 + 6 scale factors, + 3 lever arm + 1 time offset = 25 states, the shadow
dead reckoning). Wall and CPU time are printed with the load average: on a shared machine the
CPU time is the fairer figure. The mechanization alone: bench_strapdown.py.

    python benchmarks/bench_ekf.py [--minutes 60]
"""
import argparse
import os
import time

import numpy as np

from selfnav import ins
from selfnav.api import filter_config
from selfnav.types import ImuData
from selfnav.roads.graph import packaged_map, read_roads
from selfnav.sensors import GnssModel, imu_grade
from selfnav.sim.car import car_trajectory
from selfnav.sim.inverse import imu_from_trajectory


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=60.0)
    a = ap.parse_args()
    g = read_roads(packaged_map("kotka_karhula"))
    t0 = time.perf_counter()
    tr = car_trajectory(g, duration=a.minutes * 60, dt=0.1, seed=1)
    imu, truth = imu_from_trajectory(tr, 0.005, return_truth=True)
    rng = np.random.default_rng(1)
    w, f = imu_grade("industrial").apply(imu.t, imu.omega_ib_b, imu.f_ib_b, rng)
    fx = GnssModel(rate_hz=1, sigma_h=3, sigma_v=5).simulate(truth, rng)
    print(f"simulated {len(imu)} IMU samples (200 Hz), {len(fx.t)} fixes in "
          f"{time.perf_counter() - t0:.1f} s (simulated data)")
    data = ImuData(imu.t, w, f)
    gd = fx.as_gnss()
    cfg = filter_config("auto", time_offset=True)
    ins.run_filter(data.select(slice(0, 20000)), gd, cfg)        # compile the kernels first
    nx = ins.InsGnssFilter(cfg, 0, 0.9, 0.4, 0, np.zeros(3), np.eye(3)).nx
    print(f"load average {os.getloadavg()[0]:.1f}; {nx} states")
    for smooth in (False, True):
        t0, c0 = time.perf_counter(), time.process_time()
        res = ins.run_filter(data, gd, cfg, smooth=smooth)
        el, cpu = time.perf_counter() - t0, time.process_time() - c0
        span = imu.t[-1] - imu.t[0]
        print(f"filter{' + RTS smoother' if smooth else ''}: {el:.2f} s wall, {cpu:.2f} s CPU for "
              f"{span / 60:.0f} min ({span / el:.0f}× real time), {len(res.trajectory.t)} epochs, "
              f"{res.stats['accepted']} fixes used")


if __name__ == "__main__":
    main()
