"""Monte Carlo campaigns that run a whole pipeline through the API (issue 15).

:mod:`selfnav.montecarlo` holds the machinery and the pairs that need only the algorithms;
the pairs here drive what the command line drives (:func:`selfnav.api.navigate` with its
defaults), so they sit above the API. Importing this module registers them.

``roadnav``: the road navigator on simulated drives (labelled so)
    A random route on one of the two shipped OpenStreetMap extracts, a consumer MEMS IMU at
    100 Hz (the car scenario's rate) with a car magnetometer, 1 Hz GNSS at σ 10 m (positions
    only, as ``gnss.csv`` has them) with ``windows`` unflagged 200 m outlier windows of
    ``window_min_s``–``window_max_s`` (kind drawn from ``kinds``: white, first-order
    Gauss–Markov, a smooth second-order drift), the first at start-up with probability
    ``startup_prob``; optionally a wheel-speed sensor (``odometer=1``, scale factor σ
    ``odo_sf_sigma``, quantum ``odo_quantum_mps``). The navigator is
    ``selfnav navigate --map`` with its defaults (``method`` ekf or seed); the errors are
    ``selfnav evaluate --map``'s road-relative along/cross-track RMS over the solution's
    epochs, and the longest time off the driven route (:func:`longest_off_route`).

Every run is one seed: :func:`roadnav_scenario` gives its scenario (a TOML-able dict) and the
simulator seed, so the worst drives can be replayed through the command line
(``benchmarks/roadnav_montecarlo.py --replay SEED``).
"""
from __future__ import annotations

import time
import warnings

import numpy as np

from selfnav import api, sensors
from selfnav.errors import SelfnavError
from selfnav.evaluation import evaluate
from selfnav.montecarlo import register_pair
from selfnav.roads.graph import project_to_polyline, read_roads, road_polylines
from selfnav.sim.scenarios import simulate

MAPS = ("kotka_karhula", "helsinki_centre")

ROADNAV_DEFAULTS = {
    "map": "both",               # kotka_karhula, helsinki_centre, or both (drawn per run)
    "duration_s": 600.0,
    "dt_s": 0.01,
    "grade": "consumer",
    "gnss_sigma_m": 10.0,
    "windows": 2,
    "window_min_s": 30.0,
    "window_max_s": 300.0,
    "window_sigma_m": 200.0,
    "kinds": "white,gm,drift,drag",
    "startup_prob": 0.5,
    "odometer": 0,               # 1: simulate wheel speed and give it to the navigator
    "yaw_bias_split_deg": -1.0,  # the yaw-bias hypotheses this wide, °/s; 0: off; < 0: default
    "odo_sf_sigma": 0.005,
    "odo_quantum_mps": 0.01,
    "method": "ekf",
    "off_route_m": 5.0,
    "map_aid": 1,                # 0: without the map (the plain INS/GNSS navigator); -1: by seed
}

#: per-run columns summarised as distributions (median, 95th percentile, worst)
DISTRIBUTED = ("along_rms_m", "cross_rms_m", "off_route_s", "horizontal_rms_m", "err_sigma_p95",
               "beyond_5sigma")

_CACHE: dict = {}


def _cached(key, make):
    if key not in _CACHE:
        _CACHE[key] = make()
    return _CACHE[key]


def roadnav_scenario(seed: int, params: dict):
    """The scenario of run ``seed``: ``(spec dict for simulate, simulator seed, windows)``."""
    rng = np.random.default_rng(seed)
    m = params["map"]
    name = str(MAPS[int(rng.integers(2))]) if m == "both" else m
    T = float(params["duration_s"])
    kinds = tuple(k.strip() for k in str(params["kinds"]).split(",") if k.strip())
    startup = bool(rng.uniform() < float(params["startup_prob"]))
    wins = sensors.random_outlier_windows(
        0.0, T, int(params["windows"]), rng, max_duration=float(params["window_max_s"]),
        min_duration=float(params["window_min_s"]), sigma=float(params["window_sigma_m"]),
        kinds=kinds, startup=startup)
    grade = str(params["grade"])
    if grade == "mixed":
        grade = ("consumer", "industrial")[int(rng.integers(2))]
    spec = {"scenario": {"kind": "car", "duration": T, "map": name, "dt": float(params["dt_s"]),
                         "name": f"roadnav-{seed}"},
            "imu": {"grade": grade}, "mag": {"enabled": True},
            "gnss": {"sigma_m": float(params["gnss_sigma_m"]), "rate_hz": 1.0, "spike_rate": 0.0,
                     "outliers": [{"start": w.start, "duration": w.duration, "sigma_m": w.sigma,
                                   "kind": w.kind} for w in wins if w.kind != "outage"],
                     "outages": [(w.start, w.start + w.duration) for w in wins
                                 if w.kind == "outage"]}}
    if int(params["odometer"]):
        spec["odometer"] = {"enabled": True, "scale_factor_sigma": float(params["odo_sf_sigma"]),
                            "quantum_mps": float(params["odo_quantum_mps"])}
    return spec, int(rng.integers(2**62)), wins


