"""The Python API: what the command line does, as functions on data (DESIGN §6, §9).

Readers take paths and return the containers of :mod:`selfnav.types`; the algorithms take
those containers and return results; :class:`~selfnav.solution.Solution` writes itself with
``to_csv``. The ``selfnav`` command is a thin layer over these functions and gives the same
numbers. Everything here is re-exported from :mod:`selfnav`.
"""
from __future__ import annotations

import warnings

import numpy as np

from selfnav import ins
from selfnav.axes import to_vehicle
from selfnav.axes_detect import detected_frame, imu_axes_report
from selfnav.errors import SelfnavError, SelfnavWarning, warn
from selfnav.evaluation import evaluate as _evaluate_trajectories
from selfnav.evaluation import load_road_polylines
from selfnav.io.attitude_file import read_attitude
from selfnav.io.imu import report_gaps
from selfnav.io.readers import read_baro, read_gnss, read_imu, read_imu_positions
from selfnav.latitude import LatitudeResult
from selfnav.latitude import estimate_latitude as _estimate_latitude
from selfnav.latitude import estimate_latitude_multiposition
from selfnav.roads.aid import EkfRoadAid
from selfnav.roads.graph import RoadGraph, read_match_roads, read_roads
from selfnav.io.fleet import Fleet, read_fleet
from selfnav.roads.fleet import (FleetRun, MatchParams, match_files, match_track,
                                 match_tracks)
from selfnav.seed004 import SeedConfig, run_seed
from selfnav.solution import Solution, read_solution
from selfnav.types import GnssData, ImuData, OdometerData, Trajectory
from selfnav.ins.navigator import Navigator

METHODS = ("ekf", "seed")


def estimate_latitude(imu: ImuData, *, method: str = "optimal", **kw) -> LatitudeResult:
    """Latitude, heading, pitch and roll of an IMU at rest (seed 000).

    A record with a ``position`` column (several positions) is solved jointly with the sensor
    biases (:func:`selfnav.latitude.estimate_latitude_multiposition`); otherwise
    :func:`selfnav.latitude.estimate_latitude` with ``method`` ``"optimal"`` or ``"seed"``.
    """
    if imu.position is not None and len(np.unique(imu.position)) > 1:
        return estimate_latitude_multiposition(imu, **kw)
    return _estimate_latitude(imu, method=method, **kw)


def _as_roads(roads) -> RoadGraph | None:
    if roads is None or isinstance(roads, RoadGraph):
        return roads
    return read_roads(roads)


#: The platforms that move along their nose (whose forward axis the GNSS accelerations show).
_ALONG_NOSE = (None, "auto", "car", "pedestrian", "walker", "rover")


def _in_detected_axes(imu: ImuData, rep: dict, along_nose: bool, options: dict):
    """``--imu-axes detect``: the rows into the frame the record's own data show
    (:func:`selfnav.axes_detect.detected_frame`; a setting found from the whole record before
    the navigator runs, as ``--imu-axes`` would be given — the rows are causal given it). With
    the up axis alone the forward axis is a guess, and the sideways constraint that needs it is
    turned off (unless ``nhc`` was given), in one warning."""
    src = imu.source or "IMU data"
    frame, forward_known = detected_frame(rep, src)
    rep["applied"] = frame.axes.letters + (f", yaw {frame.mount_deg[2]:.2f}°"
                                           if frame.has_mount else "")
    if not forward_known and along_nose and options.get("nhc") is None:
        options = {**options, "nhc": False}
        warn(f"{src}: --imu-axes detect found up (the rows read as {frame.axes.letters}) but not "
             "forward (no GNSS velocity, or too little acceleration and turning to see it): the "
             "sideways constraint is off; give --imu-axes for it")
    return to_vehicle(imu, frame), options


def _check_overlap(imu: ImuData, gnss: GnssData) -> None:
    if gnss.t[-1] < imu.t[0] or gnss.t[0] > imu.t[-1]:
        raise SelfnavError(f"the GNSS times ({gnss.t[0]:.3f}…{gnss.t[-1]:.3f} s) and the IMU "
                           f"times ({imu.t[0]:.3f}…{imu.t[-1]:.3f} s) do not overlap: different "
                           "time bases (GPS seconds of week vs seconds of day?)")


def filter_config(grade: str = "auto", **kw) -> "ins.FilterConfig":
    """The navigator's configuration for these options (:func:`selfnav.ins.navigator_config`)."""
    return ins.navigator_config(grade, **kw)


