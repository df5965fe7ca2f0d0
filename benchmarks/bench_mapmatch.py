"""Benchmark (run by hand): road graphs, the simulated car, and GNSS-only map matching.

Targets (issues 3 and 5): map matching over 10,000 fixes/s; ``selfnav match`` places >= 95 % of
the fixes of 5-second floating-car tracks within 5 m of their true route. Also the GNSS-only
row of the navigator comparison: 1 Hz GNSS, σ 10 m, with outlier windows of 200 m σ (white and
drifting, one at start-up), where GNSS-only matching is expected to fail (DESIGN §7).

Issue 14 (fleets): side by side with FMM's own C++ (``fastmm``, the ``bench`` extra: same
graph — our directed segments as its edges —, same fixes, same k = 16, radius and σ), the
accuracy of fleets at 5-30 s sampling and 3-10 / 10-30 m noise against raw GNSS and FMM, the
end-to-end throughput of ``selfnav match`` on a fleet file, peak memory for 40,000 fixes, and
Dask 1 -> 2 workers. Timings are labelled with the load average (a shared machine).

All tracks are simulated (a car driving the real OpenStreetMap extracts shipped in
``selfnav/data``, © OpenStreetMap contributors, ODbL).

    python benchmarks/bench_mapmatch.py                 # everything (~20 min on 2 cores)
    python benchmarks/bench_mapmatch.py fmm fleet e2e memory dask   # some sections
    python benchmarks/bench_mapmatch.py real calibrate heldout acceptance e2e_fmm memory   # 21
    (also: graphs, tracks, outliers; simulated fleets are cached in $SELFNAV_BENCH_CACHE,
    default /tmp/selfnav_bench)

Issue 21: fleets with the properties of a real floating-car fleet (``real``: short tracks,
unjoined ways, multipath; tuning, reporting and fresh seeds apart), the calibration of
``match_p`` on the tuning seed (``calibrate``), ``match_p`` and per-track accuracy on seeds
never drawn while building it (``heldout``), the issue-14 acceptance fleets as before
(``acceptance``), and ``selfnav match`` end to end side by side with FMM (``e2e_fmm``).
"""
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from selfnav.roads.hmm import HmmMatcher
from selfnav.roads.graph import packaged_map, project_to_polyline, read_roads
from selfnav.sim.car import car_route
from selfnav.sim.fleet import fleet_rows, simulate_fleet

MAPS = ("kotka_karhula", "helsinki_centre")


def floating_car(g, seed, sigma, duration, period):
    traj, route = car_route(g, duration=duration, dt=period, seed=seed)
    rng = np.random.default_rng(1000 + seed)
    return traj, route, route.xy + rng.normal(0.0, sigma, route.xy.shape)


def outlier_noise(t, rng, sigma=10.0, big=200.0, tau=60.0):
    """σ 10 m white noise, plus 200 m σ windows: white at start-up (0-120 s), drifting
    (Gauss-Markov, τ 60 s) 600-900 s, white 1300-1600 s; returns (noise, in_window)."""
    n = len(t)
    e = rng.normal(0.0, sigma, (n, 2))
    w1 = t < 120.0
    w2 = (t >= 600.0) & (t < 900.0)
    w3 = (t >= 1300.0) & (t < 1600.0)
    e[w1 | w3] += rng.normal(0.0, big, ((w1 | w3).sum(), 2))
    dt = np.diff(t, prepend=t[0])
    a = np.exp(-dt / tau)
    gm = np.zeros((n, 2))
    for k in range(1, n):
        gm[k] = a[k] * gm[k - 1] + np.sqrt(1 - a[k] ** 2) * big * rng.normal(size=2)
    e[w2] += gm[w2]
    return e, w1 | w2 | w3


