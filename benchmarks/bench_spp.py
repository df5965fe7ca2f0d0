"""Benchmark (run by hand): SPP and the speed/yaw-rate filter on smartLoc Berlin Potsdamer Platz,
and ``selfnav spp`` (raw measurements) on every raw record.

Prints the tables of ``docs/smartloc.md``: horizontal error against the ground truth of raw SPP
(several weightings, with and without Sagnac and RAIM), the robust filter, the filter without
the window test (χ² gate only) and the RTS smoother, for a few fix-σ scales; and the run times.
Then the raw-SPP table of ``docs/gnss.md`` (accuracy, σ, epochs/s).

    python benchmarks/bench_spp.py [DATA_FOLDER]      # ~1 min on 2 cores
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


def raw_spp(data):
    """``selfnav spp`` (api.spp, defaults) on the raw records, against their references."""
    import os
    import warnings

    from selfnav import api
    from selfnav.earth import enu_rotation, geodetic_to_ecef
    from selfnav.io.raw_readers import read_gnss_raw

    print(f"\n## Raw SPP (selfnav spp defaults; load {os.getloadavg()[0]:.2f})\n")
    print("| record | reference | epochs | RMS m | 95 % m | max m | median σ_h m | "
          "RMS(e)/RMS(σ_h) | excluded | read s | epochs/s |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")

    def line(name, ref, sol, e, t_read, t_spp):
        sh = sol.columns["sigma_h_m"]
        print(f"| {name} | {ref} | {len(sol)} | {np.sqrt(np.mean(e**2)):.2f} | "
              f"{np.percentile(e, 95):.2f} | {e.max():.2f} | {np.median(sh):.2f} | "
              f"{np.sqrt(np.mean(e**2) / np.mean(sh**2)):.2f} | {sol.stats['excluded']} | "
              f"{t_read:.1f} | {len(sol) / t_spp:.0f} |")

    d = data / "android_raw_static_mtv"
    t0 = time.perf_counter()
    raw = read_gnss_raw(d / "pseudoranges_log_2016_06_30_21_26_07.txt", nav=d / "hour1820.16n")
    t1 = time.perf_counter()
    for tau in (30.0, 0.0):
        t2 = time.perf_counter()
        sol = api.spp(raw, smoothing_s=tau)
        t3 = time.perf_counter()
        enu = ecef_to_enu(sol.detail.spp.ecef, np.radians(37.422578), np.radians(-122.081678),
                          -28.0)
        line(f"Android static{'' if tau else ' (no smoothing)'}", "surveyed point", sol,
             np.hypot(enu[:, 0], enu[:, 1]), t1 - t0, t3 - t2)
    t0 = time.perf_counter()
    raw = read_gnss_raw(data / "rtklibexplorer_walk_0827_ubx" / "gnss_1730.ubx")
    t1 = time.perf_counter()
    rec = raw.receiver
    for systems in (None, "G", "E", "C"):
        t2 = time.perf_counter()
        try:
            sol = api.spp(raw, systems=systems)
        except Exception as e:          # GPS alone: 4 ephemerides, too few at some epochs
            print(f"| u-blox walk {systems} | - | {e} |")
            continue
        t3 = time.perf_counter()
        r = sol.detail.spp
        i = np.clip(np.searchsorted(r.t, rec.t - 0.05), 0, len(r.t) - 1)
        m = (rec.quality == 1) & (np.abs(r.t[i] - rec.t) < 0.05)
        dd = r.ecef[i[m]] - geodetic_to_ecef(rec.lat[m], rec.lon[m], rec.h[m])
        enu = np.einsum("eij,ej->ei", enu_rotation(rec.lat[m], rec.lon[m]), dd)
        off = enu.mean(0)
        line(f"u-blox walk {systems or 'G+E+C'}", "NAV-PVT fixed", sol,
             np.hypot(enu[:, 0], enu[:, 1]), t1 - t0, t3 - t2)
        c = enu[:, :2] - off[:2]
        print(f"|  | the same less its mean offset (E {off[0]:.2f}, N {off[1]:.2f}, "
              f"U {off[2]:.2f} m) | {m.sum()} | {np.sqrt(np.mean(np.sum(c**2, 1))):.2f} | | | | | | | |")
    for folder in ("smartloc_berlin_potsdamer_platz", "smartloc_berlin_potsdamer_platz_rtklib"):
        inp, gt = find_smartloc_files(data / folder)
        truth = read_smartloc_truth(gt)
        t0 = time.perf_counter()
        raw = read_gnss_raw(inp)
        t1 = time.perf_counter()
        sol = api.spp(raw)
        t3 = time.perf_counter()
        line(folder.replace("smartloc_berlin_potsdamer_platz", "smartLoc") or "smartLoc",
             "ground truth", sol, horizontal_error(sol.detail.spp, truth.t, truth.ecef),
             t1 - t0, t3 - t1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        sol = api.spp(data / "psins_insgpseo_tc" / "insgpseo_tc.mat")
        t1 = time.perf_counter()
    m = (sol.t > 185492.5) & (sol.t < 185542.5)
    print(f"\nPSINS insgpseo_tc: {len(sol)} epochs in {t1 - t0:.1f} s; static 50 s at lat "
          f"{np.degrees(np.median(sol.trajectory.lat[m])):.6f}°, lon "
          f"{np.degrees(np.median(sol.trajectory.lon[m])):.6f}°, h "
          f"{np.median(sol.trajectory.h[m]):.1f} m, median σ_h "
          f"{np.median(sol.columns['sigma_h_m']):.2f} m (no ionosphere parameters in the file)")


if __name__ == "__main__":
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT
    main(folder)
    raw_spp(folder.parent)