def initial_state(reference, imu: ImuData, cfg: "ins.FilterConfig") -> dict:
    """The navigator's start from another navigator or a survey (``--init``): the state of
    ``reference`` (a :class:`Trajectory` or a file :func:`read_solution` reads) at its first
    epoch inside the IMU record, with the σ of ``cfg.init`` — no GNSS alignment needed."""
    tr = reference.trajectory if isinstance(reference, Solution) else (
        reference if isinstance(reference, Trajectory) else read_solution(reference).trajectory)
    k = int(np.searchsorted(tr.t, imu.t[0] + imu.dt))
    if k >= len(tr.t):
        raise SelfnavError(f"the initial-state file ends ({tr.t[-1]:.3f} s) before the IMU "
                           f"starts ({imu.t[0]:.3f} s): a different time base?")
    if not (np.all(np.isfinite(tr.velocity_n[k])) and np.all(np.isfinite(tr.C_nb[k]))):
        raise SelfnavError("the initial-state file needs velocity (ve, vn, vu) and attitude "
                           "(roll_deg, pitch_deg, heading_deg) as well as position")
    ini = cfg.init
    return {"t": float(tr.t[k]), "lat": float(tr.lat[k]), "lon": float(tr.lon[k]),
            "h": float(tr.h[k]), "velocity_n": tr.velocity_n[k].copy(), "C_nb": tr.C_nb[k].copy(),
            "sigmas": ([ini.given_pos_sigma] * 3, [ini.given_vel_sigma] * 3,
                       list(ini.given_att_sigma))}


def navigator(imu: ImuData | None = None, roads=None, *, grade: str = "auto", config=None,
              init=None, smooth: bool = False, **options) -> "ins.Navigator":
    """The :class:`selfnav.Navigator` :func:`navigate` runs: the configuration of ``grade`` and
    ``options`` (:func:`selfnav.ins.navigator_config` keywords, ``out_rate_hz``), the road aid
    of ``roads`` (a map or its path), the start state ``init`` (a trajectory or file, needs
    ``imu`` for its start time)."""
    rate = options.pop("out_rate_hz", ins.DEFAULT_OUT_RATE_HZ)
    cfg = config or ins.navigator_config(grade, **options)
    graph = _as_roads(roads)
    aid = EkfRoadAid(graph) if graph is not None else None
    start = None if init is None else initial_state(init, imu, cfg)
    return ins.Navigator(cfg, road_aid=aid, init=start, out_rate_hz=rate, smoother=smooth,
                         imu_time_offset_s=options.get("imu_time_offset_s"))


def navigate(imu: ImuData, gnss: GnssData | None, roads=None, *, method: str = "ekf",
             smooth: bool = False, progress=None, odometer: OdometerData | None = None,
             **options) -> Solution:
    """Navigate with an IMU and GNSS (and a road map): the loop over :class:`selfnav.Navigator`
    that ``selfnav navigate`` runs — every row from the past only, except with ``smooth``
    (the RTS smoother: post-processing). ``options``: :func:`navigator` keywords (``grade``,
    ``lever_arm_m``, ``imu_time_offset_s``, ``nhc``, ``init``, ``out_rate_hz``, ...); with
    ``method="seed"`` seed 004's two loops (:func:`navigate_seed`)."""
    if method not in METHODS:
        raise SelfnavError(f"unknown method '{method}' (use {' or '.join(METHODS)})")
    if method == "seed":
        return navigate_seed(imu, gnss, roads, progress=progress, odometer=odometer, **options)
    imu = report_gaps(imu)          # short gaps bridged, each long one said in one line
    if gnss is None and options.get("init") is None:
        raise SelfnavError("without GNSS the navigator needs an initial state (--init FILE)")
    axes = None
    if gnss is not None:
        _check_overlap(imu, gnss)
        # gyros in deg/s or turning the other way: refused; axes other than given: a warning
        along = options.get("platform") in _ALONG_NOSE
        axes = imu_axes_report(imu, gnss, along_nose=along)
        if imu.meta.get("axes") == "sensor":          # --imu-axes detect
            imu, options = _in_detected_axes(imu, axes, along, options)
    nav = navigator(imu, roads, smooth=smooth, **options)
    odo = None if odometer is None else odometer.shifted(0.0)
    ins.feed(nav, imu, gnss, odometer=odo, progress=progress)
    res = nav.result(smooth)
    fmt = float(imu.meta.get("format_time_offset_s", 0.0))
    stats = {**res.stats, "smoothed": res.smoothed, "episodes": res.episodes, "imu_axes": axes,
             "imu_time_offset_format_s": fmt,
             "imu_time_offset_s": fmt + res.stats.get("imu_time_offset_s", 0.0)}
    cols = {"sigma_h_m": res.sigma_h, "status": res.status,
            "protection_level_m": res.protection_level}
    return Solution(res.trajectory, res.sigma_enu, cols, stats,
                    "ekf+map" if roads is not None else "ekf", res)


