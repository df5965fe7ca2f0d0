"""Benchmark: strapdown mechanization throughput on one core (target > 2e6 samples/s).

Run: ``python benchmarks/bench_strapdown.py [n_samples]``. Prints samples per second for the
batch kernel (:func:`selfnav.ins.strapdown.integrate`) and for the streaming ``Strapdown.update``.
The data are simulated (a turning, accelerating body with noise), labelled so.
"""
import sys
import time

import numpy as np

from selfnav import attitude as att
from selfnav.earth import earth_rate_n, normal_gravity
from selfnav.ins.strapdown import Strapdown, integrate


def simulated_increments(n, dt=0.005, seed=0):
    """Simulated increments: Earth rate + gravity + a slow turn and noise (not a real record)."""
    rng = np.random.default_rng(seed)
    lat = np.radians(50.0)
    C = att.dcm_nb_from_euler(0.01, 0.02, 0.3)
    w = C @ earth_rate_n(lat) + np.array([0.0, 0.0, 0.05])
    f = C @ np.array([0.0, 0.0, float(normal_gravity(lat, 0.0))]) + np.array([0.0, 0.3, 0.0])
    dth = (w + rng.normal(size=(n, 3)) * 1e-3) * dt
    dv = (f + rng.normal(size=(n, 3)) * 1e-2) * dt
    return dt * np.arange(1, n + 1), dth, dv, lat, C


def main(n=4_000_000, repeats=3):
    t, dth, dv, lat, C = simulated_increments(n)
    integrate(t[:1000], dth[:1000], dv[:1000], lat, 0.0, 0.0, np.zeros(3), C, t0=0.0)  # compile
    best = np.inf
    for _ in range(repeats):
        t1 = time.perf_counter()
        integrate(t, dth, dv, lat, 0.0, 0.0, np.zeros(3), C, t0=0.0)
        best = min(best, time.perf_counter() - t1)
    print(f"batch mechanization: {n} samples in {best:.3f} s = {n / best / 1e6:.2f}e6 samples/s "
          "(one core, simulated data)")
    m = 20_000
    ins = Strapdown(lat, 0.0, 0.0, np.zeros(3), C)
    t1 = time.perf_counter()
    for k in range(m):
        ins.update(dth[k], dv[k], 0.005)
    el = time.perf_counter() - t1
    print(f"streaming update(): {m / el / 1e3:.1f}e3 samples/s (Python call per sample)")
    return n / best


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 4_000_000)
