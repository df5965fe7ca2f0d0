"""Built-in simulation scenarios and TOML scenario files (issue 3; DESIGN §6).

A scenario is a dict (or a TOML file) with sections::

    [scenario]  kind = "static" | "multiposition" | "ship" | "aircraft" | "car" |
                       "pedestrian" | "rover" | "boat" | "drone"
                duration = 600.0   dt = 0.01   lat_deg, lon_deg, h_m (start)
                truth_hz = 10      (0: the IMU rate)
                start = "rest" | "moving"   (the platforms of :mod:`selfnav.sim.platforms`)
    [motion]    keyword arguments of the trajectory generator of that kind
    [imu]       grade = "navigation" | "tactical" | "industrial" | "consumer" | "perfect"
    [gnss]      enabled, rate_hz, sigma_m, sigma_v_m, datum, spike_rate, spike_sigma_m,
                correlated_sigma_m, correlation_s (a slowly drifting error, stand-alone GPS),
                outages = [[t0, t1], ...],
                outliers = "seed004" | [{start, duration, sigma_m, kind, tau}, ...]
    [mag]       enabled, noise_nt, hard_iron_nt = [x, y, z], field_model
    [odometer]  enabled, scale_factor_sigma, quantum_mps, noise_mps, rate_hz (car: wheel speed
                written to ``odometer.csv``, :class:`selfnav.sensors.OdometerModel`)

Randomness: one ``numpy.random.SeedSequence(seed)`` spawns independent streams for the motion,
the IMU errors, the GNSS and the magnetometer (and one more for the odometer), so the same seed
gives the same files and changing one part (say the GNSS σ) leaves the others' random numbers
alone.
"""
from __future__ import annotations

import copy
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from selfnav import attitude as att
from selfnav import sensors
from selfnav.errors import InputError, SelfnavError
from selfnav.types import ImuData, OdometerData, Trajectory

BUILTIN = ("static", "multiposition", "ship", "aircraft", "car", "pedestrian", "rover", "boat",
           "drone")
#: Kinds that move (an IMU interval above MAX_MOVING_DT cannot follow them).
MOVING = ("ship", "aircraft", "car", "pedestrian", "rover", "boat", "drone")
#: The platforms of issue 20 and their start (``[scenario] start``, ``--start``).
PLATFORMS = ("pedestrian", "rover", "boat", "drone")
STARTS = ("rest", "moving")