def navigate_seed(imu: ImuData, gnss: GnssData, roads, *, matcher: str = "seed",
                  ins_datum: str = "sk42", declination_deg: float | None = None,
                  progress=None, odometer: OdometerData | None = None, **unused) -> Solution:
    """Seed 004's two-loop road navigator (:mod:`selfnav.seed004`); options of the EKF
    navigator are refused by name rather than ignored."""
    given = sorted(k for k, v in unused.items() if v is not None and k != "grade")
    if given:
        raise SelfnavError(f"--method seed does not take {', '.join(given)} (EKF options)")
    graph = _as_roads(roads)
    if graph is None:
        raise SelfnavError("--method seed needs a road map: --map ROADS (.osm/.osm.pbf)")
    if gnss is None:
        raise SelfnavError("--method seed needs GNSS fixes (--gnss FILE)")
    imu = report_gaps(imu)
    _check_overlap(imu, gnss)
    cfg = SeedConfig(matcher=matcher, ins_datum=ins_datum,
                     declination=None if declination_deg is None else np.radians(declination_deg))
    odo = None if odometer is None else odometer.shifted(float(imu.meta.get("time_offset_s", 0.0)))
    r = run_seed(imu, gnss, graph, cfg, progress=progress, odometer=odo)
    stats = {k: v for k, v in r.stats.items() if k != "t_start"}
    # the seed loop has no covariance
    return Solution(r.trajectory, None, {}, stats, f"seed ({matcher})", r)


def write_fix_log(path, solution: Solution):
    """One row per GNSS fix of a navigator run: ``t, status, reason, nis_h, nis_v, nis_vel,
    excluded`` (status: :class:`selfnav.ins.FixStatus`; excluded: fused, then found faulty by
    the fault bank; written atomically)."""
    from selfnav.io.csvio import write_csv

    log = getattr(solution.detail, "fix_log", None)
    if log is None:
        raise SelfnavError("this method keeps no fix log (use --method ekf)")
    cols = {"t": np.asarray(log["t"], float), "status": log["status"],
            "reason": np.array([str(r).replace(",", ";") or "-" for r in log["reason"]], dtype=object),
            "nis_h": np.asarray(log["nis_h"], float), "nis_v": np.asarray(log["nis_v"], float),
            "nis_vel": np.asarray(log["nis_vel"], float),
            "excluded": np.asarray(log["excluded"], int)}
    statuses = ", ".join(s.value for s in ins.FixStatus)
    return write_csv(path, cols, comments=["selfnav navigate: one row per GNSS fix",
                                           f"status: {statuses}"],
                     fmt={"t": "%.3f", "nis_h": "%.4g", "nis_v": "%.4g", "nis_vel": "%.4g",
                          "excluded": "%d"})


def match(gnss: GnssData, roads, *, sigma_m: float | None = None,
          radius_m: float | None = None, beta_m: float | None = None) -> Solution:
    """GNSS-only map matching (hidden Markov model, Viterbi) onto OpenStreetMap roads.

    ``sigma_m``: the GNSS σ where the fixes carry none; None estimates it from the fixes
    (Newson & Krumm's median distance to the nearest road). ``roads``: a path is read as map
    matching needs it (:func:`selfnav.roads.graph.read_match_roads`: every drivable way, unjoined
    ways snapped); a :class:`RoadGraph` is used as it is. Returns a :class:`Solution` whose
    rows are the fixes moved onto the roads, with the columns ``cross_m`` (distance moved),
    ``way_id`` (OpenStreetMap way), ``matched`` (the match is plausible), ``match_p``
    (posterior of the matched road) and ``piece`` (piece of chain between breaks), and the
    matcher's summary (with the track's quality: share matched, breaks, median cross) in
    ``stats``.
    """
    if sigma_m is not None and not sigma_m > 0:
        raise SelfnavError(f"sigma_m must be positive, got {sigma_m}")
    graph = roads if isinstance(roads, RoadGraph) else read_match_roads(roads)
    m = MatchParams(sigma_m, radius_m, beta_m).matcher(graph)
    tm = match_track(m, gnss.source or "track", gnss, auto_sigma=sigma_m is None)
    if tm.error:
        raise SelfnavError(tm.error)
    return _match_solution(gnss, tm.result, m.with_sigma(tm.result.sigma))


