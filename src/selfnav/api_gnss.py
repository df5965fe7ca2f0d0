"""Python API of the tightly coupled raw-GNSS navigator (issue 23, part 3; docs/gnss.md):
:func:`navigate_raw` and its per-satellite log. Re-exported by :mod:`selfnav.api`."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from selfnav.errors import InputError, SelfnavError
from selfnav.solution import Solution
from selfnav.types import Trajectory

#: What each mixture component is called in the per-satellite log.
COMPONENT_NAMES = ("los", "multipath", "reflected")


def read_raw_with_odometry(path, *, fmt: str = "auto"):
    """Pseudoranges and the car's odometry (speed, yaw rate) of a raw record that carries both
    (the smartLoc format: :func:`selfnav.io.smartloc.read_smartloc_input`)."""
    from selfnav.io.raw_readers import detect_format
    from selfnav.io.smartloc import read_smartloc_input

    path = Path(path)
    kind = detect_format(path) if fmt == "auto" else fmt
    if kind != "smartloc":
        raise InputError(path, f"this {kind} record has no odometry: navigate --gnss-raw needs the "
                               "car's speed and yaw rate in the same file (the smartLoc "
                               "format's odom3 lines) — or give the IMU: --imu FILE (stamped "
                               "in GPS time) for the tightly coupled INS")
    prs, odo = read_smartloc_input(path)
    if len(odo.t) < 2:
        raise InputError(path, "has fewer than 2 odom3 lines: no speed and yaw rate to "
                               "navigate with")
    return prs, odo


def navigate_raw(gnss_raw, *, fmt: str = "auto", smooth: bool = False,
                 drift_guard: bool = False, config=None, progress=None) -> Solution:
    """Tightly coupled navigation from raw pseudoranges and a car's speed and yaw rate
    (:func:`selfnav.gnss.tight.run_tight`): every satellite judged on its own against a
    self-tuned mixture of line-of-sight and delayed errors, no heading needed at the start.

    Parameters
    ----------
    gnss_raw : path, or a ``(Pseudoranges, Odometry)`` pair
    fmt : raw format of the file (``"auto"`` or ``"smartloc"``)
    smooth : RTS smoother (post-processing); otherwise causal
    drift_guard : the drift-hypothesis guard (:mod:`selfnav.gnss.guard`): holds the odometry's
        track when every satellite drifts together; off by default — on simulated city drives
        it holds without a drift in 18 of 24 (docs/gnss.md)
    config : :class:`selfnav.gnss.tight.TightConfig`, optional; the odometry's noise defaults to
        the file's own variances (median)
    progress : callable(done, total), optional

    Returns
    -------
    Solution
        ``method "tight"`` (``"tight+smooth"``), σ per row, ``columns`` heading_deg, speed_scale,
        yaw_rate_bias_dps, n_sats, n_delayed, clock_m; ``detail`` the pair
        (:class:`selfnav.gnss.tight.TightResult`, the pseudoranges) :func:`write_tight_log`
        reads.
    """
    from selfnav.gnss.guard import GuardConfig
    from selfnav.gnss.tight import TightConfig, run_tight

    if isinstance(gnss_raw, (str, Path)):
        prs, odo = read_raw_with_odometry(gnss_raw, fmt=fmt)
        source = str(gnss_raw)
    else:
        prs, odo = gnss_raw
        source = getattr(prs, "source", "")
    cfg = config or TightConfig()
    if config is None and getattr(odo, "variances", None) is not None and len(odo.variances):
        v = np.median(odo.variances, axis=0)
        if v[0] > 0 and v[5] > 0:
            cfg = replace(cfg, speed_sigma=float(np.sqrt(v[0])),
                          yaw_rate_sigma=float(np.sqrt(v[5])))
    if drift_guard and cfg.guard is None:
        cfg = replace(cfg, guard=GuardConfig())
    try:
        r = run_tight(prs, odo, cfg, smooth=smooth, progress=progress)
    except np.linalg.LinAlgError as e:
        raise SelfnavError(f"{source}: the tightly coupled filter failed numerically ({e})") \
            from None
    n = len(r.t)
    traj = Trajectory(r.t, r.lat, r.lon, r.h, np.full((n, 3), np.nan),
                      np.full((n, 3, 3), np.nan), source=f"selfnav tight {source}")
    sig = np.column_stack([r.sigma_e, r.sigma_n, np.full(n, np.nan)])
    cols = {"sigma_h_m": r.sigma_h, "heading_deg": np.degrees(r.heading),
            "speed_scale": r.scale, "yaw_rate_bias_dps": np.degrees(r.yaw_bias),
            "n_sats": r.n_sats, "n_delayed": r.n_reflected, "clock_m": r.clock}
    stats = {**r.stats, "source": source, "smoothed": r.smoothed,
             "median_sigma_h_m": float(np.median(r.sigma_h))}
    return Solution(traj, sig, cols, stats, "tight+smooth" if smooth else "tight", (r, prs))


def navigate_raw_imu(gnss_raw, imu, *, grade: str = "auto", platform: str = "auto",
                     fmt: str = "auto", config=None, progress=None) -> Solution:
    """Tightly coupled INS/GNSS (:func:`selfnav.ins.tight.run_tight_ins`): the strapdown INS
    updated by each satellite's pseudorange and range rate, causal.

    Parameters
    ----------
    gnss_raw : path or :class:`selfnav.io.gnss_raw.RawGnss` (observations with ephemerides:
        RINEX with its navigation records, UBX, PSINS ``.mat``)
    imu : path or :class:`selfnav.types.ImuData`, stamped in GNSS (GPS) time
    grade : the IMU's grade; ``"auto"``: tactical (the start at rest gyrocompasses where the
        grade's gyro bias allows, else it waits for motion)
    platform : ``"car"``: a car's motion constraints (non-holonomic, level road); ``"auto"``
        and the others: none (this path does not yet tell a car from the data)
    config : :class:`selfnav.ins.tight.TightInsConfig`, optional (its ``grade`` is replaced)

    Returns
    -------
    Solution
        ``method "tight-ins"``, σ per row, columns ``sigma_h_m, n_sats, n_excluded, clock_m,
        clock_drift_mps``; ``detail`` the :class:`selfnav.ins.tight.TightInsResult`.
    """
    from selfnav.io.raw_readers import read_gnss_raw
    from selfnav.io.readers import read_imu
    from selfnav.ins.tight import TightInsConfig, run_tight_ins

    raw = read_gnss_raw(gnss_raw, fmt=fmt) if isinstance(gnss_raw, (str, Path)) else gnss_raw
    data = read_imu(imu) if isinstance(imu, (str, Path)) else imu
    g = "tactical" if str(grade).lower() == "auto" else grade
    from selfnav.ins.config import platform_settings

    cfg = replace(config or TightInsConfig(), grade=g,
                  platform=platform_settings(platform)["platform"])
    try:
        r = run_tight_ins(data, raw, cfg, progress=progress)
    except np.linalg.LinAlgError as e:
        raise SelfnavError(f"{raw.source}: the tightly coupled filter failed numerically ({e})") \
            from None
    traj = Trajectory(r.t, r.lat, r.lon, r.h, r.velocity_n, r.C_nb,
                      source=f"selfnav tight-ins {raw.source}")
    sig_h = np.sqrt((r.sigma_enu[:, 0] ** 2 + r.sigma_enu[:, 1] ** 2) / 2.0)
    cols = {"sigma_h_m": sig_h, "n_sats": r.n_used, "n_excluded": r.n_excluded,
            "clock_m": r.clock_m, "clock_drift_mps": r.drift_mps}
    stats = {**r.stats, "source": str(raw.source), "median_sigma_h_m":
             float(np.median(sig_h)) if len(sig_h) else float("nan")}
    return Solution(traj, r.sigma_enu, cols, stats, "tight-ins", r)


def write_tight_log(path, solution: Solution):
    """One row per pseudorange of a :func:`navigate_raw` solution: ``t, system, sat, cn0_dbhz,
    elevation_deg, residual_m`` (at the output state), ``component`` (los, multipath,
    reflected; ``-`` where the epoch had no output) — written atomically. Of a
    :func:`navigate_raw_imu` solution: ``t, sat, z`` (the innovation over its σ),
    ``status`` (used / excluded), ``clock_jump_m``."""
    from selfnav.io.csvio import write_csv
    from selfnav.io.smartloc import SYSTEM_NAMES

    if solution.method == "tight-ins":
        rows = [(d.t, name, z, "used" if name in d.used else "excluded", d.clock_jump_m)
                for d in solution.detail.decisions for name, z in d.z.items()]
        cols = list(zip(*rows)) if rows else [[], [], [], [], []]
        return write_csv(path, {"t": np.asarray(cols[0], float),
                                "sat": np.asarray(cols[1], dtype=object),
                                "z": np.asarray(cols[2], float),
                                "status": np.asarray(cols[3], dtype=object),
                                "clock_jump_m": np.asarray(cols[4], float)},
                         fmt={"t": "%.3f", "z": "%.2f", "clock_jump_m": "%.3f"})
    r, prs = solution.detail
    comp = np.array([COMPONENT_NAMES[c] if 0 <= c < len(COMPONENT_NAMES) else
                     (f"delayed{c}" if c > 0 else "-") for c in r.obs_component.tolist()],
                    dtype=object)
    system = np.array([SYSTEM_NAMES.get(int(s), str(int(s))) for s in prs.system.tolist()],
                      dtype=object)
    order = np.argsort(prs.t, kind="stable")
    return write_csv(path, {"t": prs.t[order], "system": system[order],
                            "sat": prs.sat_id[order].astype(int),
                            "cn0_dbhz": prs.cn0[order],
                            "elevation_deg": np.degrees(prs.elevation[order]),
                            "residual_m": r.obs_residual[order], "component": comp[order]},
                     fmt={"t": "%.3f", "cn0_dbhz": "%.1f", "elevation_deg": "%.2f",
                          "residual_m": "%.3f"})


#: Files ``selfnav simulate city`` writes (the smartLoc names, for :func:`navigate_raw`).
CITY_FILES = ("city_Input.txt", "city_GT.txt")


def simulate_city_files(out_dir, *, seed: int = 0, duration: float | None = None):
    """A SIMULATED city drive (:func:`selfnav.sim.urban.simulate_urban_drive`) written into the
    folder ``out_dir`` as ``city_Input.txt`` (pseudoranges + odometry) and ``city_GT.txt``
    (truth), smartLoc format, as one set. Returns ``(Pseudoranges, Odometry, truth, paths)``."""
    from selfnav.io.output import atomic_folder
    from selfnav.io.smartloc import write_smartloc
    from selfnav.sim.urban import UrbanConfig, simulate_urban_drive

    cfg = UrbanConfig() if duration is None else replace(UrbanConfig(), duration=float(duration))
    prs, odo, truth = simulate_urban_drive(seed, cfg)
    with atomic_folder(out_dir, owned=CITY_FILES) as tmp:
        write_smartloc(tmp / CITY_FILES[0], tmp / CITY_FILES[1], prs, odo, truth)
    return prs, odo, truth, [Path(out_dir) / f for f in CITY_FILES]


__all__ = ["navigate_raw", "write_tight_log", "read_raw_with_odometry", "simulate_city_files"]
