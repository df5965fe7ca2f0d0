"""Timing in the moving-base error budget: latitude and longitude error per ms of attitude–gyro
clock offset, for the ship, aircraft and car motion of ``selfnav.sim``.

For each profile (a perfect IMU, 100 Hz attitude from the truth): the linear sensitivity that
``navigate_moving`` reports (``lat_error_per_ms_deg``, RMS after the 3/K start) and a direct
check — the solution with the offset fixed 1 ms wrong minus the one with the right offset — at
the default gain (B = 0.01 Hz) and at the gain ``grade_table`` picks for navigation grade. The
clock requirement is the residual offset at which the timing error equals one third of the
grade's latitude σ (so that it adds < 6 % in quadrature).

    python experiments/moving_timing_budget.py            # all three (about 1 min)
"""
from __future__ import annotations

import argparse

import numpy as np

from selfnav.moving_budget import grade_table
from selfnav.moving_driver import navigate_moving
from selfnav.sim.scenarios import simulate
from selfnav.types import AttitudeData

PROFILES = {
    "ship": dict(duration=1800.0, lat_deg=45.0, lon_deg=30.0),
    "aircraft": dict(duration=900.0),
    "car": dict(duration=600.0),
}


def profile_run(kind, seed=1):
    cfg = {"scenario": {"kind": kind, "truth_hz": 0.0, **{k: v for k, v in PROFILES[kind].items()}},
           "imu": {"grade": "perfect"}, "gnss": {"enabled": False}, "mag": {"enabled": False}}
    sim = simulate(cfg, seed=seed)
    tr = sim.truth
    return sim.imu, AttitudeData(tr.t, tr.C_nb, f"simulated {kind} attitude"), tr


def sensitivity(imu, A, tr, gain):
    kw = dict(gain=gain)
    s0 = navigate_moving(imu, A, tr.lat[0], tr.lon[0], attitude_time_offset=0.0, **kw)
    s1 = navigate_moving(imu, A, tr.lat[0], tr.lon[0], attitude_time_offset=1e-3, **kw)
    est = navigate_moving(imu, A, tr.lat[0], tr.lon[0], **kw)
    ok = s0.t > s0.t[0] + 3.0 / s0.gain
    d = np.degrees(np.interp(s0.t, s1.t, s1.lat) - s0.lat)[ok]      # s1 is on shifted times
    dl = np.degrees((np.interp(s0.t[-1], s1.t, np.unwrap(s1.lon)) - np.unwrap(s0.lon)[-1] + np.pi)
                    % (2 * np.pi) - np.pi)
    lat = np.interp(est.t, tr.t, tr.lat)
    ok = est.t > est.t[0] + 3.0 / est.gain
    return {"pred_lat": s0.info["lat_error_per_ms_deg"], "pred_lon": s0.info["lon_error_per_ms_deg"],
            "direct_lat_rms": float(np.sqrt(np.mean(d**2))), "direct_lat_max": float(np.abs(d).max()),
            "direct_lon": float(abs(dl)), "offset_found_ms": 1e3 * est.info["attitude_time_offset_s"],
            "lat_rms_est": float(np.degrees(np.sqrt(np.mean((est.lat - lat)[ok] ** 2))))}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--profiles", default="ship,aircraft,car")
    a = ap.parse_args()
    table = {r["grade"]: r for r in grade_table()}
    gains = {"default K = 0.0628 (B = 0.01 Hz)": (2 * np.pi * 0.01, None)}
    for g in ("navigation", "tactical"):
        gains[f"{g}-grade K = {table[g]['gain_per_s']:.4f}"] = (table[g]["gain_per_s"],
                                                                table[g]["lat_sigma_deg"])
    print("profile | gain | lat error per ms (model RMS / direct RMS / direct max) | "
          "lon error per ms at end (model / direct) | clock for the grade (timing = σ/3) | "
          "offset found, lat RMS after 3/K (estimated offset, perfect sensors)")
    for kind in a.profiles.split(","):
        imu, A, tr = profile_run(kind)
        for name, (K, sig) in gains.items():
            r = sensitivity(imu, A, tr, K)
            clock = "" if sig is None else f"{sig / 3 / r['pred_lat']:.3g} ms"
            print(f"{kind} | {name} | {r['pred_lat']:.3g}° / {r['direct_lat_rms']:.3g}° / "
                  f"{r['direct_lat_max']:.3g}° | {r['pred_lon']:.2g}° / {r['direct_lon']:.2g}° | {clock} | "
                  f"{r['offset_found_ms']:+.2e} ms, {r['lat_rms_est']:.2e}°", flush=True)


if __name__ == "__main__":
    main()
