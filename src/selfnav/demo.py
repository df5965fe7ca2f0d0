"""``selfnav demo``: the main jobs on data that ship with the package, with a small report.

Real data: PSINS ``lasergyro.imu`` (ring-laser-gyro IMU at rest on a vehicle with some
disturbance, Xi'an, site 34.246048° N; BSD 2-clause, © Gongmin Yan, PSINS toolbox).
"""
from __future__ import annotations

import json
import warnings
from importlib import resources
from pathlib import Path

import numpy as np

from selfnav.errors import SelfnavWarning
from selfnav.io.jsonio import jsonable
from selfnav.io.output import atomic_write_bytes, figure_png

SITE_LAT_DEG = 34.246048
#: one colour per filter in the demo's plots
COLOURS = ("tab:blue", "tab:red", "tab:green")


def packaged(name: str) -> Path:
    """Path of a data file shipped inside the package."""
    return Path(str(resources.files("selfnav") / "data" / name))


def window_estimates(imu, window_s: float = 300.0):
    """Latitude in consecutive windows, plain (still) and tilt-compensated (disturbed)."""
    from selfnav.latitude import estimate_latitude

    n = int(round(window_s / imu.dt))
    out = []
    for k in range(0, len(imu) - n + 1, n):
        part = imu.select(slice(k, k + n))
        a = estimate_latitude(part, rest="still")
        b = estimate_latitude(part, rest="disturbed")
        out.append((part.t[0] + window_s / 2, np.degrees(a.latitude), np.degrees(b.latitude),
                    np.degrees(b.sigma)))
    return np.array(out)


def navigation_demo(duration: float = 420.0, seeds=(1, 2, 3), progress=None) -> dict:
    """*Simulated* drives on the shipped Karhula map (ODbL) in seed 004's case — a consumer MEMS
    IMU and 3 minutes of unflagged 200 m σ white outliers: ``selfnav navigate`` (the fault
    bank), the same filter with a plain χ² gate on each fix (what most fusion stacks do), and
    ``selfnav navigate --map``.

    Returns the RMS and max over all drives, and the first drive's tracks for the plot.
    """
    from selfnav import api
    from selfnav.evaluation import evaluate
    from selfnav.roads.graph import read_roads
    from selfnav.sim.scenarios import simulate

    spec = {"scenario": {"kind": "car", "duration": duration, "map": "kotka_karhula", "dt": 0.01},
            "imu": {"grade": "consumer"},
            "gnss": {"sigma_m": 5.0, "rate_hz": 1.0, "spike_rate": 0.0,
                     "outliers": [{"start": 150.0, "duration": 180.0, "sigma_m": 200.0,
                                   "kind": "white"}]}}
    names = (("selfnav navigate (fault bank)", True, False), ("EKF, χ² gate only", False, False),
             ("selfnav navigate --map", True, True))
    sq = {n: [] for n, _, _ in names}
    mx = {n: 0.0 for n, _, _ in names}
    first = None
    first_m, first_err = {}, {}
    for k_seed, seed in enumerate(seeds):
        sim = simulate(spec, seed=seed)
        graph = read_roads(sim.map_path)
        gd = sim.gnss.as_gnss(source="simulated")
        tracks = {}
        for k_name, (name, bank, road) in enumerate(names):
            if progress is not None:
                progress((k_seed * len(names) + k_name) / (len(seeds) * len(names)))
            sol = api.navigate(sim.imu, gd, graph if road else None,
                               **({} if bank else {"bank": False}))
            ev = evaluate(sim.truth, sol.trajectory)
            m = ev.metrics
            sq[name].append(m["horizontal_rms_m"] ** 2)
            mx[name] = max(mx[name], m["horizontal_max_m"])
            tracks[name] = graph.to_local(sol.trajectory.lat, sol.trajectory.lon)
            if first is None:
                first_m[name] = m
                first_err[name] = (ev.t, ev.horizontal)
        if first is None:
            first = (graph, tracks, graph.to_local(sim.truth.lat, sim.truth.lon),
                     graph.to_local(gd.lat, gd.lon))
    graph, tracks, truth_xy, gnss_xy = first
    runs = {n: {"horizontal_rms_m": float(np.sqrt(np.mean(sq[n]))), "horizontal_max_m": mx[n],
                "first_drive_rms_m": float(first_m[n]["horizontal_rms_m"]),
                "first_drive_max_m": float(first_m[n]["horizontal_max_m"]),
                "xy": tracks[n], "error_t": first_err[n][0], "error_m": first_err[n][1]}
            for n, _, _ in names}
    win = spec["gnss"]["outliers"][0]
    return {"runs": runs, "truth_xy": truth_xy, "gnss_xy": gnss_xy, "graph": graph,
            "origin_deg": (float(np.degrees(graph.lat0)), float(np.degrees(graph.lon0))),
            "window_s": (win["start"], win["start"] + win["duration"]),
            "note": f"{len(seeds)} simulated 7-min drives (consumer MEMS, 1 Hz GNSS σ 5 m, 3 min "
                    "of unflagged 200 m σ outliers) on the real Karhula OpenStreetMap extract "
                    "(ODbL); RMS and max over the drives, the plots show the first"}