def _match_solution(gnss: GnssData, res, m) -> Solution:
    n = len(gnss.t)
    nan3 = np.full((n, 3), np.nan)
    tr = Trajectory(gnss.t, res.lat, res.lon, gnss.h, nan3, np.full((n, 3, 3), np.nan),
                    source="selfnav match (HMM)")
    stats = {**res.summary(), "map_nodes": m.graph.n_nodes, "map_segments": m.graph.n_segments,
             "sigma_m": m.sigma, "beta_m": m.beta, "radius_m": m.radius}
    return Solution(tr, None, {"cross_m": res.moved, "way_id": res.way,
                               "matched": res.matched, "match_p": res.match_p,
                               "piece": res.piece}, stats, "hmm", res)


def match_fleet(tracks, roads, *, sigma_m: float | None = None, radius_m: float | None = None,
                beta_m: float | None = None, workers: int | None = None,
                scheduler: str | None = None, route: bool = False, progress=None,
                run: FleetRun | None = None):
    """Map-match many tracks, each on its own; results in track order, as they come.

    Parameters
    ----------
    tracks : Fleet, list of (track_id, GnssData), or path(s)
        A :class:`selfnav.io.fleet.Fleet` (:func:`read_fleet`), pairs, or fleet files/folders
        (CSV or Parquet with an optional ``track_id`` column).
    roads : path or RoadGraph
        The map; a path lets Dask workers read it themselves.
    sigma_m, radius_m, beta_m :
        As :func:`match`.
    workers : int, optional
        Local Dask workers; 0 = this process. Default: this process for a small fleet (under
        200,000 fixes), else one worker per core.
    scheduler : str, optional
        An existing Dask scheduler (``tcp://host:8786``).
    route : bool
        Also compute each track's driven route (``TrackMatch.route``).
    progress : callable(n), optional
        Called with the number of tracks just finished.

    Yields
    ------
    selfnav.roads.fleet.TrackMatch
        ``track_id``, ``result`` (a :class:`~selfnav.roads.hmm.MatchResult`, or None with
        ``error`` set), ``route``.
    """
    if sigma_m is not None and not sigma_m > 0:
        raise SelfnavError(f"sigma_m must be positive, got {sigma_m}")
    if isinstance(tracks, Fleet):
        items = [(tr.track_id, tr.gnss) for tr in tracks.tracks]
    elif isinstance(tracks, (list, tuple)) and tracks and isinstance(tracks[0], tuple):
        items = list(tracks)
    else:
        items = [(tr.track_id, tr.gnss) for tr in read_fleet(tracks).tracks]
    if not isinstance(roads, RoadGraph):
        roads = str(roads)
    return match_tracks(items, roads, MatchParams(sigma_m, radius_m, beta_m), workers=workers,
                        scheduler=scheduler, route=route, progress=progress, run=run)


def evaluate(truth, solution, *, roads=None) -> dict:
    """Errors of a solution against truth: the keys of ``selfnav evaluate --json``
    (``horizontal_rms_m``, ``horizontal_p95_m``, ``horizontal_max_m``, ``vertical_rms_m``,
    along/cross-track, ... and ``warnings``).

    ``truth`` and ``solution`` may be :class:`Trajectory`, :class:`Solution` or paths;
    ``roads`` a map path or road polylines for road-relative along/cross-track.
    """
    rn = "the map" if roads is None or isinstance(roads, list) else str(roads)
    if roads is not None and not isinstance(roads, list):
        roads = load_road_polylines(roads)
    ev = _evaluate_trajectories(as_trajectory(truth), as_trajectory(solution), roads=roads,
                                roads_name=rn)
    return {**ev.metrics, "warnings": list(ev.warnings)}


# --------------------------------------------------------------------------------------------
# The other commands' functions (issue 11: every command calls the API)
# --------------------------------------------------------------------------------------------
def allan_noise(imu: ImuData, *, plot=None, title: str | None = None) -> dict:
    """Allan deviation and noise terms of an IMU record at rest: the keys of
    ``selfnav allan --json`` (ARW, bias instability, VRW, ... per axis, DESIGN §6).

    Records with gaps are analysed on their longest gap-free stretch (one warning says so).
    ``plot``: a PNG file for the log-log plot (written only when given).
    """
    from selfnav import allan as allan_mod

    res = allan_mod.analyze_imu(imu)
    out = allan_mod.summary(res)
    if plot is not None:
        allan_mod.plot_allan(res, plot, title or f"Allan deviation: {imu.source or 'IMU'}")
        out["plot"] = str(plot)
    return out


