"""Benchmark (run by hand): the tightly coupled speed/yaw-rate + pseudorange navigator
(``selfnav navigate --gnss-raw``; issue 23, part 3) on smartLoc Berlin Potsdamer Platz, both
files (the original and the RTKLIB-preprocessed one), against the ground truth — the tables of
docs/gnss.md.

    python benchmarks/bench_tight.py            # causal and smoothed, ~20 s
    python benchmarks/bench_tight.py --drift    # + issue 23's drift injected 24 ways, ~5 min
    python benchmarks/bench_tight.py --city 24  # + 24 SIMULATED city drives, ~4 min
    python benchmarks/bench_tight.py --timeline # + the first 90 s, every 5 s, ~10 s

``--timeline``: the causal solution of both files in its first 90 s — error, heading against
the true course (from the ground truth's positions), yaw-rate bias and speed scale — started
by the heading bank (the default) and with the true course given as the start heading
(σ 5°): where the RTKLIB file's causal error comes from (docs/gnss.md).

``--drift``: every pseudorange moved as by a receiver displaced 0.5 m/s (towards North, East,
South, West) from 40, 80 or 120 s for 120 s, then held; error against the dead-reckoning bound
(odometry alone from the clean causal state at the drift's start, calibrated by that state or
raw — the better of the two ratios is printed) + 5 m, with and without the drift guard.
"""
import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from selfnav.earth import ecef_to_enu, ecef_to_geodetic, enu_rotation
from selfnav.gnss.guard import GuardConfig
from selfnav.gnss.odometry import dead_reckon
from selfnav.gnss.spp import SppConfig, horizontal_error, spp_from_pseudoranges
from selfnav.gnss.tight import TightConfig, run_tight
from selfnav.io.smartloc import find_smartloc_files, read_smartloc_input, read_smartloc_truth

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
FILES = ("smartloc_berlin_potsdamer_platz", "smartloc_berlin_potsdamer_platz_rtklib")
LIBRSF = {FILES[0]: (7.97, 5.18), FILES[1]: (4.92, 2.42)}


def errors(res, truth):
    g = ecef_to_enu(truth.ecef, *res.origin)
    return np.hypot(res.east - np.interp(res.t, truth.t, g[:, 0]),
                    res.north - np.interp(res.t, truth.t, g[:, 1])), g


