"""Benchmark: 1 h of 200 Hz gyros + attitude through the moving-base method (target < 5 s).

    python benchmarks/bench_moving.py            # library (arrays in memory), three methods,
                                                 # and navigate_moving (offset estimation incl.)
    python benchmarks/bench_moving.py --cli      # also the CLI end to end on CSV files (I/O incl.)

Data are simulated (a ship, error-free sensors); the first call compiles the numba kernels
(cached on disk), so each method is timed on a second run.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from selfnav import attitude as att
from selfnav import moving as mv
from selfnav.moving_driver import navigate_moving
from selfnav.sim.ship import exact_body_rates, ship_trajectory
from selfnav.types import AttitudeData, ImuData


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--cli", action="store_true")
    a = ap.parse_args()
    tr = ship_trajectory(a.hours * 3600.0, 1.0 / a.rate, np.radians(45.0), np.radians(20.0))
    w = exact_body_rates(tr)
    n = len(tr.t)
    print(f"simulated ship: {n} samples ({a.hours:g} h at {a.rate:g} Hz)")
    for method in ("observer", "discrete", "euler"):
        nav = mv.MovingBaseNavigator(tr.lat[0], tr.lon[0], method=method)
        nav.run(tr.t[:1000], tr.C_nb[:1000], omega_ib_b=w[:1000], rates="instantaneous")  # compile
        t0 = time.perf_counter()
        sol = nav.run(tr.t, tr.C_nb, omega_ib_b=w, rates="instantaneous")
        dt = time.perf_counter() - t0
        e = np.degrees(sol.lat - tr.lat[1:])
        print(f"{method:9s} {dt:6.2f} s  ({n / dt / 1e3:.0f} k samples/s)  lat RMS {np.sqrt(np.mean(e**2)):.2e}°  "
              f"lon end {np.degrees(sol.lon[-1] - tr.lon[-1]):+.2e}°  {'OK' if dt < 5 else 'SLOW'} (< 5 s)")
    imu = ImuData(tr.t, w, np.zeros_like(w), source="simulated")
    att_late = AttitudeData(tr.t + 0.02, tr.C_nb, "simulated, 20 ms late")
    navigate_moving(imu.select(slice(0, 5000)), AttitudeData(tr.t[:5000], tr.C_nb[:5000]), tr.lat[0],
                    tr.lon[0], rates="instantaneous")
    t0 = time.perf_counter()
    sol = navigate_moving(imu, att_late, tr.lat[0], tr.lon[0], rates="instantaneous")
    dt = time.perf_counter() - t0
    e = np.degrees(sol.lat - np.interp(sol.t, tr.t, tr.lat))
    print(f"navigate_moving (offset estimated: {1e3 * sol.info['attitude_time_offset_s']:.4f} ms of 20) "
          f"{dt:6.2f} s  lat RMS {np.sqrt(np.mean(e**2)):.2e}°  {'OK' if dt < 5 else 'SLOW'} (< 5 s)")
    if a.cli:
        from selfnav.io.csvio import write_csv

        with tempfile.TemporaryDirectory() as d:
            d = Path(d)
            f = np.einsum("nij,j->ni", tr.C_nb, [0.0, 0.0, 9.8])
            write_csv(d / "imu.csv", dict(t=tr.t, wx=w[:, 0], wy=w[:, 1], wz=w[:, 2], fx=f[:, 0],
                                          fy=f[:, 1], fz=f[:, 2]), comments=[tr.source], fmt="%.15g")
            r, p, h = att.euler_from_dcm_nb(tr.C_nb)
            write_csv(d / "att.csv", dict(t=tr.t, roll_deg=np.degrees(r), pitch_deg=np.degrees(p),
                                          heading_deg=np.degrees(h)), comments=[tr.source], fmt="%.12g")
            cmd = [sys.executable, "-m", "selfnav", "moving", "--imu", str(d / "imu.csv"), "--attitude",
                   str(d / "att.csv"), "--lat0-deg", "45", "--lon0-deg", "20", "--out", str(d / "sol.csv"),
                   "--json", "--out-step-s", "1", "--imu-rates", "instantaneous"]
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True)
            print(f"CLI end to end (read 2 CSV of {n} rows, solve, write 1 Hz): {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