def latitude_requirements(lat_deg: float = 60.0, *, seed_constants: bool = False) -> list:
    """Seed 000's sensor-requirements table at ``lat_deg``: one dict per row (Δφ in degrees
    and arc-minutes, gyro drift °/h and accelerometer error g that each cause it)."""
    from selfnav.latitude import SEED_TABLE_DPHI_DEG, requirements_table

    if not -90.0 <= lat_deg <= 90.0:
        raise SelfnavError(f"latitude {lat_deg:g}° is outside -90..90")
    tab = requirements_table(SEED_TABLE_DPHI_DEG, lat_deg, seed_constants=seed_constants)
    return [{k: float(v) for k, v in zip(tab, vals)} for vals in zip(*tab.values())]


def latitude_error_budget(result: LatitudeResult, *, gyro_bias_deg_h: float = 0.005,
                          accel_bias_ug: float = 50.0) -> dict:
    """Latitude error, degrees, caused by each gyro (``gyro_bias_deg_h``) and accelerometer
    (``accel_bias_ug``) bias alone, the noise, and their root sum square (seed 000 (4.3))."""
    from selfnav.latitude import DEG_PER_H, G_STD, error_budget

    b = error_budget(result, gyro_bias_deg_h * DEG_PER_H, accel_bias_ug * 1e-6 * G_STD)
    return {k: float(np.degrees(v)) for k, v in b.items()}


def evaluate_report(truth, solution, *, roads=None, report=None, title: str | None = None,
                    truth_name: str | None = None, solution_name: str | None = None) -> dict:
    """:func:`evaluate` and, with ``report`` (a folder), its plots, ``metrics.json`` and
    ``report.html`` (written as one set). Returns the ``selfnav evaluate --json`` object:
    the metrics (with ``coverage``), ``warnings`` and, with a report, ``report`` and
    ``figures``."""
    from selfnav.report import write_report

    tn = truth_name or (str(truth) if not isinstance(truth, (Solution, Trajectory)) else "truth")
    sn = solution_name or (str(solution) if not isinstance(solution, (Solution, Trajectory))
                           else "solution")
    rn = "the map" if roads is None or isinstance(roads, list) else str(roads)
    if roads is not None and not isinstance(roads, list):
        roads = load_road_polylines(roads)
    ev = _evaluate_trajectories(as_trajectory(truth), as_trajectory(solution), roads=roads,
                                truth_name=tn, solution_name=sn, roads_name=rn)
    out = {"truth": tn, "solution": sn, **ev.metrics, "warnings": list(ev.warnings)}
    if report is not None:
        files = write_report(ev, report, roads=roads, sources={"truth": tn, "solution": sn},
                             title=title or f"selfnav evaluate: {sn} against {tn}")
        out["report"] = files["report.html"]
        out["figures"] = [files["errors.png"], files["track.png"]]
    return out


def map_coverage(roads, lat, lon, *, margin_m: float = 1000.0) -> float:
    """Share of the points (rad) within ``margin_m`` of the map's extent
    (:func:`selfnav.roads.graph.map_coverage`)."""
    from selfnav.roads.graph import map_coverage as _coverage

    return _coverage(_as_roads(roads), lat, lon, margin_m=margin_m)


def check_map_covers(roads, lat, lon, *, what: str = "the data", margin_m: float = 1000.0):
    """Refuse (one line) a map none of the points lies on, and warn when part of them lie off
    it: the check ``selfnav match`` and ``selfnav navigate --map`` make before the work."""
    from selfnav.roads.graph import check_map_covers as _check

    graph = _as_roads(roads)
    _check(graph, lat, lon, what=what, margin_m=margin_m)
    return graph


def imu_gaps(imu: ImuData, min_missing: int = 1) -> list:
    """Gaps of an IMU record (:func:`selfnav.io.imu.imu_gaps`)."""
    from selfnav.io.imu import imu_gaps as _gaps

    return _gaps(imu, min_missing)


def simulate_files(spec, out_dir, *, seed: int = 0, grade: str | None = None,
                   duration: float | None = None, dt: float | None = None, progress=None,
                   start: str | None = None, imu_axes=None, imu_mount=None):
    """Simulate a scenario (:func:`selfnav.sim.scenarios.simulate`) and write its files
    into the folder ``out_dir`` as one set; returns ``(simulation, paths)``. ``start``:
    ``rest``/``moving`` for the platforms; ``imu_axes``/``imu_mount``: the IMU written in
    that axes convention and mounting (:func:`selfnav.sim.scenarios.write_simulation`)."""
    from selfnav.sim.scenarios import simulate, write_simulation

    if imu_axes is not None or imu_mount is not None:      # a bad spec fails before the work
        from selfnav.axes import imu_frame

        imu_frame(imu_axes, imu_mount)
    sim = simulate(spec, seed=seed, grade=grade, duration=duration, dt=dt, start=start,
                   progress=progress)
    if progress is not None:
        progress("writing")
    return sim, write_simulation(sim, out_dir, imu_axes=imu_axes, imu_mount=imu_mount)