def longest_off_route(sim, lat, lon, t, limit_m=5.0):
    """Longest run (s) of solution epochs farther than ``limit_m`` from the centre line
    actually driven (looked for within 60 m of the true position along it), and the share of
    epochs within it."""
    graph = sim.route.graph
    x, y = graph.to_local(lat, lon)
    t_route = np.arange(len(sim.route.s)) * float(sim.config["scenario"]["dt"])
    s_true = np.interp(t, t_route, sim.route.s)
    _, cross, _ = project_to_polyline(np.column_stack([x, y]), sim.route.centerline,
                                      near_s=s_true, window=60.0)
    off = np.abs(cross) > limit_m
    worst = run = 0
    for o in off:
        run = run + 1 if o else 0
        worst = max(worst, run)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    return worst * dt, float(1.0 - off.mean())


#: a drive's solution is "off" where its horizontal error passes this (the issue-19 replays'
#: "clean fix refused while the error is > 30 m")
REFUSED_OFF_M = 30.0
#: a lock-out: solution rows this far off (m) while the fixes have been clean for
#: ``CLEAN_AFTER_S`` (s) — the fixes were there to put it right
LOCKED_OFF_M, CLEAN_AFTER_S = 20.0, 10.0


def fix_outcomes(sim, sol, ev, wins) -> dict:
    """What the navigator did with the clean fixes of a drive (issue 19's account of its
    failures), from the simulator's truth about each fix and the solution's fix log:

    ``clean_refused_s``
        seconds of clean fixes (no outlier window) refused or held as suspect, from the start
        on;
    ``clean_refused_off_s``
        of those, the ones refused while the solution was more than ``REFUSED_OFF_M`` off —
        the issue's "clean fix refused while the error is > 30 m";
    ``locked_s``
        seconds of solution rows more than ``LOCKED_OFF_M`` off while the fixes had been
        clean for ``CLEAN_AFTER_S`` (a lock-out: the fixes could have put it right);
    ``window_off_s``
        seconds of rows more than ``LOCKED_OFF_M`` off inside an outlier window;
    ``start_in_window``
        the first row lies inside an outlier window (a start made on the fault)."""
    g = sim.gnss
    tg = np.asarray(g.t, float)
    bad = np.asarray(g.outlier, bool)
    dt_fix = float(np.median(np.diff(tg))) if len(tg) > 1 else 1.0
    t_row = np.asarray(ev.t, float)
    err = np.asarray(ev.horizontal, float)
    dt_row = float(np.median(np.diff(t_row))) if len(t_row) > 1 else 1.0
    log = getattr(sol.detail, "fix_log", None) if sol.detail is not None else None
    refused = refused_off = 0
    if log is not None and len(log.get("t", ())):
        tl = np.asarray(log["t"], float)
        st = np.array([str(getattr(x, "value", x)) for x in log["status"]])
        k = np.clip(np.searchsorted(tg, tl), 0, len(tg) - 1)
        clean = ~bad[k] & (np.abs(tg[k] - tl) < 0.5 * dt_fix)
        no = clean & np.isin(st, ("rejected", "suspect")) & (tl >= t_row[0])
        e_fix = np.interp(tl, t_row, err)
        refused = int(np.count_nonzero(no))
        refused_off = int(np.count_nonzero(no & (e_fix > REFUSED_OFF_M)))
    inside = np.zeros(len(t_row), bool)
    since_bad = np.full(len(t_row), np.inf)
    for w in wins:
        inside |= (t_row >= w.start) & (t_row <= w.end)
        after = t_row > w.end
        since_bad[after] = np.minimum(since_bad[after], t_row[after] - w.end)
    clean_rows = ~inside & (since_bad >= CLEAN_AFTER_S)
    return {"clean_refused_s": refused * dt_fix, "clean_refused_off_s": refused_off * dt_fix,
            "locked_s": float(np.count_nonzero(clean_rows & (err > LOCKED_OFF_M))) * dt_row,
            "window_off_s": float(np.count_nonzero(inside & (err > LOCKED_OFF_M))) * dt_row,
            "start_in_window": bool(len(t_row) and inside[0])}


def _navigator_options(params: dict) -> dict:
    """Navigator options of a campaign's parameters: ``yaw_bias_split_deg`` ≥ 0 sets the
    yaw-bias hypotheses' width (:mod:`selfnav.ins.headings`; 0: none), < 0 keeps the
    navigator's default."""
    split = float(params.get("yaw_bias_split_deg", -1.0))
    if split < 0.0:
        return {}
    import dataclasses

    from selfnav.ins.config import navigator_config

    cfg = navigator_config()
    init = dataclasses.replace(cfg.init, yaw_bias_split_sigma=(float(np.radians(split))
                                                               if split > 0.0 else None))
    return {"config": dataclasses.replace(cfg, init=init)}


