"""Benchmark (run by hand): the causal navigator on 1 h of 200 Hz IMU with 1 Hz GNSS, and
sample-by-sample through the Python calls at 100 Hz (issue 18).

Targets: the batch run (``selfnav.navigate``, the defaults of ``selfnav navigate``: consumer
prior, 15 + 6 scale-factor + 12 misalignment + 3 lever-arm + 1 time-offset states, the fault
bank's references) under 10 s CPU for 1 h at 200 Hz; ``Navigator.add_imu`` one sample a call
at least 50× real time at 100 Hz. Wall and CPU time are printed with the load average: on a
shared machine the CPU time is the fairer figure. Simulated data.

    python benchmarks/bench_ekf.py [--minutes 60] [--stream-minutes 5]
"""
import argparse
import math
import os
import time

import numpy as np

import selfnav
from selfnav.ins import Navigator
from selfnav.roads.graph import packaged_map, read_roads
from selfnav.sensors import GnssModel, imu_grade
from selfnav.sim.car import car_trajectory
from selfnav.sim.inverse import imu_from_trajectory
from selfnav.types import ImuData


def drive(minutes, dt):
    g = read_roads(packaged_map("kotka_karhula"))
    tr = car_trajectory(g, duration=minutes * 60, dt=0.1, seed=1)
    imu, truth = imu_from_trajectory(tr, dt, return_truth=True)
    rng = np.random.default_rng(1)
    w, f = imu_grade("industrial").apply(imu.t, imu.omega_ib_b, imu.f_ib_b, rng)
    fx = GnssModel(rate_hz=1, sigma_h=3, sigma_v=5).simulate(truth, rng)
    return ImuData(imu.t, w, f), fx.as_gnss()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--stream-minutes", type=float, default=5.0)
    a = ap.parse_args()
    t0 = time.perf_counter()
    data, gd = drive(a.minutes, 0.005)
    print(f"simulated {len(data)} IMU samples (200 Hz), {len(gd.t)} fixes in "
          f"{time.perf_counter() - t0:.1f} s (simulated data)")
    selfnav.navigate(data.select(slice(0, 20000)), gd)        # compile the kernels first
    print(f"load average {os.getloadavg()[0]:.1f}")
    span = data.t[-1] - data.t[0]
    for smooth in (False, True):
        t0, c0 = time.perf_counter(), time.process_time()
        sol = selfnav.navigate(data, gd, smooth=smooth)
        el, cpu = time.perf_counter() - t0, time.process_time() - c0
        print(f"navigate{' --smooth' if smooth else ''}: {el:.2f} s wall, {cpu:.2f} s CPU for "
              f"{span / 60:.0f} min ({span / el:.0f}× real time), {len(sol)} rows, "
              f"{sol.stats['fix_status']['used']} fixes used, {sol.stats['states']} states")
    # one sample a call, fixes as they come: the real-time interface at 100 Hz
    data, gd = drive(a.stream_minutes, 0.01)
    nav = Navigator()
    k = 0
    t0, c0 = time.perf_counter(), time.process_time()
    for i in range(len(data.t)):
        while k < len(gd.t) and gd.t[k] <= data.t[i]:
            nav.add_fix(gd.t[k], math.degrees(gd.lat[k]), math.degrees(gd.lon[k]), gd.h[k],
                        gd.sigma_m[k])
            k += 1
        nav.add_imu(data.t[i], data.omega_ib_b[i], data.f_ib_b[i])
    el, cpu = time.perf_counter() - t0, time.process_time() - c0
    span = data.t[-1] - data.t[0]
    print(f"Navigator.add_imu one sample a call (100 Hz): {el:.2f} s wall, {cpu:.2f} s CPU for "
          f"{span / 60:.0f} min: {span / el:.0f}× real time, {1e6 * el / len(data.t):.0f} µs "
          f"per sample")


if __name__ == "__main__":
    main()
