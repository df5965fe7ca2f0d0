"""The Python API: what the command line does, as functions on data (DESIGN §6, §9).

Readers take paths and return the containers of :mod:`selfnav.types`; the algorithms take
those containers and return results; :class:`~selfnav.solution.Solution` writes itself with
``to_csv``. The ``selfnav`` command is a thin layer over these functions and gives the same
numbers. Everything here is re-exported from :mod:`selfnav`.
"""
from __future__ import annotations


import numpy as np

from selfnav import ins
from selfnav.errors import SelfnavError
from selfnav.evaluate import evaluate as _evaluate_trajectories
from selfnav.evaluate import load_road_polylines
from selfnav.ins.align import robust_init
from selfnav.io.attitude_file import read_attitude
from selfnav.io.readers import read_gnss, read_imu, read_imu_positions
from selfnav.latitude import LatitudeResult
from selfnav.latitude import estimate_latitude as _estimate_latitude
from selfnav.latitude import estimate_latitude_multiposition
from selfnav.roads.aid import EkfRoadAid
from selfnav.roads.graph import RoadGraph, read_roads
from selfnav.io.fleet import Fleet, read_fleet
from selfnav.roads.fleet import (FleetRun, MatchParams, match_files, match_track,
                                 match_tracks)
from selfnav.seed004 import SeedConfig, run_seed
from selfnav.solution import Solution, read_solution
from selfnav.types import GnssData, ImuData, Trajectory

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


def _check_overlap(imu: ImuData, gnss: GnssData) -> None:
    if gnss.t[-1] < imu.t[0] or gnss.t[0] > imu.t[-1]:
        raise SelfnavError(f"the GNSS times ({gnss.t[0]:.3f}…{gnss.t[-1]:.3f} s) and the IMU "
                           f"times ({imu.t[0]:.3f}…{imu.t[-1]:.3f} s) do not overlap: different "
                           "time bases (GPS seconds of week vs seconds of day?)")


def filter_config(grade: str = "consumer", *, lever_arm_m=None, nhc_lever_m=None,
                  window_test: bool = True, nhc: bool = True, shadows: bool = True,
                  mount_states: bool = False, scale_factors: bool | None = None,
                  **fields) -> "ins.FilterConfig":
    """The filter configuration :func:`navigate` uses for these options (see its parameters);
    ``fields`` override any :class:`~selfnav.ins.FilterConfig` field by name."""
    opts = dict(robust=window_test, nhc=nhc, use_shadows=shadows, mount_states=mount_states)
    if lever_arm_m is not None:
        opts["lever_arm_b"] = np.asarray(lever_arm_m, dtype=float)
    if nhc_lever_m is not None:
        opts["nhc_lever_b"] = np.asarray(nhc_lever_m, dtype=float)
    if scale_factors is not None:
        opts["scale_factors"] = bool(scale_factors)
    return ins.FilterConfig.for_grade(grade, **opts, **fields)