DEFAULTS = {
    "static": {"scenario": {"duration": 600.0, "lat_deg": 50.45, "lon_deg": 30.5236, "h_m": 180.0},
               "motion": {"roll_deg": 0.0, "pitch_deg": 0.0, "heading_deg": 0.0},
               "imu": {"grade": "tactical"}, "gnss": {"enabled": True, "sigma_m": 3.0}},
    "multiposition": {"scenario": {"duration": 720.0, "lat_deg": 50.45, "lon_deg": 30.5236,
                                   "h_m": 180.0},
                      "motion": {"headings_deg": [float(a) for a in range(0, 360, 30)],
                                 "roll_deg": 0.0, "pitch_deg": 0.0},
                      "imu": {"grade": "tactical"}, "gnss": {"enabled": False}},
    "ship": {"scenario": {"duration": 1800.0, "lat_deg": 45.0, "lon_deg": 30.0, "h_m": 0.0},
             "imu": {"grade": "tactical"}, "gnss": {"enabled": True, "sigma_m": 10.0},
             "mag": {"enabled": True}},
    "aircraft": {"scenario": {"duration": 900.0, "lat_deg": 50.45, "lon_deg": 30.5236,
                              "h_m": 500.0},
                 "imu": {"grade": "tactical"}, "gnss": {"enabled": True, "sigma_m": 5.0}},
    "car": {"scenario": {"duration": 600.0, "map": "kotka_karhula", "h_m": 20.0},
            "imu": {"grade": "industrial"},
            "gnss": {"enabled": True, "sigma_m": 10.0, "outliers": "seed004",
                     "spike_rate": 0.005},
            "mag": {"enabled": True}},
    # issue 20: the platforms (selfnav.sim.platforms); GNSS with a drifting part where the
    # receiver is stand-alone
    "pedestrian": {"scenario": {"duration": 300.0, "lat_deg": 48.0, "lon_deg": 11.0,
                                "h_m": 500.0, "start": "rest"},
                   "imu": {"grade": "consumer"},
                   "gnss": {"enabled": True, "rate_hz": 1.0, "sigma_m": 1.5,
                            "correlated_sigma_m": 1.0, "correlation_s": 30.0},
                   "mag": {"enabled": True}},
    "rover": {"scenario": {"duration": 600.0, "dt": 0.005, "lat_deg": 40.1,
                           "lon_deg": -105.15, "h_m": 1600.0, "start": "rest"},
              "imu": {"grade": "consumer"},
              "gnss": {"enabled": True, "rate_hz": 20.0, "sigma_m": 0.5,
                       "correlated_sigma_m": 1.5, "correlation_s": 60.0},
              "mag": {"enabled": True}},
    "boat": {"scenario": {"duration": 900.0, "lat_deg": 59.4, "lon_deg": 24.7, "h_m": 0.0,
                          "start": "rest"},
             "imu": {"grade": "industrial"},
             "gnss": {"enabled": True, "rate_hz": 1.0, "sigma_m": 2.0,
                      "correlated_sigma_m": 1.5, "correlation_s": 60.0},
             "mag": {"enabled": True}},
    "drone": {"scenario": {"duration": 300.0, "dt": 0.005, "lat_deg": 47.4, "lon_deg": 8.55,
                           "h_m": 450.0, "start": "rest"},
              "imu": {"grade": "consumer"},
              "gnss": {"enabled": True, "rate_hz": 5.0, "sigma_m": 0.7,
                       "correlated_sigma_m": 1.0, "correlation_s": 60.0},
              "mag": {"enabled": True}},
}
COMMON = {"scenario": {"dt": 0.01, "truth_hz": 10.0}, "motion": {},
          "gnss": {"rate_hz": 1.0, "sigma_v_m": None, "datum": "wgs84", "outages": [],
                   "outliers": [], "spike_rate": 0.0, "spike_sigma_m": 50.0,
                   "correlated_sigma_m": 0.0, "correlation_s": 60.0},
          "mag": {"enabled": False, "noise_nt": 100.0, "hard_iron_nt": None, "field_model": "auto"},
          "odometer": {"enabled": False, "scale_factor_sigma": 0.005, "quantum_mps": 0.01,
                       "noise_mps": 0.0, "rate_hz": 10.0}}


@dataclass
class Simulation:
    """What one simulated run produced (all simulated, labelled so in ``source``).

    truth : Trajectory (IMU time base, thinned to ``truth_hz``; first sample the initial state)
    imu : ImuData with sensor errors (``mag_b`` in nT when the magnetometer is on)
    imu_exact : error-free rates (same times)
    gnss : :class:`selfnav.sensors.GnssFixes` or None
    map_path : the OpenStreetMap file driven on (car) or None
    config : the full scenario dict after defaults
    route : the :class:`~selfnav.sim.car.CarRoute` driven (car) or None
    odometer : :class:`~selfnav.types.OdometerData` (``[odometer] enabled``) or None; its
        ``meta['scale_factor']`` is the drive's true scale-factor error
    imu_errors : the IMU errors drawn, ``{"gyro": ..., "accel": ...}`` as
        :meth:`selfnav.sensors.ImuErrorModel.apply` returns them (the truth a filter's sensor
        states are checked against)
    """

    name: str
    truth: Trajectory
    imu: ImuData
    imu_exact: ImuData
    gnss: object = None
    map_path: Path | None = None
    config: dict = field(default_factory=dict)
    route: object = None
    odometer: object = None
    imu_errors: dict | None = None


