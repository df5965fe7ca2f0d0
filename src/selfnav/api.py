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
from selfnav.errors import SelfnavError, SelfnavWarning
from selfnav.evaluate import evaluate as _evaluate_trajectories
from selfnav.evaluate import load_road_polylines
from selfnav.ins import calibrate
from selfnav.ins.align import robust_init
from selfnav.io.attitude_file import read_attitude
from selfnav.io.readers import read_gnss, read_imu, read_imu_positions
from selfnav.latitude import LatitudeResult
from selfnav.latitude import estimate_latitude as _estimate_latitude
from selfnav.latitude import estimate_latitude_multiposition
from selfnav.roads.aid import EkfRoadAid, start_on_roads
from selfnav.roads.graph import RoadGraph, read_roads
from selfnav.roads.hmm import HmmMatcher
from selfnav.seed004 import SeedConfig, run_seed
from selfnav.solution import Solution, read_solution
from selfnav.types import GnssData, ImuData, OdometerData, Trajectory

METHODS = ("ekf", "seed")
#: a run that leaves more of its fixes unused than this warns (one line)
REJECTION_WARNING = 0.2


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


def filter_config(grade: str = "auto", *, lever_arm_m=None, nhc_lever_m=None,
                  window_test: bool = True, nhc: bool = True, shadows: bool = True,
                  mount_states: bool = False, scale_factors: bool | None = None,
                  **fields) -> "ins.FilterConfig":
    """The filter configuration :func:`navigate` starts from for these options (see its
    parameters); ``fields`` override any :class:`~selfnav.ins.FilterConfig` field by name.

    ``grade="auto"`` is the consumer preset as the prior (the widest), to be raised to what
    the data shows; without ``lever_arm_m`` the lever arm is estimated (3 states).
    """
    opts = dict(robust=window_test, nhc=nhc, use_shadows=shadows, mount_states=mount_states)
    if lever_arm_m is not None:
        opts["lever_arm_b"] = np.asarray(lever_arm_m, dtype=float)
    else:
        opts["lever_arm"] = True
    if nhc_lever_m is not None:
        opts["nhc_lever_b"] = np.asarray(nhc_lever_m, dtype=float)
    if scale_factors is not None:
        opts["scale_factors"] = bool(scale_factors)
    key = "consumer" if str(grade).lower().strip() == "auto" else grade
    cfg = ins.FilterConfig.for_grade(key, **opts, **fields)
    if str(grade).lower().strip() == "auto":
        cfg.imu.grade = "auto (consumer prior)"
    return cfg


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