def navigate(imu: ImuData, gnss: GnssData, roads=None, *, method: str = "ekf",
             smooth: bool = False, grade: str = "consumer", config: "ins.FilterConfig | None" = None,
             lever_arm_m=None, nhc_lever_m=None, window_test: bool = True, nhc: bool = True,
             shadows: bool = True, mount_states: bool = False, scale_factors: bool | None = None,
             matcher: str = "seed", ins_datum: str = "sk42", declination_deg: float | None = None,
             progress=None) -> Solution:
    """Navigate a vehicle with an IMU and GNSS, and optionally a road map.

    Parameters
    ----------
    imu : ImuData
    gnss : GnssData
        Fixes in WGS-84 (readers convert other datums at load time).
    roads : RoadGraph, path or None
        OpenStreetMap roads: the EKF gets the road aid (:mod:`selfnav.roads.aid`); the seed
        method needs them.
    method : {"ekf", "seed"}
        The error-state EKF (+ RTS smoother with ``smooth``), or seed 004's two loops.
    grade : str
        IMU noise model of the EKF: a grade of :data:`selfnav.sensors.GRADES`.
    config : FilterConfig, optional
        A full filter configuration (then ``grade`` and the switches below are ignored).
    lever_arm_m : (3,), optional
        IMU → antenna, body RFU, m.
    nhc_lever_m : (3,), optional
        IMU → the point where the non-holonomic constraint holds (rear axle), body RFU, m.
    window_test, nhc, shadows, mount_states, scale_factors : bool
        The outlier window test, the non-holonomic constraint, the shadow dead reckoning,
        the mounting-angle states, the scale-factor states (None: the grade's default).
    matcher, ins_datum, declination_deg :
        ``method="seed"`` options (:class:`selfnav.seed004.SeedConfig`).
    progress : callable(fraction), optional

    Returns
    -------
    Solution
        ``stats`` holds the counts the command line prints (fixes accepted and rejected, ...).
    """
    if method not in METHODS:
        raise SelfnavError(f"unknown method '{method}' (use {' or '.join(METHODS)})")
    _check_overlap(imu, gnss)
    graph = _as_roads(roads)
    if method == "seed":
        if graph is None:
            raise SelfnavError("--method seed needs a road map: --map ROADS (.osm/.osm.pbf)")
        cfg = SeedConfig(matcher=matcher, ins_datum=ins_datum,
                         declination=None if declination_deg is None else np.radians(declination_deg))
        r = run_seed(imu, gnss, graph, cfg, progress=progress)
        stats = {k: v for k, v in r.stats.items() if k != "t_start"}
        # the seed loop has no covariance
        return Solution(r.trajectory, None, {}, stats, f"seed ({matcher})", r)
    cfg = config or filter_config(grade, lever_arm_m=lever_arm_m, nhc_lever_m=nhc_lever_m,
                                  window_test=window_test, nhc=nhc, shadows=shadows,
                                  mount_states=mount_states, scale_factors=scale_factors)
    aid = init = None
    if graph is not None:
        aid = EkfRoadAid(graph, gnss)
        init = robust_init(imu, gnss)
    res = ins.run_filter(imu, gnss, cfg, init=init, smooth=smooth, progress=progress,
                         road_aid=aid)
    stats = dict(res.stats)
    stats["suspect_fixes"] = int(np.sum(res.mode == 1))
    stats["smoothed"] = bool(res.smoothed)
    if res.mounting is not None and len(res.mounting):
        stats["mounting_deg"] = [float(x) for x in np.degrees(res.mounting[-1])]
    return Solution(res.trajectory, res.sigma_enu, {}, stats,
                    "ekf+map" if graph is not None else "ekf", res)


def match(gnss: GnssData, roads, *, sigma_m: float | None = None,
          radius_m: float | None = None, beta_m: float | None = None) -> Solution:
    """GNSS-only map matching (hidden Markov model, Viterbi) onto OpenStreetMap roads.

    ``sigma_m``: the GNSS σ where the fixes carry none; None estimates it from the fixes
    (Newson & Krumm's median distance to the nearest road). Returns a :class:`Solution` whose
    rows are the fixes moved onto the roads, with the columns ``cross_m`` (distance moved),
    ``way_id`` (OpenStreetMap way) and ``matched`` (a road within the search radius), and the
    matcher's summary in ``stats``.
    """
    if sigma_m is not None and not sigma_m > 0:
        raise SelfnavError(f"sigma_m must be positive, got {sigma_m}")
    graph = _as_roads(roads)
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
                               "matched": res.in_radius}, stats, "hmm", res)


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
    def traj(x):
        if isinstance(x, Solution):
            return x.trajectory
        if isinstance(x, Trajectory):
            return x
        return read_solution(x).trajectory

    if roads is not None and not isinstance(roads, list):
        roads = load_road_polylines(roads)
    ev = _evaluate_trajectories(traj(truth), traj(solution), roads=roads)
    return {**ev.metrics, "warnings": list(ev.warnings)}


__all__ = ["read_imu", "read_imu_positions", "read_gnss", "read_roads", "read_solution",
           "read_attitude", "read_fleet", "estimate_latitude", "navigate", "match", "match_fleet",
           "match_files", "evaluate",
           "filter_config", "Solution"]