def run_montecarlo(scenario: str, runs: int, *, out=None, **kw):
    """A seeded Monte Carlo campaign (:func:`selfnav.montecarlo.run_montecarlo`, same keywords);
    with ``out`` (``.csv`` or ``.parquet``) the per-run rows are written too."""
    from selfnav import montecarlo as mc

    res = mc.run_montecarlo(scenario, runs, **kw)
    if out is not None:
        mc.write_results(out, res)
    return res


def read_reference_attitude(path) -> "AttitudeData":
    """An attitude to compare with: a PX4 ULog's own ``vehicle_attitude`` (``.ulg``), or an
    attitude / truth / solution CSV (``t, roll_deg, pitch_deg, heading_deg``)."""
    from pathlib import Path

    from selfnav.io.ulog import ULOG_SUFFIXES, read_ulog_attitude

    if Path(path).name.lower().endswith(ULOG_SUFFIXES):
        return read_ulog_attitude(path)
    return read_attitude(path)


def estimate_attitude(imu: ImuData, *, gnss: GnssData | None = None, grade: str = "consumer",
                      declination_deg: float | None = None, lat_deg: float | None = None,
                      lon_deg: float | None = None, h_m: float = 0.0, use_mag: bool = True,
                      config=None):
    """Attitude from gyros, accelerometers and magnetometer (:class:`selfnav.ins.ahrs.Ahrs`).

    The declination is, in this order: ``declination_deg``; IGRF-14 at ``lat_deg, lon_deg``
    or at the first fix of ``gnss`` (σ 0.5°); the declination the file says its own
    estimator used (a PX4 log's ``ATT_MAG_DECL`` / ``EKF2_MAG_DECL``, ``imu.meta``); else 0
    with a warning (the heading is then magnetic). The latitude (Earth rate) comes from the
    same place. ``result.info["declination_source"]`` says which.

    Returns
    -------
    selfnav.ins.ahrs.AhrsResult
    """
    import math
    from dataclasses import replace

    from selfnav.ins.ahrs import Ahrs, AhrsConfig
    from selfnav.ins.rest import IGRF_DECLINATION_SIGMA_DEG, declination_at

    cfg = config or AhrsConfig(grade=grade, use_mag=use_mag)
    lat = lon = None
    if lat_deg is not None and lon_deg is not None:
        lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    elif gnss is not None and len(gnss):
        lat, lon, h_m = float(gnss.lat[0]), float(gnss.lon[0]), float(gnss.h[0])
    have_mag = imu.mag_b is not None and use_mag
    if declination_deg is not None:
        dec, s_dec, src = math.radians(declination_deg), 0.0, "given"
    elif lat is not None:
        dec, _ = declination_at(lat, lon, h_m)
        s_dec, src = math.radians(IGRF_DECLINATION_SIGMA_DEG), "igrf"
    elif imu.meta.get("declination_deg") is not None:
        dec, s_dec = math.radians(float(imu.meta["declination_deg"])), 0.0
        src = "file (the logging autopilot's declination parameter)"
    else:
        dec, s_dec, src = 0.0, 0.0, "none"
        if have_mag:
            warnings.warn(f"{imu.source or 'IMU'}: no position or declination given: the heading "
                          "is magnetic (give --declination-deg, --lat-deg/--lon-deg or --gnss)",
                          SelfnavWarning, stacklevel=2)
    inc = None if lat is None else declination_at(lat, lon, h_m)[1]
    cfg = replace(cfg, declination=dec, sigma_declination=s_dec, lat=lat, inclination=inc)
    res = Ahrs(cfg).run(imu)
    res.info.update({"declination_deg": math.degrees(dec), "declination_source": src,
                     "latitude_deg": None if lat is None else math.degrees(lat),
                     "magnetometer": bool(have_mag)})
    if not res.info.get("start"):
        raise SelfnavError(f"{imu.source or 'IMU'}: the attitude filter did not start "
                           f"({len(imu)} samples: too few?)")
    return res