def along_cross(est, true, heading):
    """Error split along and across the true direction of travel (heading from grid North)."""
    d = est - true
    u = np.column_stack([np.sin(heading), np.cos(heading)])
    along = d[:, 0] * u[:, 0] + d[:, 1] * u[:, 1]
    cross = u[:, 0] * d[:, 1] - u[:, 1] * d[:, 0]
    return along, cross


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def section_graphs(graphs):
    print("## Road graphs (strongly connected drivable core)\n")
    print("| map | nodes | directed segments | km (roads) | km (directed / 2) | read s |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for name in MAPS:
        t0 = time.perf_counter()
        g = read_roads(packaged_map(name))
        dt = time.perf_counter() - t0
        print(f"| {name} | {g.n_nodes} | {g.n_segments} | {g.length_m / 1e3:.2f} | "
              f"{g.seg_len.sum() / 2e3:.2f} | {dt:.2f} |")

    print("\n## Simulated car, 600 s at 100 Hz\n")
    print("| map | samples | sim s | driven km | max |a| m/s² | max lat. acc. m/s² | stops |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, g in graphs.items():
        t0 = time.perf_counter()
        traj, route = car_route(g, duration=600.0, dt=0.01, seed=1)
        dt = time.perf_counter() - t0
        print(f"| {name} | {len(traj)} | {dt:.2f} | {route.s[-1] / 1e3:.2f} | "
              f"{np.abs(route.accel).max():.2f} | {np.abs(route.lateral_accel).max():.2f} | "
              f"{len(route.stops)} |")


def section_tracks(graphs):
    print("\n## GNSS-only matching of 5-second floating-car tracks, σ 10 m\n")
    print("| map | track | fixes | within 5 m of route (raw fixes) | within 5 m (matched) | "
          "restarts | fixes/s |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
    for name, g in graphs.items():
        m = HmmMatcher(g, sigma=10.0)
        for seed in range(5):
            traj, route, noisy = floating_car(g, seed, 10.0, 1800.0, 5.0)
            res = m.match(traj.t, noisy)
            _, c, _ = project_to_polyline(res.xy, route.polyline)
            _, c_raw, _ = project_to_polyline(noisy, route.polyline)
            print(f"| {name} | 30 min, seed {seed} | {len(traj.t)} | "
                  f"{100 * np.mean(np.abs(c_raw) < 5):.1f} % | {100 * np.mean(np.abs(c) < 5):.1f} % "
                  f"| {res.restart.sum() - 1} | {len(traj.t) / res.seconds:,.0f} |")
        traj, route, noisy = floating_car(g, 99, 10.0, 50_000.0, 5.0)
        m.match(traj.t[:50], noisy[:50])                   # numba kernel compiled/cached
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            res = m.match(traj.t, noisy)
            best = min(best, time.perf_counter() - t0)
        _, c, _ = project_to_polyline(res.xy, route.polyline)
        print(f"| {name} | 69 h, throughput | {len(traj.t)} | | {100 * np.mean(np.abs(c) < 5):.1f} %"
              f" | {res.restart.sum() - 1} | **{len(traj.t) / best:,.0f}** |")


def section_outliers(graphs):
    print("\n## GNSS-only matching through 200 m σ outlier windows (1 Hz, 30 min)\n")
    print("Windows: 0-120 s white (start-up), 600-900 s drifting (Gauss-Markov τ 60 s), "
          "1300-1600 s white; σ 10 m elsewhere. Along/cross: error split on the true direction "
          "of travel. On the right road: within 5 m of the driven route and within 30 m of the "
          "car along it.\n")
    print("| map | solution | along RMS m | along max m | cross RMS m | cross max m | "
          "on the right road: all / in windows / outside | in windows: cross RMS m | "
          "outside: cross RMS m | "
          "longest off-road s |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, g in graphs.items():
        for seed in (1, 2):
            traj, route = car_route(g, duration=1800.0, dt=1.0, seed=seed)
            rng = np.random.default_rng(seed)
            e, win = outlier_noise(traj.t, rng)
            fixes = route.xy + e
            res = HmmMatcher(g, sigma=10.0).match(traj.t, fixes)
            psi = route.path.evaluate(route.s)[1]
            for label, est in (("raw GNSS", fixes), ("GNSS-only HMM", res.xy)):
                a, c = along_cross(est, route.xy, psi)
                # on the right road: within 5 m of the route, within 30 m of the car along it
                _, c_route, _ = project_to_polyline(est, route.centerline,
                                                    near_s=route.s, window=30.0)
                on = np.abs(c_route) < 5.0
                off_run = _longest_run(~on)
                print(f"| {name} s{seed} | {label} | {rms(a):.1f} | {np.abs(a).max():.0f} | "
                      f"{rms(c):.1f} | {np.abs(c).max():.0f} | {100 * on.mean():.1f} / "
                      f"{100 * on[win].mean():.1f} / {100 * on[~win].mean():.1f} % | "
                      f"{rms(c[win]):.1f} | {rms(c[~win]):.1f} | {off_run:.0f} |")


def _longest_run(mask):
    best = run = 0
    for v in mask:
        run = run + 1 if v else 0
        best = max(best, run)
    return best


# ------------------------------------------------------------------ issue 14: fleets, FMM
CACHE = Path(os.environ.get("SELFNAV_BENCH_CACHE", tempfile.gettempdir())) / "selfnav_bench"
SECTIONS = ("graphs", "tracks", "outliers", "fmm", "fleet", "e2e", "memory", "dask", "real",
            "calibrate", "heldout", "acceptance", "e2e_fmm")


def load():
    return os.getloadavg()[0]


def cached_fleet(g, name, n, seed, sigma):
    """A simulated fleet (:func:`selfnav.sim.fleet.simulate_fleet`), cached on disk."""
    CACHE.mkdir(parents=True, exist_ok=True)
    f = CACHE / f"fleet_{name}_{n}_{seed}_{sigma[0]:g}-{sigma[1]:g}.pkl"
    if f.exists():
        return pickle.loads(f.read_bytes())
    tracks = simulate_fleet(g, n, seed=seed, sigma=sigma)
    f.write_bytes(pickle.dumps(tracks))
    return tracks


def distinct(tr):
    """A track's fixes with repeated stamps averaged (what both matchers get)."""
    t, inv = np.unique(tr.t, return_inverse=True)
    xy = np.zeros((len(t), 2))
    np.add.at(xy, inv, tr.xy)
    return t, xy / np.bincount(inv)[:, None], inv


class Fmm:
    """FMM (``fastmm``) on our graph: each directed segment an edge, the same node ids."""

    def __init__(self, g):
        import fastmm

        self.fastmm = fastmm
        t0 = time.perf_counter()
        net = fastmm.Network()
        for i in range(g.n_segments):
            u, v = int(g.seg_u[i]), int(g.seg_v[i])
            net.add_edge(i, source=u, target=v, geom=[tuple(g.xy[u]), tuple(g.xy[v])],
                         speed=float(g.seg_speed[i]))
        net.finalize()
        self.net = net
        self.fmm = fastmm.FastMapMatch(net, fastmm.TransitionMode.SHORTEST,
                                       max_distance_between_candidates=3000.0,
                                       cache_dir=str(CACHE / "ubodt"))
        self.setup_s = time.perf_counter() - t0
        self.cpu = 0.0

    def match(self, t, xy, *, sigma, radius, reverse, k=16):
        """Matched positions (unmatched fixes keep their raw position) and a matched flag.
        ``self.cpu`` adds up the CPU time of FMM's ``match`` call alone (not the conversions
        to and from Python lists around it)."""
        traj = self.fastmm.Trajectory.from_xyt_tuples(
            [(float(a), float(b), float(c)) for (a, b), c in zip(xy, t)])
        c0 = time.process_time()
        r = self.fmm.match(traj, max_candidates=k, candidate_search_radius=radius,
                           gps_error=sigma, reverse_tolerance=reverse)
        self.cpu += time.process_time() - c0
        out = xy.copy()
        ok = np.zeros(len(t), bool)
        for st in r.subtrajectories:
            for seg in st.segments:
                for q in (seg.p0, seg.p1):
                    out[q.trajectory_index - 1] = (q.x, q.y)
                    ok[q.trajectory_index - 1] = True
        return out, ok


def _share(points, poly):
    _, c, _ = project_to_polyline(points, poly)
    return np.abs(c) < 5.0


def _best_cpu(fn, repeat=3, fmm=None):
    """Best CPU seconds of ``fn()`` over ``repeat`` runs (with ``fmm``: of FMM's match calls
    alone)."""
    best = np.inf
    out = None
    for _ in range(repeat):
        c0 = time.process_time()
        if fmm is not None:
            fmm.cpu = 0.0
        out = fn()
        best = min(best, fmm.cpu if fmm is not None else time.process_time() - c0)
    return out, best


def section_fmm(graphs):
    """The matcher alone against FMM, side by side: same graph, fixes, k, radius, σ."""
    print(f"\n## Matcher alone vs FMM (fastmm {__import__('fastmm').__version__}), side by side"
          f" (load average {load():.1f} on 2 cores)\n")
    print("Both get the same fixes in local metres and the same k = 16, radius (clip(4σ, 30, "
          "200) m), σ and backwards tolerance (max(15, 3σ) m); FMM's UBODT (delta 3 km) is "
          "precomputed beforehand (its set-up time is shown separately). Times: CPU seconds, "
          "best of 3 (the machine is shared); fixes/s = fixes / CPU s; selfnav from arrays in "
          "to matched positions out (latitude/longitude included), FMM its `match` call alone "
          "(not the conversion to and from Python lists). Fleet: matched as one batch by "
          "selfnav (`match_many`), track by track by FMM.\n")
    print("| map | data | fixes | selfnav fixes/s | FMM fixes/s | ratio | within 5 m: selfnav "
          "/ FMM / raw | FMM set-up s |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, g in graphs.items():
        fmm = Fmm(g)
        m = HmmMatcher(g, sigma=10.0)
        traj, route, noisy = floating_car(g, 99, 10.0, 50_000.0, 5.0)
        m.match(traj.t[:50], noisy[:50])
        res, c_s = _best_cpu(lambda: m.match(traj.t, noisy))
        (fx, _), c_f = _best_cpu(lambda: fmm.match(traj.t, noisy, sigma=10.0, radius=m.radius,
                                                   reverse=m.backtrack), fmm=fmm)
        n = len(traj.t)
        print(f"| {name} | one 5 s track, σ 10 m | {n} | {n / c_s:,.0f} | {n / c_f:,.0f} | "
              f"**{c_f / c_s:.2f}×** | {100 * _share(res.xy, route.polyline).mean():.1f} / "
              f"{100 * _share(fx, route.polyline).mean():.1f} / "
              f"{100 * _share(noisy, route.polyline).mean():.1f} % | {fmm.setup_s:.1f} |")
        for sig in ((3.0, 10.0), (10.0, 30.0)):
            tracks = cached_fleet(g, name, 200, 1, sig)
            items = [distinct(tr) for tr in tracks]
            n = sum(len(t) for t, _, _ in items)
            batch = [(t, xy, None) for t, xy, _ in items]
            out, c_s = _best_cpu(lambda: m.match_many(batch))
            fo, c_f = _best_cpu(lambda: [fmm.match(t, xy, sigma=10.0, radius=m.radius,
                                                   reverse=m.backtrack)[0]
                                         for t, xy, _ in items], fmm=fmm)
            w_s, w_f, w_r = [], [], []
            for tr, (t, xy, inv), r, f in zip(tracks, items, out, fo):
                w_s += list(_share(r.xy[inv], tr.polyline))
                w_f += list(_share(f[inv], tr.polyline))
                w_r += list(_share(tr.xy, tr.polyline))
            print(f"| {name} | fleet of 200, 5-30 s, σ {sig[0]:g}-{sig[1]:g} m (matched with "
                  f"σ 10) | {n} | {n / c_s:,.0f} | {n / c_f:,.0f} | **{c_f / c_s:.2f}×** | "
                  f"{100 * np.mean(w_s):.1f} / {100 * np.mean(w_f):.1f} / "
                  f"{100 * np.mean(w_r):.1f} % | |")


def section_fleet(graphs):
    """Accuracy of fleets at real-world sampling: selfnav's defaults (σ estimated per track)
    against FMM at σ 10 and 20 m and raw GNSS, by sampling and noise."""
    print(f"\n## Fleets: share of fixes within 5 m of the driven route (load {load():.1f})\n")
    print("200 simulated floating-car tracks per map and noise band (2-20 min each, irregular "
          "5-30 s sampling stamped to the second, repeated stamps, stationary starts); "
          "selfnav with its defaults (σ estimated per track); FMM with σ 10 m and 20 m "
          "(k 16, radius 4σ, reverse tolerance 3σ). Tuned on seed 1 (σ estimator, β), reported "
          "on seed 2.\n")
    print("| map | noise σ | sampling | fixes | raw GNSS | FMM σ 10 | FMM σ 20 | selfnav |")
    print("| --- | --- | --- | ---: | ---: | ---: | ---: | ---: |")
    from selfnav.roads.fleet import MatchParams, match_batch
    from selfnav.types import GnssData

    for name, g in graphs.items():
        fmm = Fmm(g)
        for sig in ((3.0, 10.0), (10.0, 30.0)):
            tracks = cached_fleet(g, name, 200, 2, sig)
            items = [distinct(tr) for tr in tracks]
            gd = []
            for tr, (t, xy, _) in zip(tracks, items):
                lat, lon = g.to_geodetic(xy[:, 0], xy[:, 1])
                gd.append((tr.track_id, GnssData(t, lat, lon, np.zeros(len(t)))))
            ours = match_batch(MatchParams().matcher(g), gd)
            f10 = [fmm.match(t, xy, sigma=10.0, radius=40.0, reverse=30.0)[0]
                   for t, xy, _ in items]
            f20 = [fmm.match(t, xy, sigma=20.0, radius=80.0, reverse=60.0)[0]
                   for t, xy, _ in items]
            for band in ((5, 15), (15, 30), (5, 30)):
                acc = {k: [] for k in ("raw", "f10", "f20", "ours")}
                for tr, (t, xy, inv), o, a, b in zip(tracks, items, ours, f10, f20):
                    if not band[0] <= tr.period < band[1] and band != (5, 30):
                        continue
                    acc["raw"] += list(_share(tr.xy, tr.polyline))
                    acc["f10"] += list(_share(a[inv], tr.polyline))
                    acc["f20"] += list(_share(b[inv], tr.polyline))
                    acc["ours"] += list(_share(o.result.xy[inv], tr.polyline))
                cells = " | ".join(f"{100 * np.mean(acc[k]):.1f} %" for k in
                                   ("raw", "f10", "f20"))
                label = "all (5-30 s)" if band == (5, 30) else f"{band[0]}-{band[1]} s"
                print(f"| {name} | {sig[0]:g}-{sig[1]:g} m | {label} | {len(acc['raw'])} | "
                      f"{cells} | **{100 * np.mean(acc['ours']):.1f} %** |")


def _fleet_file(g, name, tracks, path):
    ids, ts, lats, lons = fleet_rows(g, tracks, shuffle_prob=0.02)
    with open(path, "w") as fh:
        fh.write("track_id,t,lat_deg,lon_deg\n")
        fh.writelines(f"{a},{b},{c:.8f},{d:.8f}\n" for a, b, c, d in zip(ids, ts, lats, lons))
    return len(ids)


def _run_cli(args):
    """``selfnav match`` in a fresh process: (wall s, peak RSS MB of the process, summary)."""
    # VmHWM, not ru_maxrss: the latter keeps the parent's RSS across fork + exec
    code = ("import sys\n"
            "from selfnav.cli import main\n"
            "rc = main(sys.argv[1:])\n"
            "hwm = [ln for ln in open('/proc/self/status') if ln.startswith('VmHWM')][0]\n"
            "sys.stderr.write('MAXRSS %d\\n' % int(hwm.split()[1]))\n"
            "sys.exit(rc)")
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", code, "match", *args, "--json"],
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode:
        raise RuntimeError(p.stderr)
    rss = int(p.stderr.rsplit("MAXRSS", 1)[1].split()[0]) / 1024
    return wall, rss, json.loads(p.stdout)


def section_e2e(graphs):
    """``selfnav match`` on one fleet file, start-up to written output, in a fresh process."""
    print(f"\n## End to end: one `selfnav match` call on a fleet file (load {load():.1f})\n")
    print("Wall time of a fresh process (Python start-up, imports, reading the CSV, reading the "
          "map, matching, writing), best of 3.\n")
    print("| map | tracks | fixes | workers | wall s | fixes/s end to end | peak RSS MB |")
    print("| --- | ---: | ---: | --- | ---: | ---: | ---: |")
    for name, g in graphs.items():
        tracks = cached_fleet(g, name, 200, 1, (3.0, 10.0))
        more = cached_fleet(g, name, 200, 2, (3.0, 10.0))[:100]
        for tr in more:                            # ids of their own
            tr.track_id = "s2" + tr.track_id
        tracks = tracks + more
        with tempfile.TemporaryDirectory() as d:
            src = Path(d) / "fleet.csv"
            rows = _fleet_file(g, name, tracks, src)
            for workers in ("default", "2"):
                extra = [] if workers == "default" else ["--workers", workers]
                best = None
                for _ in range(3):
                    r = _run_cli(["--gnss", str(src), "--map", str(packaged_map(name)),
                                  "--out", str(Path(d) / "out.csv"), *extra])
                    best = r if best is None or r[0] < best[0] else best
                wall, rss, s = best
                print(f"| {name} | {s['tracks']} | {rows} | {workers} ({s['mode']}) | "
                      f"{wall:.2f} | **{rows / wall:,.0f}** | {rss:.0f} |")


def section_memory(graphs):
    """Peak memory of ``selfnav match`` on one long track, and the matcher's growth per fix."""
    print(f"\n## Memory (load {load():.1f})\n")
    print("Peak RSS (VmHWM) of a fresh `selfnav match` process on one track (imports alone: "
          "~170 MB); the matcher's own peak allocation (tracemalloc, numpy included) per fix.\n")
    print("| map | fixes | `selfnav match` peak RSS MB | matcher: peak allocation per fix |")
    print("| --- | ---: | ---: | ---: |")
    g = graphs["helsinki_centre"]
    for n in (10_000, 40_000):
        traj, route, noisy = floating_car(g, 99, 10.0, 5.0 * (n - 1), 5.0)
        with tempfile.TemporaryDirectory() as d:
            lat, lon = g.to_geodetic(noisy[:, 0], noisy[:, 1])
            src = Path(d) / "track.csv"
            with open(src, "w") as fh:
                fh.write("t,lat_deg,lon_deg\n")
                fh.writelines(f"{a:.1f},{b:.9f},{c:.9f}\n" for a, b, c in
                              zip(traj.t, np.degrees(lat), np.degrees(lon)))
            np.savez(Path(d) / "track.npz", t=traj.t, xy=noisy)
            _, rss, _ = _run_cli(["--gnss", str(src), "--map", str(packaged_map(g.name[:-8])),
                                  "--out", str(Path(d) / "out.csv")])
            code = ("import tracemalloc, numpy as np\n"
                    "from selfnav.roads.graph import packaged_map, read_roads\n"
                    "from selfnav.roads.hmm import HmmMatcher\n"
                    f"f = np.load({str(Path(d) / 'track.npz')!r})\n"
                    "m = HmmMatcher(read_roads(packaged_map('helsinki_centre')), sigma=10.0)\n"
                    "m.match(f['t'][:200], f['xy'][:200])\n"
                    "tracemalloc.start()\n"
                    "m.match(f['t'], f['xy'])\n"
                    "print(tracemalloc.get_traced_memory()[1])")
            grow = int(subprocess.run([sys.executable, "-c", code], capture_output=True,
                                      text=True, check=True).stdout) / n / 1e3
        print(f"| helsinki_centre | {n} | **{rss:.0f}** | {grow:.2f} kB |")


def section_dask(graphs):
    """Matching a larger fleet on 1 and 2 local Dask workers (cluster started beforehand)."""
    from dask.distributed import Client

    from selfnav.cluster import local_cluster
    from selfnav.roads.fleet import FleetRun, MatchParams, match_tracks
    from selfnav.types import GnssData

    print(f"\n## Dask: 1 -> 2 workers (load {load():.1f} before)\n")
    print("The Karhula and Helsinki fleets (σ 10-30 m) with fresh noise ×5 "
          "(2,000 tracks); map read once per worker; matching wall time on a running cluster "
          "after one warm-up run (start-up shown apart), best of 2.\n")
    print("| workers | tracks | fixes | cluster start s | matching wall s | fixes/s | speed-up | "
          "load |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    items = {}
    for name, g in graphs.items():
        rng = np.random.default_rng(7)
        lst = []
        for rep in range(5):
            for tr in cached_fleet(g, name, 200, 1, (10.0, 30.0)):
                t, first = np.unique(tr.t, return_index=True)
                xy = tr.true_xy[first] + rng.normal(0, tr.sigma, (len(t), 2))
                lat, lon = g.to_geodetic(xy[:, 0], xy[:, 1])
                lst.append((f"{tr.track_id}_{rep}", GnssData(t, lat, lon, np.zeros(len(t)))))
        items[name] = lst
    base = None
    for nw in (1, 2):
        t0 = time.perf_counter()
        with local_cluster(nw) as cl, Client(cl) as client:
            start = time.perf_counter() - t0
            best = np.inf
            n = 0
            for rep in range(3):                 # the first run reads the maps in each worker
                w0 = time.perf_counter()
                n = 0
                for name in graphs:
                    for r in match_tracks(items[name], str(packaged_map(name)), MatchParams(),
                                          client=client, run=FleetRun()):
                        n += len(r.result.t)
                if rep:
                    best = min(best, time.perf_counter() - w0)
        base = base or best
        print(f"| {nw} | {sum(len(v) for v in items.values())} | {n} | {start:.1f} | "
              f"{best:.2f} | {n / best:,.0f} | **{base / best:.2f}×** | {load():.1f} |")


# ------------------------------------------------------------------ issue 21: real-like fleets
#: seeds: tuning (the defaults of selfnav.roads.hmm were chosen on it and match_p calibrated on
#: it), reporting, and a fresh one drawn after the model was settled
TUNE_SEEDS = (1,)
REPORT_SEEDS = (2, 3)
FRESH_SEEDS = (4,)
#: bins of the reliability table of match_p
P_EDGES = (0.0, 0.5, 0.9, 0.95, 0.97, 0.98, 0.99, 0.995, 1.0001)
BANDS = {"σ 1-4 m": (1.0, 4.0), "σ 1.5-5 m (harsher)": (1.5, 5.0)}


def _write_rows(path, g, tracks, rng_seed=1):
    ids, ts, lats, lons = fleet_rows(g, tracks, rng=np.random.default_rng(rng_seed),
                                     shuffle_prob=0.02)
    with open(path, "w") as fh:
        fh.write("track_id,t,lat_deg,lon_deg\n")
        fh.writelines(f"{a},{b},{c:.8f},{d:.8f}\n" for a, b, c, d in zip(ids, ts, lats, lons))
    return len(ids)


def _read_matched(path):
    """Output rows of ``selfnav match`` by track: lat, lon (rad), matched, match_p, piece."""
    import csv

    by = {}
    for r in csv.DictReader(ln for ln in open(path) if not ln.startswith("#")):
        by.setdefault(r["track_id"], []).append(r)
    out = {}
    for tid, rows in by.items():
        out[tid] = (np.radians([float(r["lat_deg"]) for r in rows]),
                    np.radians([float(r["lon_deg"]) for r in rows]),
                    np.array([r["matched"] == "1" for r in rows]),
                    np.array([float(r["match_p"]) for r in rows]))
    return out


def fleet_run(truth, tracks, map_path, d):
    """One ``selfnav match`` call (the Python API behind it) on a fleet file of ``tracks``;
    returns per-track shares within 5 m, per-row ok / matched / match_p, and the summary."""
    import warnings

    from selfnav.roads.fleet import match_files

    src = Path(d) / "fleet.csv"
    out = Path(d) / "out.csv"
    _write_rows(src, truth, tracks)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = match_files([src], map_path, out)
    by = _read_matched(out)
    shares, oks, flags, ps = [], [], [], []
    for tr in tracks:
        lat, lon, flag, p = by[tr.track_id]
        x, y = truth.to_local(lat, lon)
        _, c, _ = project_to_polyline(np.column_stack([x, y]), tr.polyline)
        ok = np.abs(c) < 5.0
        shares.append(ok.mean())
        oks.append(ok)
        flags.append(flag)
        ps.append(p)
    return (np.asarray(shares), np.concatenate(oks), np.concatenate(flags), np.concatenate(ps),
            s)


def _fmm_shares(fmm, tracks, sigma=5.0):
    outs = []
    for tr in tracks:
        t, xy, inv = distinct(tr)
        o, _ = fmm.match(t, xy, sigma=sigma, radius=max(30.0, 4 * sigma),
                         reverse=max(15.0, 3 * sigma))
        outs.append(o[inv])
    from selfnav.sim.fleet import score_fleet

    return score_fleet(None, tracks, outs)[:2]


def section_real(graphs):
    """Issue 21: fleets with the properties of a real floating-car fleet (short tracks, 5-15 s,
    repeated stamps, stationary runs, multipath), on the maps as shipped and with unjoined
    ways; one ``selfnav match`` call per fleet file with a ``track_id`` column."""
    from selfnav.roads.graph import read_match_roads
    from selfnav.sim.fleet import simulate_real_fleet, unjoin_map

    print(f"\n## Real-like fleets (issue 21; load {load():.1f})\n")
    print("263 simulated tracks per fleet, 2-20 fixes each, 5-15 s irregular sampling stamped "
          "to the second (ISO-8601), 5 % repeated stamps, 30 % with a 20-90 s stationary run "
          "at the start or the end, 30 % driving to or from a part of the map outside its "
          "strongly connected core; GNSS σ per track uniform in the band, half white, half "
          "Gauss-Markov (τ 60 s), 2 % multipath outliers 30-150 m. Unjoined: half the ends of "
          "ways that end on another way moved 0.5-3 m off it (their own node). Truth: the OSM "
          f"centre line driven. Tuning seed {TUNE_SEEDS}, reported seeds {REPORT_SEEDS}, fresh "
          f"seed {FRESH_SEEDS}. FMM: "
          "σ 5 m, k 16, radius 30 m, on the same graph and fixes. Within 5 m: per-track mean "
          "/ fix-weighted; precision: of the fixes flagged matched, share within 5 m.\n")
    print("| map | map as | noise | seed | fixes | raw | FMM σ 5 (track / fix) | selfnav "
          "per track | selfnav fix-weighted | tracks < 90 % | matched | precision of matched "
          "| breaks | snapped |")
    print("| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | "
          "---: | ---: |")
    pooled = {"p": [], "ok": []}
    for name in graphs:
        truth = read_roads(packaged_map(name), strongly_connected=False)
        with tempfile.TemporaryDirectory() as d:
            for seed in TUNE_SEEDS + REPORT_SEEDS + FRESH_SEEDS:
                unj = Path(d) / f"unjoined_{seed}.osm"
                n_unj = unjoin_map(packaged_map(name), unj, seed=seed)
                for band, sig in BANDS.items():
                    tracks = simulate_real_fleet(truth, 263, seed=seed, sigma=sig)
                    raw = np.concatenate([_share(tr.xy, tr.polyline) for tr in tracks])
                    for label, mp in (("shipped", packaged_map(name)),
                                      (f"unjoined ({n_unj} ends)", unj)):
                        fmm = Fmm(read_match_roads(mp))
                        f_sh, f_ok = _fmm_shares(fmm, tracks)
                        sh, ok, flag, p, s = fleet_run(truth, tracks, mp, d)
                        if seed not in TUNE_SEEDS and band == next(iter(BANDS)):
                            pooled["p"].append(p)
                            pooled["ok"].append(ok)
                        tag = ("tune" if seed in TUNE_SEEDS else "report" if seed in
                               REPORT_SEEDS else "fresh")
                        print(f"| {name} | {label} | {band} | {seed} ({tag}) | {len(ok)} | "
                              f"{100 * raw.mean():.1f} % | {100 * f_sh.mean():.2f} / "
                              f"{100 * f_ok.mean():.2f} % | **{100 * sh.mean():.2f} %** | "
                              f"**{100 * ok.mean():.2f} %** | {int(np.sum(sh < 0.9))} | "
                              f"{100 * flag.mean():.1f} % | **{100 * ok[flag].mean():.2f} %** | "
                              f"{s['breaks']} | {s['map_snapped']} |", flush=True)
    p, ok = np.concatenate(pooled["p"]), np.concatenate(pooled["ok"])
    print(f"\n### Reliability of match_p (seeds {REPORT_SEEDS + FRESH_SEEDS}, σ 1-4 m, both "
          "maps, both map forms)\n")
    _reliability(p, ok)


def _reliability(p, ok, edges=P_EDGES):
    print("| match_p | fixes | mean match_p | within 5 m of the route |")
    print("| --- | ---: | ---: | ---: |")
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (p >= lo) & (p < hi)
        if sel.any():
            print(f"| {lo:.3f}-{min(hi, 1):.3f} | {sel.sum()} | {p[sel].mean():.3f} | "
                  f"{100 * ok[sel].mean():.1f} % |")
    print(f"\nAll: {len(p)} fixes, mean match_p {p.mean():.4f}, within 5 m {100 * ok.mean():.2f} %,"
          f" Brier score {np.mean((p - ok) ** 2):.4f}.")


def _raw_matches(truth, tracks, map_path, d):
    """One fleet call as :func:`fleet_run` with ``match_p`` left as the model's posterior;
    per fix of the matcher (repeated stamps merged): the regressors of the calibration
    (:func:`selfnav.roads.posterior.calibration_features`), "within 5 m of the route", and
    the number of fixes of each track (in order)."""
    import selfnav.roads.fleet as fleet_mod
    from selfnav.roads.posterior import calibration_features

    orig, orig_batch, seen = fleet_mod.MatchParams.matcher, fleet_mod.match_batch, []

    def raw(self, graph):                     # the posterior itself, not calibrated
        m = orig(self, graph)
        m.calibration = None
        return m

    def batch(*a, **k):
        r = orig_batch(*a, **k)
        seen.extend(r)
        return r

    fleet_mod.MatchParams.matcher, fleet_mod.match_batch = raw, batch
    fleet_mod._MATCHERS.clear()
    try:
        fleet_run(truth, tracks, map_path, d)
    finally:
        fleet_mod.MatchParams.matcher, fleet_mod.match_batch = orig, orig_batch
        fleet_mod._MATCHERS.clear()
    by = {tr.track_id: tr for tr in tracks}
    xs, oks, sizes = [], [], []
    for tm in seen:
        r = tm.result
        if r is None:
            continue
        x, y = truth.to_local(r.lat, r.lon)
        _, c, _ = project_to_polyline(np.column_stack([x, y]), by[tm.track_id].polyline)
        xs.append(calibration_features(r.match_p, r.moved / r.sigma, len(r.t)))
        oks.append(np.abs(c) < 5.0)
        sizes.append(len(r.t))
    return np.concatenate(xs), np.concatenate(oks), np.asarray(sizes)


def _real_fleets_raw(graphs, seeds, sigmas):
    """``(map name, seed, "shipped" | "unjoined", features, within 5 m, track sizes)`` of
    :func:`_raw_matches` for the real-like fleet of each map, seed and noise band, matched on
    the shipped map and on its unjoined form."""
    from selfnav.sim.fleet import simulate_real_fleet, unjoin_map

    for name in graphs:
        truth = read_roads(packaged_map(name), strongly_connected=False)
        with tempfile.TemporaryDirectory() as d:
            for seed in seeds:
                unj = Path(d) / f"unjoined_{seed}.osm"
                unjoin_map(packaged_map(name), unj, seed=seed)
                for sig in sigmas:
                    tracks = simulate_real_fleet(truth, 263, seed=seed, sigma=sig)
                    for form, mp in (("shipped", packaged_map(name)), ("unjoined", unj)):
                        yield (name, seed, form) + tuple(_raw_matches(truth, tracks, mp, d))


def section_calibrate(graphs):
    """Issue 21: the calibration of match_p, fitted on the tuning seed only: the fleets of
    ``real`` (both noise bands, both maps, both map forms) matched with the model's posterior
    (``calibration=None``); a logistic regression of "within 5 m of the route" on the
    posterior's log odds, the fix's distance from its road in σ, the track's end and its
    length (:func:`selfnav.roads.posterior.calibrate`); the flag's precision against its
    threshold."""
    print(f"\n## Calibration of match_p on the tuning seed {TUNE_SEEDS} (load {load():.1f})\n")
    xs, oks = [], []
    for _, _, _, x, ok, _ in _real_fleets_raw(graphs, TUNE_SEEDS, BANDS.values()):
        xs.append(x)
        oks.append(ok)
    F, ok = np.concatenate(xs), np.concatenate(oks).astype(float)
    X = np.column_stack([F, np.ones(len(F))])
    w = np.zeros(X.shape[1])
    for _ in range(100):                      # logistic regression, Newton steps
        q = 1.0 / (1.0 + np.exp(-X @ w))
        w += np.linalg.solve((X * (q * (1 - q))[:, None]).T @ X + 1e-9 * np.eye(len(w)),
                             X.T @ (ok - q))
    print("Fitted (selfnav.roads.hmm.MATCH_P_COEF: log odds, log(1 + moved/σ), end of track, "
          f"log(fixes), intercept): ({', '.join(f'{v:.3f}' for v in w)}). The model's "
          "posterior, before the calibration:\n")
    p = 1.0 / (1.0 + np.exp(-F[:, 0]))
    _reliability(p, ok, (0.0, 0.3, 0.5, 0.7, 0.8, 0.9, 0.95, 0.99, 1.0001))
    q = 1.0 / (1.0 + np.exp(-X @ w))
    print("\nAfter it (the tuning seed itself):\n")
    _reliability(q, ok)
    print("\nThe calibrated probability's precision (within 5 m, of the fixes at or above the "
          "threshold, the other conditions of `matched` aside) and the share above it:\n")
    print("| threshold | precision | share |")
    print("| ---: | ---: | ---: |")
    for thr in (0.95, 0.96, 0.97, 0.98, 0.99):
        sel = q >= thr
        print(f"| {thr:.2f} | {100 * ok[sel].mean():.2f} % | {100 * sel.mean():.1f} % |")


#: seeds never drawn while the matcher and its calibration were built (stop 56)
HELDOUT_SEEDS = ((5, 6), (7, 8, 9, 10))


def section_heldout(graphs):
    """Issue 21: ``match_p`` and per-track accuracy on fleets never drawn while building the
    matcher (``HELDOUT_SEEDS``; σ 1-4 m, both maps, both map forms), per fix of the matcher
    (repeated stamps merged): the calibrated ``match_p`` (the matcher's own
    :func:`selfnav.roads.posterior.calibrate` of its posterior) by range against the share
    within 5 m of the route, and the per-track mean within 5 m per fleet."""
    from selfnav.roads.hmm import MATCH_P_COEF
    from selfnav.roads.posterior import calibrate

    print(f"\n## Held-out fleets (seeds {HELDOUT_SEEDS}; load {load():.1f})\n")
    print("| seeds | match_p < 0.95: mean → right (fixes) | 0.95–0.99 | ≥ 0.99 | per track, "
          "by fleet (map, form, seed) |")
    print("| --- | --- | --- | --- | --- |")
    sig = BANDS["σ 1-4 m"]
    for group in HELDOUT_SEEDS:
        qs, oks, tracks_ok = [], [], []
        for name, seed, form, X, ok, sizes in _real_fleets_raw(graphs, group, (sig,)):
            p = 1.0 / (1.0 + np.exp(-X[:, 0]))          # the posterior again
            cuts = np.r_[0, np.cumsum(sizes)]
            q = np.concatenate([calibrate(p[a:b], np.expm1(X[a:b, 1]), b - a, MATCH_P_COEF)
                                for a, b in zip(cuts[:-1], cuts[1:])])
            qs.append(q)
            oks.append(ok)
            share = [ok[a:b].mean() for a, b in zip(cuts[:-1], cuts[1:])]
            tracks_ok.append(f"{name[:4]} {form[:4]} {seed}: {100 * np.mean(share):.2f}")
        q, ok = np.concatenate(qs), np.concatenate(oks)
        cells = []
        for lo, hi in ((0.0, 0.95), (0.95, 0.99), (0.99, 1.01)):
            sel = (q >= lo) & (q < hi)
            cells.append(f"{q[sel].mean():.3f} → {100 * ok[sel].mean():.1f} % ({sel.sum()})")
        print(f"| {', '.join(map(str, group))} | {' | '.join(cells)} | "
              f"{'; '.join(tracks_ok)} |", flush=True)


def section_acceptance(graphs):
    """The issue-14 acceptance fleets (seed 41, σ 3-10 m, 200 trips of 5-20 min) in one
    ``selfnav match`` call each, with FMM (σ 10 m) on the same fixes."""
    print(f"\n## Acceptance fleets of issue 14, as before (seed 41; load {load():.1f})\n")
    print("| map | trips | fixes | selfnav fix-weighted | selfnav per track | FMM σ 10 | raw |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
    for name, g in graphs.items():
        for dur, label in (((300.0, 1200.0), "200 × 5-20 min"), ((120.0, 420.0),
                                                                  "200 × 2-7 min")):
            tracks = simulate_fleet(g, 200, seed=41, sigma=(3.0, 10.0), duration=dur)
            with tempfile.TemporaryDirectory() as d:
                sh, ok, _, _, _ = fleet_run(g, tracks, packaged_map(name), d)
            fmm = Fmm(g)
            _, f_ok = _fmm_shares(fmm, tracks, sigma=10.0)
            raw = np.concatenate([_share(tr.xy, tr.polyline) for tr in tracks])
            print(f"| {name} | {label} | {len(ok)} | **{100 * ok.mean():.2f} %** | "
                  f"{100 * sh.mean():.2f} % | {100 * f_ok.mean():.2f} % | "
                  f"{100 * raw.mean():.1f} % |", flush=True)


_FMM_E2E = r"""
import csv, sys, time
import numpy as np
import fastmm
from selfnav.io.fleet import read_fleet
from selfnav.roads.graph import read_match_roads
fleet_path, map_path, out_path, cache = sys.argv[1:5]
fleet = read_fleet([fleet_path])
g = read_match_roads(map_path)
net = fastmm.Network()
for i in range(g.n_segments):
    u, v = int(g.seg_u[i]), int(g.seg_v[i])
    net.add_edge(i, source=u, target=v, geom=[tuple(g.xy[u]), tuple(g.xy[v])],
                 speed=float(g.seg_speed[i]))
net.finalize()
fmm = fastmm.FastMapMatch(net, fastmm.TransitionMode.SHORTEST,
                          max_distance_between_candidates=3000.0, cache_dir=cache)
with open(out_path, "w") as fh:
    fh.write("track_id,t,lat_deg,lon_deg\n")
    for tr in fleet.tracks:
        if tr.error:
            continue
        x, y = g.to_local(tr.gnss.lat, tr.gnss.lon)
        traj = fastmm.Trajectory.from_xyt_tuples([(float(a), float(b), float(c)) for a, b, c in
                                                 zip(x, y, tr.gnss.t)])
        r = fmm.match(traj, max_candidates=16, candidate_search_radius=40.0, gps_error=10.0,
                      reverse_tolerance=30.0)
        mx, my = x.copy(), y.copy()
        for st in r.subtrajectories:
            for seg in st.segments:
                for q in (seg.p0, seg.p1):
                    mx[q.trajectory_index - 1], my[q.trajectory_index - 1] = q.x, q.y
        lat, lon = g.to_geodetic(mx, my)
        f = tr.row_fix
        for tt, a, b in zip(tr.t_text, np.degrees(lat[f]), np.degrees(lon[f])):
            fh.write(f"{tr.track_id},{tt},{a:.9f},{b:.9f}\n")
"""


def section_e2e_fmm(graphs):
    """End to end, side by side in one run: ``selfnav match`` on a fleet file against the same
    job done with FMM (fastmm) -- a fresh process each: imports, reading the fleet file (the
    same reader), the same graph (read_match_roads), FMM's network and its UBODT (precomputed
    once beforehand, loaded from its cache), matching track by track, writing the output."""
    print(f"\n## End to end, side by side with FMM (load {load():.1f})\n")
    print("Wall seconds of a fresh process, alternating selfnav / FMM, best of 3; the fleet "
          "file of the e2e section (300 trips, σ 3-10 m). FMM: σ 10 m, radius 40 m, k 16.\n")
    print("| map | fixes | selfnav wall s | FMM wall s | ratio | load |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    from selfnav.roads.graph import read_match_roads

    for name, g in graphs.items():
        tracks = cached_fleet(g, name, 200, 1, (3.0, 10.0))
        more = cached_fleet(g, name, 200, 2, (3.0, 10.0))[:100]
        for tr in more:
            tr.track_id = "s2" + tr.track_id
        tracks = tracks + more
        Fmm(read_match_roads(packaged_map(name)))          # UBODT into its cache once
        with tempfile.TemporaryDirectory() as d:
            src = Path(d) / "fleet.csv"
            rows = _fleet_file(g, name, tracks, src)
            script = Path(d) / "fmm_e2e.py"
            script.write_text(_FMM_E2E)
            best_s = best_f = np.inf
            for _ in range(3):
                w, _, _ = _run_cli(["--gnss", str(src), "--map", str(packaged_map(name)),
                                    "--out", str(Path(d) / "out.csv")])
                best_s = min(best_s, w)
                t0 = time.perf_counter()
                subprocess.run([sys.executable, str(script), str(src), str(packaged_map(name)),
                                str(Path(d) / "fmm.csv"), str(CACHE / "ubodt")], check=True,
                               capture_output=True)
                best_f = min(best_f, time.perf_counter() - t0)
            print(f"| {name} | {rows} | {best_s:.2f} | {best_f:.2f} | **{best_f / best_s:.2f}×** "
                  f"| {load():.1f} |", flush=True)


def main(argv):
    which = argv or list(SECTIONS)
    graphs = {name: read_roads(packaged_map(name)) for name in MAPS}
    print(f"selfnav map-matching benchmark — {time.strftime('%Y-%m-%d %H:%M')}, load average "
          f"{load():.1f} (2 cores)")
    for name in which:
        globals()[f"section_{name}"](graphs)


if __name__ == "__main__":
    main(sys.argv[1:])