def _merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in (over or {}).items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def load_scenario(spec) -> dict:
    """A built-in name, a TOML file path or a dict -> the full scenario dict (defaults filled)."""
    if isinstance(spec, dict):
        cfg = spec
    elif str(spec) in BUILTIN:
        cfg = {"scenario": {"kind": str(spec)}}
    else:
        p = Path(spec)
        if not p.is_file():
            raise InputError(p, f"no such scenario file; built-in scenarios: {', '.join(BUILTIN)}")
        try:
            cfg = tomllib.loads(p.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
            raise InputError(p, f"is not a valid TOML scenario ({e})") from None
        cfg.setdefault("scenario", {}).setdefault("name", p.stem)
    kind = cfg.get("scenario", {}).get("kind")
    if kind not in BUILTIN:
        raise SelfnavError(f"scenario kind '{kind}' unknown: use one of {', '.join(BUILTIN)}")
    full = _merge(_merge(COMMON, DEFAULTS[kind]), cfg)
    full["scenario"].setdefault("name", kind)
    return full


def _static_truth(t, lat, lon, h, C_nb):
    n = len(t)
    C = np.broadcast_to(C_nb, (n, 3, 3)) if np.ndim(C_nb) == 2 else C_nb
    return Trajectory(t, np.full(n, lat), np.full(n, lon), np.full(n, h), np.zeros((n, 3)),
                      np.array(C), source="simulated static")


def _motion(cfg, rng_seed, progress):
    """Trajectory and error-free IMU of a scenario; returns (truth, imu, map_path, route)."""
    from selfnav.sim import static as st
    from selfnav.sim.inverse import imu_from_trajectory

    sc, mo = cfg["scenario"], cfg["motion"]
    kind, dt, T = sc["kind"], float(sc["dt"]), float(sc["duration"])
    lat, lon = np.radians(sc.get("lat_deg", 0.0)), np.radians(sc.get("lon_deg", 0.0))
    h = float(sc.get("h_m", 0.0))
    progress("trajectory")
    if kind == "static":
        r, p, hd = (np.radians(mo.get(k, 0.0)) for k in ("roll_deg", "pitch_deg", "heading_deg"))
        imu = st.static_imu(lat, T, dt, roll=r, pitch=p, heading=hd, h=h)
        t = np.concatenate([[0.0], imu.t])
        return _static_truth(t, lat, lon, h, att.dcm_nb_from_euler(r, p, hd)), imu, None, None
    if kind == "multiposition":
        heads = np.radians(mo["headings_deg"])
        dwell = T / len(heads)
        r, p = np.radians(mo.get("roll_deg", 0.0)), np.radians(mo.get("pitch_deg", 0.0))
        imu = st.multiposition_imu(lat, heads, dwell, dt, roll=r, pitch=p, h=h)
        C = att.dcm_nb_from_euler(r, p, heads[imu.position])
        truth = _static_truth(imu.t, lat, lon, h, C)
        return truth, imu, None, None
    map_path, route = None, None
    if kind == "ship":
        from selfnav.sim.ship import ship_trajectory

        traj = ship_trajectory(T, dt, lat, lon, h=h, seed=rng_seed, **mo)
    elif kind == "aircraft":
        from selfnav.sim.aircraft import aircraft_trajectory

        traj = aircraft_trajectory(T, dt, lat, lon, h, seed=rng_seed, **mo)
    elif kind in PLATFORMS:
        from selfnav.sim.platforms import GENERATORS

        traj = GENERATORS[kind](T, dt, lat, lon, h, start=str(sc.get("start", "rest")),
                                seed=rng_seed, **mo)
    else:  # car
        from selfnav.roads.graph import packaged_map, read_roads
        from selfnav.sim.car import car_route

        m = str(sc.get("map", "kotka_karhula"))
        map_path = packaged_map(m) if m in ("kotka_karhula", "helsinki_centre") else Path(m)
        graph = read_roads(map_path)
        traj, route = car_route(graph, duration=T, dt=dt, seed=rng_seed, h0=h, **mo)
    progress("inverse strapdown")
    imu, truth = imu_from_trajectory(traj, dt, return_truth=True)
    truth.source = traj.source
    return truth, imu, map_path, route


def _gnss_model(g, truth, rng) -> sensors.GnssModel:
    out = g.get("outliers") or []
    if out == "seed004":  # one 200 m σ window per 20 min, anywhere (DESIGN §5)
        n = max(1, int(round((truth.t[-1] - truth.t[0]) / 1200.0)))
        out = sensors.random_outlier_windows(truth.t[0], truth.t[-1], n, rng)
    elif isinstance(out, str):
        raise SelfnavError(f"gnss.outliers = '{out}': use \"seed004\" or a list of windows")
    else:
        out = [sensors.OutlierWindow(float(w["start"]), float(w["duration"]),
                                     float(w.get("sigma_m", 200.0)), str(w.get("kind", "white")),
                                     float(w.get("tau", 60.0))) for w in out]
    s = float(g["sigma_m"])
    return sensors.GnssModel(rate_hz=float(g["rate_hz"]), sigma_h=s,
                             sigma_corr_h=float(g.get("correlated_sigma_m") or 0.0),
                             tau_corr=float(g.get("correlation_s") or 60.0),
                             sigma_v=float(g["sigma_v_m"] if g["sigma_v_m"] is not None else 1.5 * s),
                             outages=[tuple(map(float, o)) for o in g["outages"]], outliers=out,
                             spike_rate=float(g["spike_rate"]),
                             spike_sigma=float(g["spike_sigma_m"]), datum=str(g["datum"]))


#: Coarsest IMU sample interval that still follows a moving vehicle, s.
MAX_MOVING_DT = 0.1


def check_scenario(cfg: dict) -> None:
    """Refuse, one line each, scenario values no sensor or place has: a non-positive length,
    sample interval, rate or σ, an IMU interval too coarse for a moving vehicle, fewer than
    100 samples, a latitude outside ±90° or a longitude outside −180..360°."""
    sc, g = cfg["scenario"], cfg.get("gnss", {})
    T, dt = float(sc["duration"]), float(sc["dt"])
    if not T > 0 or not dt > 0:
        raise SelfnavError(f"scenario duration and dt must be positive (got {T:g} s, {dt:g} s)")
    if sc.get("start", "rest") not in STARTS:
        raise SelfnavError(f"scenario start = '{sc['start']}': use rest or moving")
    if sc["kind"] in MOVING and dt > MAX_MOVING_DT:
        raise SelfnavError(f"dt = {dt:g} s ({1 / dt:.3g} Hz) cannot follow a moving {sc['kind']}: "
                           f"use an IMU interval of at most {MAX_MOVING_DT:g} s")
    if T / dt < 100:
        raise SelfnavError(f"duration {T:g} s at dt = {dt:g} s gives {T / dt:.0f} samples: at "
                           "least 100 are needed")
    lat, lon = float(sc.get("lat_deg", 0.0)), float(sc.get("lon_deg", 0.0))
    if not -90.0 <= lat <= 90.0:
        raise SelfnavError(f"scenario lat_deg = {lat:g} is not a latitude (-90..90)")
    if not -180.0 <= lon <= 360.0:
        raise SelfnavError(f"scenario lon_deg = {lon:g} is not a longitude (-180..360)")
    for key in ("sigma_m", "rate_hz"):
        v = g.get(key)
        if v is not None and not float(v) > 0:
            raise SelfnavError(f"gnss.{key} = {v} must be positive")


def simulate(spec, *, seed: int = 0, grade: str | None = None, duration: float | None = None,
             dt: float | None = None, start: str | None = None, progress=None) -> Simulation:
    """Run a scenario: trajectory, exact inverse strapdown, IMU/GNSS/magnetometer errors.

    Parameters
    ----------
    spec : built-in name, TOML path or dict (see the module docstring)
    seed : int
    grade : IMU grade overriding the scenario's
    duration, dt : s, overriding the scenario's
    start : ``"rest"`` or ``"moving"``, overriding the scenario's (platforms)
    progress : callable(str), optional, told the name of each stage
    """
    progress = progress or (lambda stage: None)
    cfg = load_scenario(spec)
    if grade is not None:
        cfg["imu"]["grade"] = grade
    if duration is not None:
        cfg["scenario"]["duration"] = float(duration)
    if dt is not None:
        cfg["scenario"]["dt"] = float(dt)
    if start is not None:
        if cfg["scenario"]["kind"] not in PLATFORMS:
            raise SelfnavError(f"--start is for the platforms ({', '.join(PLATFORMS)}), not "
                               f"'{cfg['scenario']['kind']}'")
        cfg["scenario"]["start"] = str(start)
    check_scenario(cfg)
    model = sensors.imu_grade(cfg["imu"]["grade"])   # fail early on a bad grade
    ss = np.random.SeedSequence(int(seed))
    s_motion, s_imu, s_gnss, s_mag = ss.spawn(4)
    motion_seed = int(s_motion.generate_state(1)[0])
    truth, exact, map_path, route = _motion(cfg, motion_seed, progress)
    progress("sensor errors")
    n = len(exact)
    t_err = exact.t if exact.position is None else exact.t[0] + exact.dt * np.arange(n)
    w, f, imu_errors = model.apply(t_err, exact.omega_ib_b, exact.f_ib_b,
                                   np.random.default_rng(s_imu), return_errors=True)
    imu = ImuData(exact.t, w, f, None, exact.position,
                  source=f"simulated {cfg['scenario']['name']}, IMU grade {model.name}",
                  meta={"simulated": True, "seed": seed, "grade": cfg["imu"]["grade"]})
    if cfg["mag"]["enabled"]:
        progress("magnetometer")
        rng = np.random.default_rng(s_mag)
        mg = sensors.MagnetometerModel.typical_car(rng)
        mg.noise = float(cfg["mag"]["noise_nt"])
        mg.field_model = str(cfg["mag"]["field_model"])
        if cfg["mag"]["hard_iron_nt"] is not None:
            mg.hard_iron = np.asarray(cfg["mag"]["hard_iron_nt"], dtype=float)
        kin = truth if len(truth) == n else None
        C = kin.C_nb if kin is not None else _interp_attitude(truth, exact.t)
        lat = np.interp(exact.t, truth.t, truth.lat)
        lon = np.interp(exact.t, truth.t, np.unwrap(truth.lon))
        hh = np.interp(exact.t, truth.t, truth.h)
        imu.mag_b = mg.measure(lat, lon, hh, C, rng)
        imu.meta["mag_field_model"] = mg.field_model
    gnss = None
    if cfg["gnss"]["enabled"]:
        progress("GNSS")
        rng = np.random.default_rng(s_gnss)
        gnss = _gnss_model(cfg["gnss"], truth, rng).simulate(truth, rng)
    odo = None
    if cfg["odometer"]["enabled"]:
        progress("odometer")
        odo = _odometer(cfg["odometer"], truth, ss.spawn(1)[0])
    th = float(cfg["scenario"].get("truth_hz") or 0.0)
    if th > 0 and len(truth) > 2:
        step = max(1, int(round(1.0 / (th * exact.dt))))
        keep = np.zeros(len(truth), bool)
        keep[::step] = True
        keep[-1] = True
        truth = Trajectory(truth.t[keep], truth.lat[keep], truth.lon[keep], truth.h[keep],
                           truth.velocity_n[keep], truth.C_nb[keep], truth.source)
    return Simulation(cfg["scenario"]["name"], truth, imu, exact, gnss, map_path, cfg, route, odo,
                      imu_errors)


def _odometer(o, truth, seed_seq) -> OdometerData:
    """Wheel speed of the truth's forward velocity (body y; the car's IMU sits at the rear
    axle) through :class:`~selfnav.sensors.OdometerModel`."""
    model = sensors.OdometerModel(float(o["scale_factor_sigma"]), float(o["quantum_mps"]),
                                  float(o["noise_mps"]), float(o["rate_hz"]))
    v_fwd = np.einsum("nj,nj->n", truth.C_nb[:, 1, :], truth.velocity_n)
    t, v, k = model.simulate(truth.t, v_fwd, np.random.default_rng(seed_seq))
    return OdometerData(t, v, source="simulated odometer", meta={"scale_factor": k})


def _interp_attitude(truth, t):
    """Attitude at ``t`` from a truth with one more sample (the initial state)."""
    k = np.clip(np.searchsorted(truth.t, t - 1e-9), 0, len(truth) - 1)
    return truth.C_nb[k]


def write_simulation(sim: Simulation, out_dir, *, imu_axes=None, imu_mount=None) -> list[Path]:
    """Write ``imu.csv``, ``truth.csv``, ``gnss.csv``, ``gnss_errors.csv``, ``mag.csv``,
    ``odometer.csv`` (``t, speed_mps``, when simulated) and the map (DESIGN §6 columns), each
    with a ``# simulated ...`` comment line; returns the paths.

    The files are written as one set (:func:`selfnav.io.output.atomic_folder`): into a folder
    that holds an older simulation, an interrupt leaves the old set or the new one, never a
    mix; other files in the folder are left alone.

    ``imu_axes``, ``imu_mount`` (:func:`selfnav.axes.imu_frame`): write ``imu.csv`` and
    ``mag.csv`` as a sensor in that axes convention and mounting would give them
    (:func:`selfnav.axes.from_vehicle`; a comment line says which); ``read_imu(...,
    axes=..., mount=...)`` reads them back into the vehicle's RFU frame (exactly, for axes
    alone: a signed permutation of the same digits)."""
    from selfnav.io.output import atomic_folder

    out = Path(out_dir)
    frame = None
    if imu_axes is not None or imu_mount is not None:
        from selfnav.axes import DETECT, AxesError, imu_frame

        frame = imu_frame(imu_axes, imu_mount)
        if frame == DETECT:
            raise AxesError("the simulated IMU is written in given axes, not 'detect'")
    with atomic_folder(out, owned=SIMULATION_FILES) as tmp:
        names = _write_simulation_files(sim, tmp, frame)
    return [out / n for n in names]


#: The files :func:`write_simulation` may write (an older set's files are replaced as a whole).
SIMULATION_FILES = ("imu.csv", "mag.csv", "truth.csv", "gnss.csv", "gnss_errors.csv",
                    "odometer.csv", "kotka_karhula.osm.pbf", "helsinki_centre.osm.pbf",
                    "MAP_ATTRIBUTION.txt")


def _write_simulation_files(sim: Simulation, out: Path, frame=None) -> list[str]:
    """Write the files of :func:`write_simulation` into the folder ``out``; their names."""
    from selfnav.io.csvio import write_csv
    from selfnav.io.output import atomic_copy, atomic_write_text
    from selfnav.io.trajectory import write_truth

    sc = sim.config["scenario"]
    tag = (f"simulated by selfnav: scenario {sc['name']} ({sc['kind']}), seed "
           f"{sim.imu.meta.get('seed')}, IMU grade {sim.config['imu']['grade']}")
    paths = []
    imu = sim.imu
    axes_note = "body RFU"
    if frame is not None and not frame.is_identity:
        from selfnav.axes import from_vehicle

        imu = from_vehicle(imu, frame)
        axes_note = (f"sensor {frame.describe()} (read with --imu-axes {frame.axes.letters}"
                     + (" --imu-mount " + ",".join(f"{v:g}" for v in frame.mount_deg)
                        if frame.has_mount else "") + "; the truth is the vehicle's RFU)")
    cols = {"t": imu.t, "wx": imu.omega_ib_b[:, 0], "wy": imu.omega_ib_b[:, 1],
            "wz": imu.omega_ib_b[:, 2], "fx": imu.f_ib_b[:, 0], "fy": imu.f_ib_b[:, 1],
            "fz": imu.f_ib_b[:, 2]}
    if imu.mag_b is not None:
        cols.update({"mx": imu.mag_b[:, 0], "my": imu.mag_b[:, 1], "mz": imu.mag_b[:, 2]})
    if imu.position is not None:
        cols["position"] = imu.position
    fmt = {"t": "%.6f", "position": "%d"}
    paths.append(write_csv(out / "imu.csv", cols, comments=[
        tag, f"{axes_note}; rad/s and m/s^2, mean over the interval ending at t"
        + ("; mx,my,mz magnetometer in nT" if imu.mag_b is not None else "")], fmt=fmt))
    if imu.mag_b is not None:
        paths.append(write_csv(out / "mag.csv", {"t": imu.t, "mx": imu.mag_b[:, 0],
                                                 "my": imu.mag_b[:, 1], "mz": imu.mag_b[:, 2]},
                               comments=[tag, f"magnetometer, {axes_note}, nT (hard and soft iron, "
                                         f"field model {imu.meta.get('mag_field_model')})"],
                               fmt={"t": "%.6f"}))
    paths.append(write_truth(out / "truth.csv", sim.truth, comments=[tag]))
    if sim.odometer is not None:
        o = sim.config["odometer"]
        paths.append(write_csv(out / "odometer.csv", {"t": sim.odometer.t,
                                                      "speed_mps": sim.odometer.speed_mps},
                               comments=[tag, "wheel speed (forward, rear axle), m/s, on the IMU "
                                         f"clock; scale-factor σ {o['scale_factor_sigma']:g} (this "
                                         f"drive: {sim.odometer.meta['scale_factor']:+.5f}), quantum "
                                         f"{o['quantum_mps']:g} m/s"],
                               fmt={"t": "%.6f", "speed_mps": "%.4f"}))
    g = sim.gnss
    if g is not None:
        paths.append(write_csv(out / "gnss.csv", {
            "t": g.t, "lat_deg": np.degrees(g.lat), "lon_deg": np.degrees(g.lon), "h_m": g.h,
            "sigma_m": g.sigma_m}, comments=[tag, f"GNSS fixes, datum {g.datum}; outliers are "
                                             "NOT flagged here (see gnss_errors.csv)"],
            fmt={"t": "%.6f", "lat_deg": "%.10f", "lon_deg": "%.10f", "h_m": "%.4f"}))
        win = "; ".join(f"{w.start:.1f}-{w.end:.1f} s {w.kind} {w.sigma:g} m" for w in g.windows)
        paths.append(write_csv(out / "gnss_errors.csv", {
            "t": g.t, "err_e_m": g.error_enu[:, 0], "err_n_m": g.error_enu[:, 1],
            "err_u_m": g.error_enu[:, 2], "outlier": g.outlier.astype(int),
            "spike": g.spike.astype(int)}, comments=[tag, "the truth about the GNSS errors; "
                                                     f"outlier windows: {win or 'none'}"],
            fmt={"t": "%.6f", "outlier": "%d", "spike": "%d"}))
    if sim.map_path is not None:
        dst = out / Path(sim.map_path).name
        paths.append(atomic_copy(sim.map_path, dst))
        paths.append(atomic_write_text(
            out / "MAP_ATTRIBUTION.txt",
            f"{dst.name}: map data (c) OpenStreetMap contributors, Open Database License (ODbL) "
            "1.0, https://www.openstreetmap.org/copyright\n"))
    return [Path(p).name for p in paths]