def compare_attitude(result, reference, *, t_from: float | None = None) -> dict:
    """Roll, pitch and heading differences (RMS, max, mean; within 2σ, NEES) of an attitude
    run against a reference :class:`~selfnav.types.AttitudeData` from ``t_from`` (default
    the run's start) on (:func:`selfnav.evaluation.attitude_errors`)."""
    from selfnav.evaluation import attitude_errors

    t0 = result.info.get("t_start") if t_from is None else t_from
    return attitude_errors(result.t, result.C_nb, reference.t, reference.C_nb, t_from=t0,
                           sigma_rph=result.sigma_rph)


def as_trajectory(x) -> Trajectory:
    """A :class:`Trajectory` from a Trajectory, a :class:`Solution` or a solution/truth file."""
    if isinstance(x, Solution):
        return x.trajectory
    if isinstance(x, Trajectory):
        return x
    return read_solution(x).trajectory


__all__ = ["read_imu", "read_imu_positions", "read_gnss", "read_roads", "read_solution",
           "read_attitude", "read_fleet", "estimate_latitude", "navigate", "match", "match_fleet",
           "match_files", "evaluate", "filter_config", "initial_state", "write_fix_log",
           "navigator", "navigate_seed", "Navigator",
           "Solution", "allan_noise", "latitude_requirements", "latitude_error_budget",
           "evaluate_report", "map_coverage", "check_map_covers", "imu_gaps", "simulate_files",
           "run_montecarlo", "as_trajectory", "read_baro", "estimate_attitude",
           "compare_attitude", "read_reference_attitude"]


# ---------------------------------------------------------------- raw GNSS (issue 23)
def read_gnss_raw(path, nav=None, *, fmt: str = "auto"):
    """Raw GNSS measurements (+ ephemerides) of a RINEX, u-blox UBX, Android GnssLogger,
    smartLoc or PSINS file: :func:`selfnav.io.raw_readers.read_gnss_raw`."""
    from selfnav.io.raw_readers import read_gnss_raw as _read

    return _read(path, nav, fmt=fmt)


def spp(gnss_raw, nav=None, *, fmt: str = "auto", elevation_mask_deg: float = 5.0,
        smoothing_s: float = 30.0, fde: bool = True, systems=None, alpha: float = 1e-3):
    """Single-point positions, Doppler velocities and per-epoch satellite exclusions of a raw
    GNSS record (docs/gnss.md).

    Parameters
    ----------
    gnss_raw : path or :class:`selfnav.io.gnss_raw.RawGnss`
    nav : RINEX navigation file(s) adding ephemerides, optional
    fmt : raw format (:data:`selfnav.io.gnss_raw.RAW_FORMATS`)
    elevation_mask_deg, smoothing_s, alpha : see :class:`selfnav.gnss.raw.RawSppConfig`
    fde : exclude faulty satellites (largest consistent subset); False: all satellites
    systems : iterable of RINEX letters (``"GREC"``) or system codes; None: all

    Returns
    -------
    Solution
        ``method "spp"``; ``columns`` per epoch (see docs/gnss.md), ``stats`` the summary,
        ``detail`` the :class:`selfnav.gnss.raw.RawSppResult`.
    """
    from dataclasses import replace as _replace

    from selfnav.gnss.raw import RawSppConfig, spp_raw
    from selfnav.io.gnss_raw import GPS_WEEK_S, LETTER_SYSTEMS, RawGnss
    from selfnav.io.raw_readers import read_gnss_raw as _read

    raw = gnss_raw if isinstance(gnss_raw, RawGnss) else _read(gnss_raw, nav, fmt=fmt)
    cfg = RawSppConfig()
    sp = _replace(cfg.spp, alpha=alpha, raim=bool(fde))
    kw = {}
    if systems is not None:
        codes = []
        for s in systems:
            if isinstance(s, str):
                if s.upper() not in LETTER_SYSTEMS:
                    raise SelfnavError(f"unknown satellite system '{s}' (G, R, E, C, J)")
                codes.append(LETTER_SYSTEMS[s.upper()])
            else:
                codes.append(int(s))
        kw["systems"] = tuple(codes)
    cfg = _replace(cfg, spp=sp, elevation_mask_deg=elevation_mask_deg, smoothing_s=smoothing_s,
                   **kw)
    res = spp_raw(raw, cfg)
    r = res.spp
    ok = np.isfinite(r.lat)
    n = int(ok.sum())
    if n == 0:
        raise SelfnavError(f"{raw.source}: no epoch has enough satellites for a position")
    week0 = 0
    if raw.obs.corrected:             # smartLoc: the file's own time base
        t, week = r.t[ok], np.zeros(n, int)
    else:
        week0 = int(np.floor(r.t[ok][0] / GPS_WEEK_S))
        t, week = r.t[ok] - week0 * GPS_WEEK_S, np.floor(r.t[ok] / GPS_WEEK_S).astype(int)
    vel = res.velocity_enu[ok]
    full_vel = bool(np.all(np.isfinite(vel)))
    traj = Trajectory(t, r.lat[ok], r.lon[ok], r.h[ok],
                      vel if full_vel else np.full((n, 3), np.nan),
                      np.full((n, 3, 3), np.nan), source=f"selfnav spp {raw.source}")
    sig = r.sigma_enu[ok]
    cols = {"sigma_h_m": np.hypot(sig[:, 0], sig[:, 1]), "sigma_m": r.sigma_m[ok]}
    if np.any(np.isfinite(vel)):
        sv = res.sigma_vel_enu[ok]
        cols["sigma_vel_mps"] = np.sqrt(0.5 * (sv[:, 0] ** 2 + sv[:, 1] ** 2))
        cols["clock_drift_mps"] = res.clock_drift[ok]
    idx = np.flatnonzero(ok)
    cols.update(
        gps_week=week, n_sats=r.n_sats[ok], n_used=r.n_used[ok],
        excluded=np.array([" ".join(res.excluded[i]) or "-" for i in idx], dtype=object),
        excluded_doppler=np.array([" ".join(res.excluded_doppler[i]) or "-" for i in idx],
                                  dtype=object),
        test_stat=r.test_stat[ok], dof=r.dof[ok], passed=r.passed[ok].astype(int),
        sigma_scale=(r.sigma_scale[ok] if r.sigma_scale is not None else np.ones(n)))
    stats = {**res.stats, "epochs_out": n, "no_fix": int((~ok).sum()),
             "median_sigma_h_m": float(np.median(cols["sigma_h_m"])),
             "receiver_solution": raw.receiver is not None, "source": raw.source,
             "week0": week0}
    return Solution(traj, sig, cols, stats, "spp", res)


