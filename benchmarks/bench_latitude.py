"""Benchmark (run by hand): static latitude end to end from CSV, and the estimator alone.

Targets (issue 2): a 1 h, 200 Hz file (720,000 samples) end to end from CSV in under 2 s on one
core; the estimator alone over 1e7 samples/s.

    python benchmarks/bench_latitude.py
"""
import os
import tempfile
import time

import numpy as np

from selfnav import latitude as L
from selfnav.io.csvio import write_csv
from selfnav.io.readers import read_imu
from selfnav.sim.static import static_imu


def main():
    imu = static_imu(np.radians(50), 3600, 0.005, roll=0.01, pitch=0.02, heading=1.0,
                     arw=np.radians(0.01) / 60, vrw=1e-4, seed=0)
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "imu.csv")
        write_csv(p, {"t": imu.t, "wx": imu.omega_ib_b[:, 0], "wy": imu.omega_ib_b[:, 1],
                      "wz": imu.omega_ib_b[:, 2], "fx": imu.f_ib_b[:, 0], "fy": imu.f_ib_b[:, 1],
                      "fz": imu.f_ib_b[:, 2]}, fmt="%.12g")
        L.estimate_latitude(imu)  # compile the numba kernel once (cached afterwards)
        t0 = time.perf_counter()
        data = read_imu(p)
        t1 = time.perf_counter()
        res = L.estimate_latitude(data)
        t2 = time.perf_counter()
    n = len(imu)
    print(f"samples: {n}")
    print(f"read CSV: {t1 - t0:.3f} s; estimate: {t2 - t1:.3f} s; end to end: {t2 - t0:.3f} s")
    print(f"latitude error: {np.degrees(res.latitude) - 50:+.5f} deg (sigma {np.degrees(res.sigma):.5f})")
    for rest in ("still", "disturbed"):
        reps = 5
        t0 = time.perf_counter()
        for _ in range(reps):
            L.estimate_latitude(imu, rest=rest)
        dt = (time.perf_counter() - t0) / reps
        print(f"estimator alone ({rest}): {n / dt / 1e6:.1f} M samples/s")
    w, f = imu.omega_ib_b, imu.f_ib_b
    t0 = time.perf_counter()
    for _ in range(20):
        L.latitude_angle(w.mean(0), f.mean(0))
    dt = (time.perf_counter() - t0) / 20
    print(f"closed form on the means (mean + angle): {n / dt / 1e6:.1f} M samples/s")


if __name__ == "__main__":
    main()
