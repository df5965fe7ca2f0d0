"""Where the per-track accuracy of ``selfnav match`` goes on the issue-21 real-like fleets
(simulated): every fix matched 5 m or more from its true route, sorted by kind, and what it
costs the per-track mean.

The fleets are ``benchmarks/bench_mapmatch.py real``'s (263 tracks of 2–20 fixes, σ 1–4 m,
half Gauss–Markov, 2 % multipath, stationary runs), matched through the same Python API
``selfnav match`` calls (``benchmarks/bench_mapmatch.py::fleet_run``), on the shipped map and
on its unjoined form. A missed fix is sorted by

* ``raw_good`` / ``raw_bad``: its own (raw) fix within 5 m of the true route or not — a raw
  fix that is good and a match that is not is a road chosen wrongly (a parallel way, the
  crossing road at a track's end, a standing car's run on the way beside it);
* ``moved``: the match is more than 5 σ from the fix (an outlier put on its neighbours'
  route, or an end fix put where its one neighbour is);
* ``end``: the first or the last fix of its track; ``short``: a track of 2–3 fixes.

    python experiments/match_misses.py [--map helsinki_centre] [--seeds 2 3 4 5 6] [-v]

``-v`` lists each missed fix (track, index, distance of the match and of the raw fix from the
route, flag, ``match_p``).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from bench_mapmatch import BANDS, _read_matched, fleet_run  # noqa: E402

from selfnav.roads.graph import packaged_map, project_to_polyline, read_roads  # noqa: E402
from selfnav.sim.fleet import simulate_real_fleet, unjoin_map  # noqa: E402

N_TRACKS = 263


def misses(truth, tracks, out_csv, verbose=False):
    """``(kind, 1 / track length)`` of each fix of ``tracks`` matched ≥ 5 m off its route."""
    by = _read_matched(out_csv)
    found = []
    for tr in tracks:
        lat, lon, flag, p = by[tr.track_id]
        x, y = truth.to_local(lat, lon)
        _, cross, _ = project_to_polyline(np.column_stack([x, y]), tr.polyline)
        if len(cross) != len(tr.t):        # repeated stamps merged: rows do not pair up
            continue
        _, cross_raw, _ = project_to_polyline(tr.xy, tr.polyline)
        moved = np.hypot(tr.xy[:, 0] - x, tr.xy[:, 1] - y)
        n = len(cross)
        for k in np.flatnonzero(np.abs(cross) >= 5.0):
            kind = ("raw_good" if abs(cross_raw[k]) < 5.0 else "raw_bad") \
                + ("_moved" if moved[k] > 5.0 * tr.sigma else "") \
                + ("_end" if k in (0, n - 1) else "") + ("_short" if n <= 3 else "")
            found.append((kind, 1.0 / n))
            if verbose:
                print(f"   {tr.track_id} fix {k} of {n}: match {cross[k]:+.1f} m, raw "
                      f"{cross_raw[k]:+.1f} m, moved {moved[k]:.1f} m, flag {int(flag[k])}, "
                      f"match_p {p[k]:.2f} ({kind})")
    return found


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--map", default="helsinki_centre")
    ap.add_argument("--seeds", type=int, nargs="+", default=[2, 3, 4, 5, 6])
    ap.add_argument("-v", action="store_true")
    a = ap.parse_args(argv)
    truth = read_roads(packaged_map(a.map), strongly_connected=False)
    sigma = BANDS[next(iter(BANDS))]
    count, cost, fleets = Counter(), Counter(), 0
    with tempfile.TemporaryDirectory() as d:
        for seed in a.seeds:
            unjoined = Path(d) / f"unjoined_{seed}.osm"
            unjoin_map(packaged_map(a.map), unjoined, seed=seed)
            tracks = simulate_real_fleet(truth, N_TRACKS, seed=seed, sigma=sigma)
            for form, mp in (("shipped", packaged_map(a.map)), ("unjoined", unjoined)):
                share, *_ = fleet_run(truth, tracks, mp, d)
                print(f"{a.map} seed {seed} {form}: per track {100 * share.mean():.2f} %",
                      flush=True)
                for kind, w in misses(truth, tracks, Path(d) / "out.csv", a.v):
                    count[kind] += 1
                    cost[kind] += w
                fleets += 1
    print(f"\n| kind | fixes | points of the per-track mean (average over {fleets} fleets) |")
    print("| --- | ---: | ---: |")
    for kind, w in sorted(cost.items(), key=lambda kv: -kv[1]):
        print(f"| {kind} | {count[kind]} | {100 * w / N_TRACKS / fleets:.3f} |")
    print(f"| all | {sum(count.values())} | {100 * sum(cost.values()) / N_TRACKS / fleets:.3f} |")


if __name__ == "__main__":
    main()