def receiver_solution(raw) -> Solution:
    """The receiver's own solution of a raw record (u-blox NAV-PVT, Android ``Fix``) as a
    :class:`Solution` on the same time base as :func:`spp` (GPS seconds of the first week),
    ``quality`` per row (1 fixed RTK, 2 float, 4 differential, 5 single)."""
    from selfnav.io.gnss_raw import GPS_WEEK_S

    g = raw.receiver
    if g is None:
        raise SelfnavError(f"{raw.source}: the file has no receiver solution (NAV-PVT, Fix)")
    week0 = int(np.floor(raw.obs.t[0] / GPS_WEEK_S))
    n = len(g.t)
    v = g.velocity_n if g.velocity_n is not None else np.full((n, 3), np.nan)
    traj = Trajectory(g.t - week0 * GPS_WEEK_S, g.lat, g.lon, g.h, v,
                      np.full((n, 3, 3), np.nan), source=g.source)
    return Solution(traj, None, {"quality": g.quality, "sigma_m": g.sigma_m}, {}, "receiver")


def write_sat_log(path, solution: Solution):
    """Per satellite and epoch of an :func:`spp` solution: ``t, sat, used, residual_m,
    elevation_deg, azimuth_deg, iono_m, tropo_m`` (written atomically)."""
    from selfnav.io.csvio import write_csv
    from selfnav.io.gnss_raw import GPS_WEEK_S

    res = solution.detail
    r = res.spp
    t = res.obs_t - solution.stats.get("week0", 0) * GPS_WEEK_S
    return write_csv(path, {"t": t, "sat": res.obs_name, "used": r.obs_used.astype(int),
                            "residual_m": r.obs_residual,
                            "elevation_deg": np.degrees(res.obs_elevation),
                            "azimuth_deg": np.degrees(res.obs_azimuth),
                            "iono_m": res.obs_iono, "tropo_m": res.obs_tropo},
                     fmt={"t": "%.3f", "residual_m": "%.3f", "elevation_deg": "%.2f",
                          "azimuth_deg": "%.2f", "iono_m": "%.3f", "tropo_m": "%.3f"})


__all__ += ["read_gnss_raw", "spp", "receiver_solution", "write_sat_log"]

from selfnav.api_gnss import (navigate_raw, navigate_raw_imu, simulate_city_files,  # noqa: E402  (issue 23)
                              write_tight_log)

__all__ += ["navigate_raw", "navigate_raw_imu", "write_tight_log", "simulate_city_files"]
