"""Benchmark: 1,000 static-latitude Monte Carlo runs with 1 and 2 local Dask workers.

    python benchmarks/bench_montecarlo.py [--runs 1000] [--repeat 3] [--json]

For each cluster size it reports the end-to-end time of one campaign (cluster start-up, worker
warm-up and shut-down included: what ``selfnav montecarlo`` costs) and the best of ``--repeat``
campaigns on the warm cluster (the compute part the speed-up is about), then the speed-up from 1
to 2 workers and the in-process time without Dask. The best-of-N guards against other jobs on a
shared machine; the load average is printed so that a reader can judge. Results are checked to be
identical in every mode. Scenario: the registered default (60 s at 100 Hz, random latitude and
attitude). Simulated data only.
"""
from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from selfnav.montecarlo import local_cluster, run_montecarlo


def main() -> None:
    from dask.distributed import Client

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    out = {"runs": a.runs, "cpu_count": os.cpu_count(), "load_average_start": os.getloadavg()}
    best = np.inf
    for _ in range(a.repeat):
        t = time.perf_counter()
        r0 = run_montecarlo("static-latitude", a.runs, seed=a.seed, workers=0)
        best = min(best, time.perf_counter() - t)
    out["in_process_s"] = best
    for w in (1, 2):
        t = time.perf_counter()
        r = run_montecarlo("static-latitude", a.runs, seed=a.seed, workers=w)
        out[f"workers_{w}_end_to_end_s"] = time.perf_counter() - t
        assert np.array_equal(r.table["error"], r0.table["error"]), "results depend on workers"
        with local_cluster(w) as cl, Client(cl) as client:
            run_montecarlo("static-latitude", 4 * w, seed=a.seed + 1, client=client,
                           chunk_size=1)  # warm-up: imports and numba cache in every worker
            times = []
            for _ in range(a.repeat):
                r = run_montecarlo("static-latitude", a.runs, seed=a.seed, client=client)
                times.append(r.compute_s)
            out[f"workers_{w}_compute_s"] = min(times)
            out[f"workers_{w}_compute_all_s"] = times
    out["speedup_compute"] = out["workers_1_compute_s"] / out["workers_2_compute_s"]
    out["speedup_end_to_end"] = out["workers_1_end_to_end_s"] / out["workers_2_end_to_end_s"]
    out["load_average_end"] = os.getloadavg()
    out["summary"] = r0.summary
    if a.json:
        print(json.dumps(out, indent=2))
        return
    print(f"{a.runs} static-latitude runs, {os.cpu_count()} cores, load average "
          f"{out['load_average_start'][0]:.2f} -> {out['load_average_end'][0]:.2f} "
          "(identical results in all modes)")
    print(f"  in-process, no Dask (best of {a.repeat})     {out['in_process_s']:6.2f} s")
    for w in (1, 2):
        name = f"{w} worker{'s' if w > 1 else ' '}"
        print(f"  {name}: end to end {out[f'workers_{w}_end_to_end_s']:6.2f}"
              f" s, warm cluster best of {a.repeat} {out[f'workers_{w}_compute_s']:6.2f} s "
              f"({', '.join(f'{x:.2f}' for x in out[f'workers_{w}_compute_all_s'])})")
    print(f"  speed-up 1 -> 2 workers: {out['speedup_compute']:.2f}x (warm), "
          f"{out['speedup_end_to_end']:.2f}x (end to end)")
    s = r0.summary
    print(f"  RMS error {s['rms_error']:.4f}°, bound {s['rms_bound']:.4f}° "
          f"(ratio {s['rms_error_over_bound']:.3f}), RMS(e/σ) {s['rms_normalized_error']:.3f}, "
          f"within 2σ {100 * s['fraction_within_2sigma']:.1f} %")


if __name__ == "__main__":
    main()