def run_roadnav(seed: int, params: dict) -> dict:
    """One simulated drive through ``navigate --map`` and ``evaluate --map`` (module
    docstring); returns the run's row."""
    spec, sim_seed, wins = roadnav_scenario(seed, params)
    c0, w0 = time.process_time(), time.perf_counter()
    sim = simulate(spec, seed=sim_seed)
    graph = _cached(("graph", str(sim.map_path)), lambda: read_roads(sim.map_path))
    roads = _cached(("roads", str(sim.map_path)),
                    lambda: [np.asarray(r, float) for r in road_polylines(sim.map_path)])
    c1 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        use_map = int(params["map_aid"]) if int(params["map_aid"]) >= 0 else seed % 2
        try:
            sol = api.navigate(sim.imu, sim.gnss.as_gnss(), graph if use_map else None,
                               method=str(params["method"]), odometer=sim.odometer,
                               **_navigator_options(params))
        except SelfnavError:                # no start in the whole drive: a row that says so
            sol = None
    if sol is None:
        nan = float("nan")
        row = {k: nan for k in ROW_KEYS}
        row.update({"map": spec["scenario"]["map"], "sim_seed": sim_seed,
                    "windows": "; ".join(f"{w.start:.0f}+{w.duration:.0f} s {w.kind}" for w in wins),
                    "startup_window": bool(wins and wins[0].start == 0.0),
                    "kinds": "+".join(w.kind for w in wins), "grade": spec["imu"]["grade"],
                    "map_aid": use_map, "off_route_s": float(spec["scenario"]["duration"]),
                    "on_route": 0.0, "cpu_s": time.process_time() - c0,
                    "wall_s": time.perf_counter() - w0})
        return row
    c2 = time.process_time()
    ev = evaluate(sim.truth, sol.trajectory, roads=roads)
    m = ev.metrics
    off, on = longest_off_route(sim, ev.sol_lat, ev.sol_lon, ev.t, float(params["off_route_m"]))
    sig = sol.columns.get("sigma_h_m") if sol.columns else None
    k = np.isin(sol.trajectory.t, ev.t) if sig is not None else None
    row = {
        "map": spec["scenario"]["map"], "sim_seed": sim_seed,
        "windows": "; ".join(f"{w.start:.0f}+{w.duration:.0f} s {w.kind}" for w in wins),
        "startup_window": bool(wins and wins[0].start == 0.0),
        "kinds": "+".join(w.kind for w in wins),
        "along_rms_m": m["road_along_track_rms_m"], "cross_rms_m": m["road_cross_track_rms_m"],
        "along_max_m": m["road_along_track_max_m"], "cross_max_m": m["road_cross_track_max_m"],
        "along_heading_rms_m": m["along_track_rms_m"],
        "cross_heading_rms_m": m["cross_track_rms_m"],
        "horizontal_rms_m": m["horizontal_rms_m"], "horizontal_p95_m": m["horizontal_p95_m"],
        "off_route_s": off, "on_route": on, "start_s": float(ev.t[0]),
        "error": m["horizontal_rms_m"],
        "sigma": (float(np.sqrt(np.mean(np.square(sig[k])))) if sig is not None and k.any()
                  else float("nan")),
        **_sigma_honesty(ev, sol),
        **fix_outcomes(sim, sol, ev, wins),
        "grade": spec["imu"]["grade"], "map_aid": use_map,
        "odometer_sf": float(sim.odometer.meta["scale_factor"]) if sim.odometer is not None
        else float("nan"),
        "odometer_sf_est": float(sol.stats.get("odometer_scale_factor", np.nan)),
        # when the sideways-constraint check warned (selfnav.ins.measurements.NhcCheck)
        "nhc_slip_s": float((sol.stats.get("nhc_check") or {}).get("slip_seen_s") or np.nan),
        "sim_cpu_s": c1 - c0, "nav_cpu_s": c2 - c1, "cpu_s": time.process_time() - c0,
        "wall_s": time.perf_counter() - w0,
    }
    assert set(row) == set(ROW_KEYS)
    return row


