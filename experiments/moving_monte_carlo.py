"""Monte Carlo of ``selfnav.moving_driver.navigate_moving``: is the reported σ honest?

Simulated ship tracks (``selfnav.sim.ship`` through the exact inverse strapdown), a sensor
grade of ``selfnav.sensors.GRADES`` on the gyros (its own error model: bias, Gauss-Markov,
ARW, scale factor, misalignment, quantum), the attitude source of the same grade
(``selfnav.moving_budget.ATTITUDE_SOURCES``: white noise per sample and a drift ramp), and the
attitude stamped late or early by a random offset in ±``max_offset_ms``. Each run alternates the
IMU row convention (interval means or instantaneous samples, told to the driver). The offset is
estimated (default) or, with ``--fixed-error-ms E``, fixed by hand with an error in ±E ms.

    python experiments/moving_monte_carlo.py                       # navigation grade, 40 runs
    python experiments/moving_monte_carlo.py --grade tactical --runs 20
    python experiments/moving_monte_carlo.py --fixed-error-ms 2
    python experiments/moving_monte_carlo.py --grade-gain            # K of grade_table

Prints per run the latitude RMS error, the RMS of error/σ (after 5/K) and the offset error, then
the ensemble RMS(error/σ) for latitude and final longitude (target 0.7–1.5).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from selfnav import attitude as att
from selfnav import sensors
from selfnav.moving_budget import grade_errors
from selfnav.moving_driver import navigate_moving
from selfnav.sim.inverse import TrajectorySpline, imu_from_trajectory
from selfnav.sim.ship import ship_trajectory
from selfnav.types import AttitudeData, ImuData


def make_track(lat_deg, course_deg, duration, dt, seed):
    """Trajectory, interval-mean IMU, instantaneous rates and truth on the IMU knots."""
    tr = ship_trajectory(duration, dt, np.radians(lat_deg), np.radians(20.0), course_deg=course_deg,
                         seed=seed)
    imu, truth = imu_from_trajectory(tr, dt, return_truth=True)
    inst = TrajectorySpline(tr).kinematics(imu.t)["omega_ib_b"]
    return imu, inst, truth


def one_run(imu, inst, truth, *, grade, rates, offset, rng, fixed_error=None, gain=None):
    """One noisy run; returns a dict of errors and σ (rad, s)."""
    model = sensors.imu_grade(grade)
    w_true = imu.omega_ib_b if rates == "interval-mean" else inst
    w, _ = model.apply(imu.t, w_true, imu.f_ib_b, rng)
    g = grade_errors(grade)
    n = len(truth.t)
    eps = (rng.normal(0.0, g["attitude_noise"], (n, 3))
           + np.outer(truth.t - truth.t[0], rng.normal(0.0, g["attitude_rate"], 3)))
    C_bn = att.rotvec_to_dcm(eps) @ np.swapaxes(truth.C_nb, -1, -2)
    A = AttitudeData(truth.t + offset, np.swapaxes(C_bn, -1, -2), "simulated attitude")
    data = ImuData(imu.t, w, imu.f_ib_b, source="simulated")
    given = None if fixed_error is None else offset + fixed_error
    sol = navigate_moving(data, A, truth.lat[0], truth.lon[0], rates=rates, grade=grade,
                          attitude_time_offset=given, gain=gain)
    lat = np.interp(sol.t, truth.t, truth.lat)
    lon = np.interp(sol.t, truth.t, np.unwrap(truth.lon))
    e = sol.lat - lat
    el = (sol.lon - lon + np.pi) % (2 * np.pi) - np.pi
    ok = sol.t > sol.t[0] + 5.0 / sol.gain
    k = np.flatnonzero(ok)[:: max(1, ok.sum() // 200)]   # ~200 nearly independent samples
    return {"lat_rms": float(np.sqrt(np.mean(e[ok] ** 2))),
            "z_lat": e[k] / sol.sigma_lat[k], "z_lon": el[-1] / sol.sigma_lon[-1],
            "offset_err": sol.info["attitude_time_offset_s"] - offset,
            "sigma_lat_end": float(sol.sigma_lat[-1]), "lon_err": float(el[-1])}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--grade", default="navigation")
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--duration", type=float, default=1800.0)
    ap.add_argument("--dt", type=float, default=0.02)
    ap.add_argument("--max-offset-ms", type=float, default=50.0)
    ap.add_argument("--fixed-error-ms", type=float, default=None)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--grade-gain", action="store_true",
                    help="use the gain grade_table picks for the grade (default: B = 0.01 Hz)")
    a = ap.parse_args()
    gain = None
    if a.grade_gain:
        from selfnav.moving_budget import grade_table

        gain = {r["grade"]: r for r in grade_table(a.dt)}[a.grade]["gain_per_s"]
    rng = np.random.default_rng(a.seed)
    tracks = [make_track(45.0, 30.0, a.duration, a.dt, 1), make_track(-38.0, -140.0, a.duration, a.dt, 2)]
    z_lat, z_lon, rows = [], [], []
    t0 = time.perf_counter()
    for i in range(a.runs):
        imu, inst, truth = tracks[i % 2]
        rates = ("interval-mean", "instantaneous")[(i // 2) % 2]
        off = rng.uniform(-a.max_offset_ms, a.max_offset_ms) * 1e-3
        fe = None if a.fixed_error_ms is None else rng.uniform(-1, 1) * a.fixed_error_ms * 1e-3
        r = one_run(imu, inst, truth, grade=a.grade, rates=rates, offset=off, rng=rng, fixed_error=fe,
                    gain=gain)
        z_lat.append(r["z_lat"])
        z_lon.append(r["z_lon"])
        rows.append(r)
        print(f"run {i:3d} {'N' if i % 2 == 0 else 'S'} {rates:13s} offset {1e3 * off:+7.2f} ms  "
              f"found {1e3 * r['offset_err']:+.2e} ms off  lat RMS {np.degrees(r['lat_rms']):.4f}°  "
              f"RMS(e/σ) {np.sqrt(np.mean(r['z_lat'] ** 2)):.2f}  lon end {np.degrees(r['lon_err']):+.4f}° "
              f"(e/σ {r['z_lon']:+.2f})", flush=True)
    zl = np.concatenate(z_lat)
    print(f"\n{a.runs} runs, grade {a.grade}, K = {gain or 2 * np.pi * 0.01:.4g}, "
          f"{a.duration:g} s at {1 / a.dt:g} Hz, offsets ±{a.max_offset_ms:g} ms"
          + ("" if a.fixed_error_ms is None else f", fixed by hand with error ±{a.fixed_error_ms:g} ms")
          + f" ({time.perf_counter() - t0:.0f} s)")
    print(f"latitude: RMS error {np.degrees(np.sqrt(np.mean([r['lat_rms'] ** 2 for r in rows]))):.4f}°, "
          f"mean σ at the end {np.degrees(np.mean([r['sigma_lat_end'] for r in rows])):.4f}°, "
          f"RMS(error/σ) {np.sqrt(np.mean(zl ** 2)):.2f}")
    print(f"final longitude: RMS(error/σ) {np.sqrt(np.mean(np.square(z_lon))):.2f}")
    print(f"offset error: RMS {1e3 * np.sqrt(np.mean([r['offset_err'] ** 2 for r in rows])):.2e} ms, "
          f"max {1e3 * np.max(np.abs([r['offset_err'] for r in rows])):.2e} ms")


if __name__ == "__main__":
    main()