def navigate(imu: ImuData, gnss: GnssData | None, roads=None, *, method: str = "ekf",
             smooth: bool = False, grade: str = "auto", config: "ins.FilterConfig | None" = None,
             lever_arm_m=None, nhc_lever_m=None, imu_time_offset_s: float | None = None,
             window_test: bool = True, nhc: bool = True, shadows: bool = True,
             mount_states: bool = False, scale_factors: bool | None = None,
             matcher: str = "seed", ins_datum: str = "sk42", declination_deg: float | None = None,
             init=None, progress=None, odometer: OdometerData | None = None) -> Solution:
    """Navigate a vehicle with an IMU and GNSS, and optionally a road map.

    With the defaults the EKF calibrates itself (DESIGN §10; :mod:`selfnav.ins.calibrate`):
    the IMU noise from the still segments, the IMU–GNSS time offset from the gyro heading
    against the GNSS course (then refined as a state), the lever arm as three states, and the
    process-noise scale online from trusted fixes.

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
        IMU noise prior of the EKF: ``auto`` or a grade of :data:`selfnav.sensors.GRADES`;
        where the data is noisier, the measured noise wins (one warning says so).
    config : FilterConfig, optional
        A full filter configuration (then ``grade`` and the switches below are ignored; the
        noise is still checked against the data).
    lever_arm_m : (3,), optional
        IMU → antenna, body RFU, m; not given: estimated (3 states).
    nhc_lever_m : (3,), optional
        IMU → the point where the non-holonomic constraint holds (rear axle), body RFU, m.
    imu_time_offset_s : float, optional
        Added to the IMU time stamps (after the reader's own); not given: estimated.
    window_test, nhc, shadows, mount_states, scale_factors : bool
        The outlier window test, the non-holonomic constraint, the shadow dead reckoning,
        the mounting-angle states, the scale-factor states (None: the grade's default).
    matcher, ins_datum, declination_deg :
        ``method="seed"`` options (:class:`selfnav.seed004.SeedConfig`).
    init : Trajectory, Solution or path, optional
        Start from this state (:func:`initial_state`) instead of an in-motion alignment
        from GNSS; then ``gnss`` may be None (free inertial navigation with the vehicle
        constraints).
    progress : callable(fraction), optional
    odometer : OdometerData, optional
        Wheel speed on the IMU's clock (shifted with the IMU stamps): the EKF adds the
        scale-factor state and a forward-speed update; the seed loop takes its travel (13)
        from it, scaled by a factor it learns from the healthy periods.

    Returns
    -------
    Solution
        ``stats`` holds the counts the command line prints (fixes used and rejected, ...),
        ``imu_time_offset_s`` (the total offset applied to the IMU stamps, estimate included)
        and ``lever_arm_m``; ``columns`` the per-row ``sigma_h_m`` and ``gnss`` status.
    """
    if method not in METHODS:
        raise SelfnavError(f"unknown method '{method}' (use {' or '.join(METHODS)})")
    if gnss is None:
        if init is None:
            raise SelfnavError("without GNSS the navigator needs an initial state (--init FILE)")
        gnss = GnssData(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), source="none")
    else:
        _check_overlap(imu, gnss)
    graph = _as_roads(roads)
    if method == "seed":
        if graph is None:
            raise SelfnavError("--method seed needs a road map: --map ROADS (.osm/.osm.pbf)")
        cfg = SeedConfig(matcher=matcher, ins_datum=ins_datum,
                         declination=None if declination_deg is None else np.radians(declination_deg))
        odo = None if odometer is None else odometer.shifted(
            float(imu.meta.get("time_offset_s", 0.0)))
        r = run_seed(imu, gnss, graph, cfg, progress=progress, odometer=odo)
        stats = {k: v for k, v in r.stats.items() if k != "t_start"}
        # the seed loop has no covariance
        return Solution(r.trajectory, None, {}, stats, f"seed ({matcher})", r)
    cfg = config or filter_config(grade, lever_arm_m=lever_arm_m, nhc_lever_m=nhc_lever_m,
                                  window_test=window_test, nhc=nhc, shadows=shadows,
                                  mount_states=mount_states, scale_factors=scale_factors)
    applied = float(imu.meta.get("time_offset_s", 0.0))
    stats = {}
    lag = calibrate.estimate_velocity_lag(gnss) if cfg.gnss.use_velocity and len(gnss) else None
    if lag:
        gnss = calibrate.shift_velocity(gnss, lag)
        stats["gnss_velocity_lag_s"] = lag
    if imu_time_offset_s is None and len(gnss):
        est = calibrate.estimate_time_offset(imu, gnss)
        if est is not None:
            imu = imu.shifted(est[0])
            applied += est[0]
            cfg = cfg.updated(time_offset=True, time_offset_sigma=max(3 * est[1], 0.01))
            stats["imu_time_offset_prepass_s"] = est[0]
        else:
            cfg = cfg.updated(time_offset=True, time_offset_sigma=0.1)
    elif imu_time_offset_s:
        imu = imu.shifted(float(imu_time_offset_s))
        applied += float(imu_time_offset_s)
    cfg, measured, notes = calibrate.calibrated_config(cfg, imu, gnss)
    if odometer is not None:
        cfg = cfg.updated(odometer=True)
    if notes and str(grade).lower() != "auto" and config is None:
        warnings.warn(f"the IMU is noisier than the '{grade}' preset says ({'; '.join(notes)}): "
                      "using the measured noise", SelfnavWarning, stacklevel=2)
    aid = None
    if graph is not None:
        aid = EkfRoadAid(graph, gnss)
    if init is not None:
        start = initial_state(init, imu, cfg)
    else:
        # start only after a run of fixes that look healthy without an INS (an outlier window
        # at start-up must not seed the navigator hundreds of metres off); with a map, fixes
        # that also lie on its roads (a smooth drift from power-on looks healthy)
        start = (start_on_roads(imu, gnss, graph, cfg) if graph is not None
                 else robust_init(imu, gnss, cfg=cfg))
    res = ins.run_filter(imu, gnss, cfg, init=start, smooth=smooth, progress=progress,
                         road_aid=aid,
                         odometer=None if odometer is None else odometer.shifted(applied))
    # without a given lever arm, the antenna is the point the data defines (the lever arm is
    # an estimate); rows at true time (the residual time-offset state)
    point = "antenna" if cfg.states.lever_arm else "imu"
    traj = ins.output_trajectory(res, antenna=point == "antenna")
    if res.time_offset is not None:
        applied += float(res.time_offset[-1])
    stats["position_of"] = point
    stats.update(res.stats)
    stats["suspect_fixes"] = int(np.sum(res.mode == 1))
    stats["smoothed"] = bool(res.smoothed)
    stats["imu_time_offset_s"] = applied
    stats["imu_time_offset_format_s"] = float(imu.meta.get("format_time_offset_s", 0.0))
    stats["lever_arm_m"] = [float(x) for x in (res.lever_arm[-1] if res.lever_arm is not None
                                               else cfg.gnss.lever_arm_b)]
    stats["noise"] = {"grade": cfg.imu.grade, "arw_deg_per_sqrt_h": float(np.degrees(cfg.imu.arw) * 60),
                      "vrw_m_per_s_per_sqrt_h": float(cfg.imu.vrw * 60),
                      "still_s": measured.still_s, "raised": notes}
    if res.odometer_scale is not None and len(res.odometer_scale):
        stats["odometer_scale_factor"] = float(res.odometer_scale[-1])
    if res.mounting is not None and len(res.mounting):
        stats["mounting_deg"] = [float(x) for x in np.degrees(res.mounting[-1])]
    st = res.fix_log["status"]
    used = np.isin(st, ("used", "used-h", "used-v"))
    stats["rejection_rate"] = float(1.0 - used.sum() / max(1, np.sum(st != "before-init"))) if len(st) else 0.0
    if stats["rejection_rate"] > REJECTION_WARNING and len(st) >= 20:
        warnings.warn(f"{100 * stats['rejection_rate']:.0f} % of the GNSS fixes were not used: the "
                      "fixes and the IMU disagree (outliers, wrong lever arm or time base, or a "
                      "noise model too optimistic); see --fix-log", SelfnavWarning, stacklevel=2)
    cols = {"sigma_h_m": res.sigma_h, "gnss": res.gnss_status}
    return Solution(traj, res.sigma_enu, cols, stats, "ekf+map" if graph is not None else "ekf",
                    res)


def write_fix_log(path, solution: Solution):
    """One row per GNSS fix of a navigator run: ``t, status, reason, nis_h, nis_v, nis_vel,
    anchored`` (written atomically)."""
    from selfnav.io.csvio import write_csv

    log = getattr(solution.detail, "fix_log", None)
    if log is None:
        raise SelfnavError("this method keeps no fix log (use --method ekf)")
    cols = {"t": log["t"], "status": log["status"],
            "reason": np.array([str(r).replace(",", ";") or "-" for r in log["reason"]], dtype=object),
            "nis_h": log["nis_h"], "nis_v": log["nis_v"], "nis_vel": log["nis_vel"],
            "anchored": np.asarray(log["anchored"], int)}
    return write_csv(path, cols, comments=["selfnav navigate: one row per GNSS fix",
                                           "status: used, used-h (height rejected), used-v (height "
                                           "only), degraded, rejected, before-init"],
                     fmt={"t": "%.3f", "nis_h": "%.4g", "nis_v": "%.4g", "nis_vel": "%.4g",
                          "anchored": "%d"})


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
           "filter_config", "initial_state", "write_fix_log", "Solution"]
