"""Benchmark (run by hand): SPP and the speed/yaw-rate filter on smartLoc Berlin Potsdamer Platz.

Prints the tables of ``docs/smartloc.md``: horizontal error against the ground truth of raw SPP
(several weightings, with and without Sagnac and RAIM), the robust filter, the filter without
the window test (χ² gate only) and the RTS smoother, for a few fix-σ scales; and the run times.

    python benchmarks/bench_spp.py [DATA_FOLDER]      # ~10 s on 2 cores
"""
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from selfnav.io.smartloc import find_smartloc_files, read_smartloc_input, read_smartloc_truth
from selfnav.earth import ecef_to_enu
from selfnav.gnss.odometry import OdoConfig, horizontal_metrics, run_odometry_filter, run_smartloc
from selfnav.gnss.spp import SppConfig, horizontal_error, spp_from_pseudoranges

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "data" / "smartloc_berlin_potsdamer_platz"


def row(name, m, extra=""):
    return f"| {name} | {m['rms_m']:.1f} | {m['p95_m']:.1f} | {m['max_m']:.1f} | {extra} |"


def main(folder):
    inp, gt = find_smartloc_files(folder)
    prs, odo = read_smartloc_input(inp)
    truth = read_smartloc_truth(gt)

    print("## SPP variants\n")
    print("| SPP | RMS m | 95 % m | max m | excluded sats / time |")
    print("| --- | --- | --- | --- | --- |")
    variants = [("C/N0 weights, Sagnac, RAIM (used by the filter)", SppConfig(weighting="cn0")),
                ("file variances, Sagnac, RAIM", SppConfig()),
                ("elevation weights, Sagnac, RAIM", SppConfig(weighting="elevation")),
                ("C/N0 weights, Sagnac, no RAIM", SppConfig(weighting="cn0", raim=False)),
                ("C/N0 weights, no Sagnac, RAIM", SppConfig(weighting="cn0", sagnac=False)),
                ("equal weights, Sagnac, no RAIM", SppConfig(weighting="equal", raim=False))]
    for name, cfg in variants:
        t0 = time.perf_counter()
        res = spp_from_pseudoranges(prs, cfg)
        dt = time.perf_counter() - t0
        e = horizontal_error(res, truth.t, truth.ecef)
        m = {"rms_m": float(np.sqrt(np.mean(e**2))), "p95_m": float(np.percentile(e, 95)),
             "max_m": float(e.max())}
        print(row(name, m, f"{res.stats['excluded']} / {dt:.2f} s"))

    print("\n## Filters (defaults: fix σ = 2 × SPP formal σ, window 6)\n")
    t0 = time.perf_counter()
    m = run_smartloc(folder)
    wall = time.perf_counter() - t0
    print("| solution | RMS m | 95 % m | max m | fixes rejected |")
    print("| --- | --- | --- | --- | --- |")
    print(row("raw SPP (C/N0 weights)", m["spp"], "-"))
    print(row("robust filter (χ² gate + window test)", m["robust"], m["robust_stats"]["rejected"]))
    print(row("filter without window test (χ² gate only)", m["gate_only"],
              m["gate_only_stats"]["rejected"]))
    print(row("robust filter + RTS smoother", m["smoother"], m["smoother_stats"]["rejected"]))
    print(f"\nwhole run (read, SPP, three filter runs): {wall:.2f} s; SPP alone {m['spp_time_s']:.2f} s")

    print("\n## Sensitivity to the fix σ scale (RMS m: robust / gate only / smoother)\n")
    sp = spp_from_pseudoranges(prs, SppConfig(weighting="cn0"))
    origin = (sp.lat[0], sp.lon[0], sp.h[0])
    z = ecef_to_enu(sp.ecef, *origin)[:, :2]
    g = ecef_to_enu(truth.ecef, *origin)[:, :2]
    print("| σ scale | robust | gate only | smoother | robust, no heading widening |")
    print("| --- | --- | --- | --- | --- |")
    for sc in (1.5, 2.0, 3.0, 4.0, 8.0):
        c = OdoConfig(fix_sigma_scale=sc)
        out = []
        for cc, sm in ((c, False), (replace(c, robust=False), False), (c, True),
                       (replace(c, reacquire_heading=False), False)):
            r = run_odometry_filter(odo.t, odo.speed, odo.yaw_rate, sp.t, z, sp.sigma_m, cc, smooth=sm)
            out.append(horizontal_metrics(r["x"][:, :2] - g)["rms_m"])
        print(f"| {sc:g} | " + " | ".join(f"{x:.1f}" for x in out) + " |")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT)