def table():
    print("| file | solution | RMS m | 95 % m | max m | RMS(e/σ_h) | delayed | s | libRSF |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name in FILES:
        inp, gt = find_smartloc_files(DATA / name)
        prs, odo = read_smartloc_input(inp)
        truth = read_smartloc_truth(gt)
        for smooth in (False, True):
            t0 = time.perf_counter()
            r = run_tight(prs, odo, smooth=smooth)
            wall = time.perf_counter() - t0
            e, _ = errors(r, truth)
            z = e / r.sigma_h
            print(f"| {name.replace('smartloc_berlin_', '')} | "
                  f"{'smoothed' if smooth else 'causal'} | {np.sqrt(np.mean(e ** 2)):.2f} | "
                  f"{np.percentile(e, 95):.1f} | {e.max():.1f} | {np.sqrt(np.mean(z ** 2)):.2f} "
                  f"| {100 * r.stats['reflected_share']:.0f} % | {wall:.1f} | "
                  f"{LIBRSF[name][int(smooth)]} |")


def drift_scan():
    print("\n| file | drift from s | towards | followed: max m (× bound) | guarded: max m "
          "(× bound) | caught after s |")
    print("| --- | ---: | --- | ---: | ---: | ---: |")
    ratios, held_ratios = [], []
    for name in FILES:
        inp, gt = find_smartloc_files(DATA / name)
        prs, odo = read_smartloc_input(inp)
        truth = read_smartloc_truth(gt)
        idx = np.clip(np.searchsorted(truth.t, prs.t), 0, len(truth.t) - 1)
        u = prs.sat_ecef - truth.ecef[idx]
        u /= np.linalg.norm(u, axis=1)[:, None]
        lat, lon, _ = ecef_to_geodetic(truth.ecef[0])
        u_enu = u @ enu_rotation(lat, lon).T
        clean = run_tight(prs, odo)
        for t0 in (40.0, 80.0, 120.0):
            k0, i0 = int(np.searchsorted(clean.t, t0)), int(np.searchsorted(odo.t, t0))
            _, g = errors(clean, truth)
            bounds = []
            for s0, b0 in ((clean.scale[k0], clean.yaw_bias[k0]), (1.0, 0.0)):
                dr = dead_reckon(odo.t[i0:], odo.speed[i0:], odo.yaw_rate[i0:],
                                 (clean.east[k0], clean.north[k0], clean.heading[k0], s0, b0))
                bounds.append(np.hypot(dr[:, 0] - np.interp(odo.t[i0:], truth.t, g[:, 0]),
                                       dr[:, 1] - np.interp(odo.t[i0:], truth.t, g[:, 1])) + 5)
            for az, word in ((0, "North"), (90, "East"), (180, "South"), (270, "West")):
                a = np.radians(az)
                d = np.clip(prs.t - t0, 0.0, 120.0) * 0.5
                bad = replace(prs, pr=prs.pr - d * (u_enu[:, 0] * np.sin(a)
                                                    + u_enu[:, 1] * np.cos(a)))
                out = []
                for guard in (False, True):
                    cfg = TightConfig(guard=GuardConfig()) if guard else TightConfig()
                    r = run_tight(bad, odo, cfg)
                    e, _ = errors(r, truth)
                    after = r.t >= t0
                    ratio = min(np.max(e[after] / np.interp(r.t[after], odo.t[i0:], b))
                                for b in bounds)
                    out.append((e[after].max(), ratio, r.stats["guard_episodes"]))
                ratios.append(out[0][1])
                held_ratios.append(out[1][1])
                ep = out[1][2]
                caught = f"{ep[0]['start_s'] - t0:.0f}" if ep else "—"
                print(f"| {name.replace('smartloc_berlin_', '')} | {t0:.0f} | {word} | "
                      f"{out[0][0]:.1f} ({out[0][1]:.2f}) | {out[1][0]:.1f} ({out[1][1]:.2f}) | "
                      f"{caught} |", flush=True)
    held_ratios = np.array(held_ratios)
    print(f"\nwithin the bound: followed {np.sum(np.array(ratios) <= 1)} of {len(ratios)}, "
          f"guarded {np.sum(held_ratios <= 1)} of {len(held_ratios)} (worst "
          f"{held_ratios.max():.2f}×, median {np.median(held_ratios):.2f}×)")


def city(n):
    """SIMULATED city drives (selfnav.sim.urban), seeds 0 … n−1: SPP, causal, smoothed, and the
    drift guard on drives without any drift (a hold there is a false alarm)."""
    from selfnav.sim.urban import horizontal_errors, simulate_urban_drive

    print("\n| seed | satellites / epoch | SPP m | causal m | RMS(e/σ_h) | smoothed m | "
          "--drift-guard m | holds |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    rows = []
    for seed in range(n):
        prs, odo, truth = simulate_urban_drive(seed)
        sp = spp_from_pseudoranges(prs, SppConfig(weighting="cn0"))
        out = [len(prs.t) / len(np.unique(prs.t)),
               np.sqrt(np.nanmean(horizontal_error(sp, truth.t, truth.ecef) ** 2))]
        for cfg, sm in ((TightConfig(), False), (TightConfig(), True),
                        (TightConfig(guard=GuardConfig()), False)):
            r = run_tight(prs, odo, cfg, smooth=sm)
            e = horizontal_errors(r.t, r.east, r.north, r.origin, truth)
            out.append(np.sqrt(np.mean(e ** 2)))
            if not sm and cfg.guard is None:
                out.append(np.sqrt(np.mean((e / r.sigma_h) ** 2)))
        out.append(len(r.stats["guard_episodes"]))
        out.append(r.stats["guard_max_llr"])
        rows.append(out)
        print(f"| {seed} | {out[0]:.1f} | {out[1]:.1f} | {out[2]:.2f} | {out[3]:.1f} | "
              f"{out[4]:.2f} | {out[5]:.2f} | {out[6]} |", flush=True)
    a = np.array(rows, float)
    print(f"\nmedian drive: SPP {np.median(a[:, 1]):.1f} m, causal {np.median(a[:, 2]):.2f} m "
          f"(pooled {np.sqrt(np.mean(a[:, 2] ** 2)):.1f}, worst {a[:, 2].max():.1f}), e/σ "
          f"{np.median(a[:, 3]):.1f} (worst {a[:, 3].max():.0f}), smoothed "
          f"{np.median(a[:, 4]):.2f} m (worst {a[:, 4].max():.1f}); --drift-guard "
          f"{np.median(a[:, 5]):.2f} m, holding without a drift on {int(np.sum(a[:, 6] > 0))} "
          f"of {n} drives (Λ up to {a[:, 7].max():.0f})")


def timeline():
    import math

    for name in FILES:
        inp, gt = find_smartloc_files(DATA / name)
        prs, odo = read_smartloc_input(inp)
        truth = read_smartloc_truth(gt)
        for given in (False, True):
            r = run_tight(prs, odo)
            e, g = errors(r, truth)
            east, north = (np.interp(r.t, truth.t, g[:, i]) for i in (0, 1))
            course = np.degrees(np.arctan2(np.gradient(east, r.t), np.gradient(north, r.t)))
            if given:
                r = run_tight(prs, odo, heading0=(math.radians(course[0]), math.radians(5.0)))
                e, _ = errors(r, truth)
            print(f"\n{name.replace('smartloc_berlin_', '')}, start "
                  f"{'given the true course' if given else 'by the heading bank'}: RMS "
                  f"{np.sqrt(np.mean(e ** 2)):.2f} m\n")
            print("| t s | error m | σ_h m | heading − course ° | yaw-rate bias °/s | scale |")
            print("| ---: | ---: | ---: | ---: | ---: | ---: |")
            t = r.t - r.t[0]
            for a in np.arange(0.0, 90.0, 5.0):
                k = int(np.searchsorted(t, a))
                d = (np.degrees(r.heading[k]) - course[k] + 180.0) % 360.0 - 180.0
                print(f"| {t[k]:.1f} | {e[k]:.1f} | {r.sigma_h[k]:.2f} | {d:+.1f} | "
                      f"{np.degrees(r.yaw_bias[k]):+.3f} | {r.scale[k]:.3f} |")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--drift", action="store_true", help="the drift-injection scan (~5 min)")
    ap.add_argument("--city", type=int, default=0, metavar="N",
                    help="N SIMULATED city drives (~10 s each)")
    ap.add_argument("--timeline", action="store_true",
                    help="the first 90 s of the causal solution, bank or true course (~10 s)")
    args = ap.parse_args()
    table()
    if args.drift:
        drift_scan()
    if args.city:
        city(args.city)
    if args.timeline:
        timeline()