#: The files of the demo report (an older report's files are replaced as a set).
DEMO_FILES = ("latitude.json", "latitude_windows.png", "navigation.png", "navigation_errors.png",
              "index.html")


def latitude_rows(summary: dict) -> list:
    """The latitude table of the demo, one place for the terminal and the HTML page:
    ``(label, latitude_deg, sigma_deg, error_deg)`` per estimate (σ is 1σ)."""
    out = []
    for key, label in (("optimal", "selfnav (optimal, tilt-compensated)"),
                       ("plain_single_window", "plain single window (angle of mean vectors)"),
                       ("seed_formula", "seed formula (1.4)")):
        r = summary[key]
        out.append((label, r["latitude_deg"], r["sigma_deg"],
                    r["latitude_deg"] - summary["site_latitude_deg"]))
    return out


def run_demo(out_dir: Path, progress=None) -> dict:
    """Run the latitude method on the shipped static record and the simulated drives; write
    JSON, plots and ``index.html`` into ``out_dir`` as one set (an interrupt leaves the old
    report or the new one). ``progress(fraction, description)`` is told of each step."""
    from selfnav.io.output import atomic_folder, check_output_folder

    check_output_folder(out_dir)
    with warnings.catch_warnings():  # the demo reports its own notes
        warnings.simplefilter("ignore", SelfnavWarning)
        with atomic_folder(out_dir, owned=DEMO_FILES) as tmp:
            return _write_demo(Path(tmp), progress or (lambda fraction, description=None: None))