#: the columns of a roadnav row (a drive without a start has them too, NaN)
ROW_KEYS = ("map", "sim_seed", "windows", "startup_window", "kinds", "along_rms_m",
            "cross_rms_m", "along_max_m", "cross_max_m", "along_heading_rms_m",
            "cross_heading_rms_m", "horizontal_rms_m", "horizontal_p95_m", "off_route_s",
            "on_route", "start_s", "error", "sigma", "err_sigma_p95", "beyond_5sigma",
            "clean_refused_s", "clean_refused_off_s", "locked_s", "window_off_s",
            "start_in_window", "grade",
            "map_aid", "odometer_sf", "odometer_sf_est", "nhc_slip_s", "sim_cpu_s", "nav_cpu_s",
            "cpu_s", "wall_s")


def _sigma_honesty(ev, sol) -> dict:
    """The σ a drive's rows promised against their errors: the 95th percentile of
    ``error / σ_h`` and the share of rows beyond 5σ (issue 18's honest σ)."""
    sig = sol.columns.get("sigma_h_m") if sol.columns else None
    if sig is None:
        return {"err_sigma_p95": float("nan"), "beyond_5sigma": float("nan")}
    s = np.interp(ev.t, sol.trajectory.t, np.asarray(sig, float))
    r = np.asarray(ev.horizontal, float) / np.maximum(s, 1e-9)
    return {"err_sigma_p95": float(np.percentile(r, 95)), "beyond_5sigma": float(np.mean(r > 5.0))}


def failure_classes(table: dict, off_s: float = 20.0) -> dict:
    """The clean fixes refused over all drives (s), and the drives more than ``off_s`` off the
    route sorted by what went wrong first (:func:`fix_outcomes`): ``no_start`` (no solution at
    all), ``started_in_window`` (the start was made on faulty fixes), ``locked_out`` (more than
    ``off_s`` of rows ``LOCKED_OFF_M`` off with the fixes clean: it could have recovered and
    did not), else ``in_windows`` (off only while the fixes were faulty: the dead reckoning, or
    a fault followed)."""
    def col(k):
        return np.asarray(table[k], float)

    off = col("off_route_s") > off_s
    none = ~np.isfinite(col("start_in_window"))
    start = np.nan_to_num(col("start_in_window")) > 0.5
    locked = np.nan_to_num(col("locked_s")) > off_s
    rest = off & ~none & ~start
    return {"clean_refused_s": float(np.nansum(col("clean_refused_s"))),
            "clean_refused_off_s": float(np.nansum(col("clean_refused_off_s"))),
            "off_route_classes": {"no_start": int(np.sum(off & none)),
                                  "started_in_window": int(np.sum(off & ~none & start)),
                                  "locked_out": int(np.sum(rest & locked)),
                                  "in_windows": int(np.sum(rest & ~locked))}}


def summarize_roadnav(table: dict, worst: int = 5) -> dict:
    """Distributions of the per-run figures (median, 95th percentile, worst), the pooled RMS
    (root of the mean of the squared per-run RMS), the runs over 10 and 20 s off the route,
    and the ``worst`` drives by along-track RMS and by time off the route, with their seeds."""
    out = {}
    for k in DISTRIBUTED:
        if k not in table:
            continue
        x = np.asarray(table[k], float)
        x = x[np.isfinite(x)]
        out[k] = {"median": float(np.median(x)), "p95": float(np.percentile(x, 95)),
                  "max": float(np.max(x))} if len(x) else {"median": float("nan"),
                                                          "p95": float("nan"), "max": float("nan")}
    for k in ("along_rms_m", "cross_rms_m", "horizontal_rms_m"):
        x = np.asarray(table[k], float)
        out[k]["pooled"] = float(np.sqrt(np.mean(np.square(x[np.isfinite(x)]))))
    out["runs_without_a_start"] = int(np.sum(~np.isfinite(np.asarray(table["along_rms_m"], float))))
    off = np.asarray(table["off_route_s"], float)
    out["runs_off_route_over_10_s"] = int(np.sum(off > 10.0))
    out["runs_off_route_over_20_s"] = int(np.sum(off > 20.0))
    out["cpu_s_per_run"] = float(np.mean(table["cpu_s"]))
    if "clean_refused_s" in table:
        out.update(failure_classes(table))

    def rows(order):
        return [{"seed": int(table["seed"][i]), "map": str(table["map"][i]),
                 "windows": str(table["windows"][i]),
                 "along_rms_m": round(float(table["along_rms_m"][i]), 2),
                 "cross_rms_m": round(float(table["cross_rms_m"][i]), 2),
                 "off_route_s": float(table["off_route_s"][i])} for i in order[:worst]]

    out["worst_along"] = rows(np.argsort(-np.asarray(table["along_rms_m"], float)))
    out["worst_off_route"] = rows(np.argsort(-off, kind="stable"))
    return out


register_pair("roadnav", run_roadnav, unit="m", defaults=ROADNAV_DEFAULTS,
              summarize=summarize_roadnav,
              description="road navigator (navigate --map, defaults) on simulated drives on "
                          "both shipped maps: random routes, outlier windows, consumer MEMS")
