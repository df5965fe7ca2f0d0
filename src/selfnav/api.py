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
from selfnav.roads.hmm import HmmMatcher
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


def match(gnss: GnssData, roads, *, sigma_m: float = 10.0, radius_m: float | None = None,
          beta_m: float | None = None) -> Solution:
    """GNSS-only map matching (hidden Markov model, Viterbi) onto OpenStreetMap roads.

    Returns a :class:`Solution` whose rows are the fixes moved onto the roads, with the
    ``cross_m`` column (distance moved) and the matcher's summary in ``stats``.
    """
    if not sigma_m > 0:
        raise SelfnavError(f"sigma_m must be positive, got {sigma_m}")
    graph = _as_roads(roads)
    x, y = graph.to_local(gnss.lat, gnss.lon)
    m = HmmMatcher(graph, sigma=sigma_m, radius=radius_m, beta=beta_m)
    res = m.match(gnss.t, np.column_stack([x, y]), gnss.sigma_m)
    n = len(gnss.t)
    nan3 = np.full((n, 3), np.nan)
    tr = Trajectory(gnss.t, res.lat, res.lon, gnss.h, nan3, np.full((n, 3, 3), np.nan),
                    source="selfnav match (HMM)")
    stats = {**res.summary(), "map_nodes": graph.n_nodes, "map_segments": graph.n_segments,
             "sigma_m": m.sigma, "beta_m": m.beta, "radius_m": m.radius}
    return Solution(tr, None, {"cross_m": res.moved}, stats, "hmm", res)


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
           "read_attitude", "estimate_latitude", "navigate", "match", "evaluate",
           "filter_config", "Solution"]