def _write_demo(out_dir: Path, progress) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from selfnav.io.readers import read_imu
    from selfnav.latitude import estimate_latitude

    progress(0.0, "latitude of the shipped RLG record")
    imu = read_imu(packaged("lasergyro.imu.gz"), "psins")
    res = {m: estimate_latitude(imu, rest=m).to_dict() for m in ("auto", "still")}
    res["seed"] = estimate_latitude(imu, method="seed").to_dict()
    win = window_estimates(imu)
    summary = {
        "data": "PSINS lasergyro.imu (real RLG IMU at rest, Xi'an), shipped with selfnav",
        "site_latitude_deg": SITE_LAT_DEG,
        "optimal": res["auto"], "plain_single_window": res["still"], "seed_formula": res["seed"],
        "error_deg": res["auto"]["latitude_deg"] - SITE_LAT_DEG,
    }
    atomic_write_bytes(out_dir / "latitude.json", json.dumps(jsonable(summary), indent=2).encode())
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(win[:, 0] / 60, win[:, 1], "o-", label="plain mean (still)")
    ax.errorbar(win[:, 0] / 60, win[:, 2], win[:, 3], fmt="s-", capsize=3,
                label="tilt-compensated (disturbed rest), error bars ±1σ")
    ax.axhline(SITE_LAT_DEG, color="k", lw=1, label="site 34.246048° N")
    ax.set_xlabel("window centre, min")
    ax.set_ylabel("latitude, deg")
    ax.set_title("Latitude from a resting RLG IMU, 5-min windows (real data)")
    ax.legend()
    fig.tight_layout()
    atomic_write_bytes(out_dir / "latitude_windows.png", figure_png(fig, 110))
    plt.close(fig)
    progress(0.1, "simulated drives through outliers (3 drives × 3 filters)")
    nav = navigation_demo(progress=lambda x: progress(0.1 + 0.85 * x))
    progress(0.95, "plots and the report")
    fig, ax = plt.subplots(figsize=(7, 7))
    gr = nav["graph"]
    for u, v in zip(gr.seg_u, gr.seg_v):
        ax.plot(gr.xy[[u, v], 0], gr.xy[[u, v], 1], color="0.85", lw=1)
    ax.plot(*nav["gnss_xy"], ".", color="tab:orange", ms=3, label="GNSS fixes (simulated)")
    ax.plot(*nav["truth_xy"], "k-", lw=2, label="truth")
    for (name, r), c in zip(nav["runs"].items(), COLOURS):
        ax.plot(*r["xy"], color=c, lw=1.2, label=f"{name} (this drive: RMS "
                                                 f"{r['first_drive_rms_m']:.1f} m)")
    tx, ty = nav["truth_xy"]
    from selfnav.report import mark_ends

    mark_ends(ax, tx, ty)
    ax.plot(0.0, 0.0, "k+", ms=12, mew=1.5, label="origin {:.5f}°, {:.5f}° (map centre)".format(
        *nav["origin_deg"]))
    ax.set_xlim(tx.min() - 150, tx.max() + 150)
    ax.set_ylim(ty.min() - 150, ty.max() + 150)
    ax.set_aspect("equal")
    ax.set_xlabel("East of the origin, m")
    ax.set_ylabel("North of the origin, m")
    ax.set_title("Simulated drive through 3 min of unflagged 200 m outliers (first drive)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    atomic_write_bytes(out_dir / "navigation.png", figure_png(fig, 100))
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(8, 4))
    a, b = nav["window_s"]
    ax.axvspan(a, b, color="tab:orange", alpha=0.15, label="GNSS outlier window (unflagged)")
    for (name, r), c in zip(nav["runs"].items(), COLOURS):
        ax.plot(r["error_t"], r["error_m"], color=c, lw=1, label=name)
    ax.set_yscale("log")
    ax.set_xlabel("time, s")
    ax.set_ylabel("horizontal error, m")
    ax.set_title("Error against time (first drive; the truth is known: simulated)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    atomic_write_bytes(out_dir / "navigation_errors.png", figure_png(fig, 100))
    plt.close(fig)
    summary["navigation_simulated"] = {
        "note": nav["note"],
        **{k: {m: r[m] for m in ("horizontal_rms_m", "horizontal_max_m", "first_drive_rms_m",
                                 "first_drive_max_m")} for k, r in nav["runs"].items()}}
    atomic_write_bytes(out_dir / "latitude.json", json.dumps(jsonable(summary), indent=2).encode())
    lat_rows = "\n".join(f"<tr><td>{lab}</td><td>{v:.4f}</td><td>{sd:.4f}</td><td>{e:+.4f}</td></tr>"
                         for lab, v, sd, e in latitude_rows(summary))
    nav_rows = "".join(f"<tr><td>{k}</td><td>{r['horizontal_rms_m']:.1f}</td><td>{r['horizontal_max_m']:.1f}</td></tr>"
                       for k, r in nav["runs"].items())
    a = res["auto"]
    html = f"""<!doctype html><html><head><meta charset="utf-8"><title>selfnav demo</title></head>
<body style="font-family:sans-serif;max-width:50em">
<h1>selfnav demo — latitude from an IMU at rest</h1>
<p>Real data: PSINS <code>lasergyro.imu</code>, ring-laser-gyro IMU static on a vehicle with some
disturbance, Xi'an (site {SITE_LAT_DEG}° N), 30.8 min at 100 Hz.</p>
<table border=1 cellpadding=4>
<tr><th>estimate</th><th>latitude, deg</th><th>1σ, deg</th><th>error, deg</th></tr>
{lat_rows}
</table>
<p>Heading {a['heading_deg']:.3f}°, pitch {a['pitch_deg']:.4f}°, roll {a['roll_deg']:.4f}°.</p>
<img src="latitude_windows.png" alt="window estimates">
<p>Notes: {'; '.join(a['warnings'])}</p>
<h2>Navigation through unflagged GNSS outliers (simulated)</h2>
<p>{nav['note']}.</p>
<table border=1 cellpadding=4><tr><th>filter</th><th>horizontal RMS over the drives, m</th><th>max over the drives, m</th></tr>{nav_rows}</table>
<img src="navigation.png" alt="tracks">
<img src="navigation_errors.png" alt="error against time">
</body></html>"""
    atomic_write_bytes(out_dir / "index.html", html.encode())
    return summary
