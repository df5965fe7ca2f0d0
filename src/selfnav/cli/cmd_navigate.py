"""``selfnav navigate``: INS/GNSS navigation (DESIGN §5, §6) — the EKF (+ RTS smoother)."""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from selfnav.cli.common import emit_json
from selfnav.errors import SelfnavError


def _vec3(text: str, name: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise SelfnavError(f"{name} must be three numbers separated by commas, got '{text}'") from None
    if v.shape != (3,):
        raise SelfnavError(f"{name} must be three numbers separated by commas, got '{text}'")
    return v


def read_imu_any(path: Path, fmt: str, time_offset: float = 0.0):
    """IMU in any supported format (csv, psins, rtklibexplorer, kfgins)."""
    from selfnav.io import read_imu

    if fmt == "rtklibexplorer":
        from selfnav.io.rtklibexplorer import read_rtklibexplorer_imu

        # upstream's own offset (−0.125 s) plus the user's
        return read_rtklibexplorer_imu(path, t_offset=-0.125 + time_offset)
    if fmt == "kfgins":
        try:
            from selfnav.io.kfgins import read_kfgins_imu
        except ImportError:
            raise SelfnavError("the KF-GINS reader is not available in this build") from None
        imu = read_kfgins_imu(path)
    else:
        imu = read_imu(path, fmt)
    if time_offset:
        imu.t = imu.t + time_offset
    return imu


def write_solution(path: Path, res, *, datum: str = "wgs84", comments=()):
    """SOL file: DESIGN §6 columns plus 1σ position, m."""
    from selfnav import attitude as att
    from selfnav.io import write_csv

    tr = res.trajectory
    lat, lon, h = tr.lat, tr.lon, tr.h
    if datum.lower() != "wgs84":
        from selfnav import datum as dm

        lat, lon, h = dm.convert(lat, lon, h, "wgs84", datum)
    roll, pitch, hdg = att.euler_from_dcm_nb(tr.C_nb)
    cols = {"t": tr.t, "lat_deg": np.degrees(lat), "lon_deg": np.degrees(lon), "h_m": h,
            "ve": tr.velocity_n[:, 0], "vn": tr.velocity_n[:, 1], "vu": tr.velocity_n[:, 2],
            "roll_deg": np.degrees(roll), "pitch_deg": np.degrees(pitch),
            "heading_deg": np.degrees(hdg), "sigma_e_m": res.sigma_enu[:, 0],
            "sigma_n_m": res.sigma_enu[:, 1], "sigma_u_m": res.sigma_enu[:, 2]}
    fmt = {"t": "%.4f", "lat_deg": "%.9f", "lon_deg": "%.9f", "h_m": "%.3f"}
    return write_csv(path, cols, comments=list(comments), fmt=fmt)


def _run_seed(data, g, graph, mag_path, matcher, ins_datum, declination_deg, progress):
    """``--method seed``: :func:`selfnav.seedloop.run_seed`, packed like an EKF result."""
    from types import SimpleNamespace

    from selfnav.seedloop import SeedConfig, run_seed

    if mag_path is not None:
        from selfnav.io import read_table

        tab = read_table(mag_path, ("t", "mx", "my", "mz"))
        m = np.column_stack([np.interp(data.t, tab["t"], tab[c]) for c in ("mx", "my", "mz")])
        data.mag_b = m
    cfg = SeedConfig(matcher=matcher, ins_datum=ins_datum,
                     declination=None if declination_deg is None else np.radians(declination_deg))
    r = run_seed(data, g, graph, cfg, progress=progress)
    n = len(r.trajectory.t)
    # the seed loop has no covariance: σ columns are NaN
    stats = dict(r.stats)
    stats.pop("t_start", None)
    return SimpleNamespace(trajectory=r.trajectory, sigma_enu=np.full((n, 3), np.nan),
                           mode=np.zeros(n, int), stats=stats)


def register(app: typer.Typer) -> None:
    @app.command("navigate")
    def navigate_cmd(
        imu: Path = typer.Option(..., "--imu", help="IMU file."),
        gnss: Path = typer.Option(..., "--gnss", help="GNSS fixes (csv, RTKLIB .pos, NMEA)."),
        out: Path = typer.Option(..., "--out", help="Solution CSV (written atomically)."),
        method: str = typer.Option("ekf", help="ekf (error-state Kalman filter) or seed."),
        map_: Optional[Path] = typer.Option(None, "--map", help="Road map (.osm/.osm.pbf)."),
        smooth: bool = typer.Option(False, "--smooth", help="RTS smoother (post-processing)."),
        imu_format: str = typer.Option("auto", help="csv, psins, rtklibexplorer, kfgins, auto."),
        gnss_format: str = typer.Option("auto", help="csv, pos, nmea, auto (by extension)."),
        gnss_datum: str = typer.Option("wgs84", help="Datum of the GNSS file: wgs84, pz90.11, pz90, sk42."),
        out_datum: str = typer.Option("wgs84", help="Datum of the solution file."),
        grade: str = typer.Option("consumer", help="IMU noise model: navigation, tactical, "
                                  "industrial, consumer, consumer-car."),
        lever_arm: str = typer.Option("0,0,0", help="IMU-to-antenna lever arm, body RFU, m: x,y,z."),
        imu_time_offset: float = typer.Option(0.0, help="Added to the IMU time stamps, s."),
        no_window_test: bool = typer.Option(False, help="Only the χ² gate (for comparison)."),
        no_nhc: bool = typer.Option(False, help="No non-holonomic constraint (not a car)."),
        scale_factors: bool = typer.Option(False, help="Estimate scale factors (21 states)."),
        mount_states: bool = typer.Option(False, help="Estimate the IMU's pitch and yaw to the "
                                          "vehicle (2 states, seen by the NHC)."),
        nhc_lever: str = typer.Option("0,0,0", help="IMU to the rear-axle centre (where the NHC "
                                      "holds), body RFU, m: x,y,z."),
        no_shadows: bool = typer.Option(False, help="No shadow dead reckoning (drifting-outlier "
                                        "guard), for comparison."),
        matcher: str = typer.Option("seed", help="--method seed identification: seed "
                                    "(residual minimisation, seed 004 §3) or mht (road particles)."),
        ins_datum: str = typer.Option("sk42", help="--method seed: datum of the fast loop."),
        declination_deg: Optional[float] = typer.Option(
            None, help="Magnetic declination, deg (default: field model at the start)."),
        mag: Optional[Path] = typer.Option(None, "--mag", help="Magnetometer CSV t,mx,my,mz "
                                           "(default: mx,my,mz columns of the IMU CSV)."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    ):
        """Navigate with an IMU and GNSS; survives unflagged GNSS outliers (window test)."""
        from selfnav import ekf
        from selfnav.io.gnss import read_gnss

        if method not in ("ekf", "seed"):
            raise SelfnavError(f"unknown method '{method}' (use ekf or seed)")
        graph = None
        if method == "seed" and map_ is None:
            raise SelfnavError("--method seed needs a road map: --map ROADS (.osm/.osm.pbf)")
        if map_ is not None:
            from selfnav.roads import read_roads

            graph = read_roads(map_)
        fmt = imu_format
        if fmt == "auto":
            name = imu.name.lower()
            fmt = ("psins" if name.endswith((".imu", ".imu.gz"))
                   else "rtklibexplorer" if imu.with_name(imu.name + ".tag").exists() else "csv")
        data = read_imu_any(imu, fmt, imu_time_offset)
        g = read_gnss(gnss, gnss_format, gnss_datum)
        if g.t[-1] < data.t[0] or g.t[0] > data.t[-1]:
            raise SelfnavError(f"the GNSS times ({g.t[0]:.3f}…{g.t[-1]:.3f} s) and the IMU times "
                               f"({data.t[0]:.3f}…{data.t[-1]:.3f} s) do not overlap: different "
                               "time bases (GPS seconds of week vs seconds of day?)")
        cfg = ekf.FilterConfig.for_grade(grade, lever_arm_b=_vec3(lever_arm, "--lever-arm"),
                                         robust=not no_window_test, nhc=not no_nhc,
                                         nhc_lever_b=_vec3(nhc_lever, "--nhc-lever"),
                                         mount_states=mount_states, dr_guard=not no_shadows)
        if scale_factors:
            cfg.scale_factors = True
        t0 = time.perf_counter()
        progress = None
        bar = None
        if not as_json and sys.stderr.isatty():
            from rich.progress import Progress

            bar = Progress(transient=True, console=None)
            bar.start()
            task = bar.add_task("navigating", total=1.0)
            progress = lambda x: bar.update(task, completed=x)  # noqa: E731
        try:
            if method == "seed":
                res = _run_seed(data, g, graph, mag, matcher, ins_datum, declination_deg, progress)
            else:
                aid = init = None
                if graph is not None:
                    from selfnav.roadaid import EkfRoadAid
                    from selfnav.seedloop import robust_init

                    aid = EkfRoadAid(graph, g)
                    init = robust_init(data, g)
                res = ekf.run_filter(data, g, cfg, init=init, smooth=smooth, progress=progress,
                                     road_aid=aid)
        finally:
            if bar is not None:
                bar.stop()
        elapsed = time.perf_counter() - t0
        write_solution(out, res, datum=out_datum, comments=[
            f"selfnav navigate --method {method}{' --smooth' if smooth else ''}"
            f"{' --map ' + map_.name if map_ is not None else ''}; imu {imu.name}; "
            f"gnss {gnss.name}; datum {out_datum}"])
        span = float(data.t[-1] - data.t[0])
        summary = {"method": method, "map": None if map_ is None else str(map_),
                   "smoothed": smooth and method == "ekf", "epochs": len(res.trajectory.t),
                   "imu_samples": len(data), "duration_s": span, "seconds": elapsed,
                   "real_time_factor": span / max(elapsed, 1e-9), **res.stats,
                   "suspect_fixes": int(np.sum(res.mode == 1)), "out": str(out)}
        mounting = getattr(res, "mounting", None)
        if mounting is not None and len(mounting):
            summary["mounting_deg"] = [float(x) for x in np.degrees(mounting[-1])]
        if as_json:
            emit_json(summary)
            return
        print(f"{out}: {summary['epochs']} epochs over {span:.1f} s, {elapsed:.1f} s "
              f"({summary['real_time_factor']:.0f}× real time)")
        if method == "seed":
            print(f"  seed 004 slow loop ({matcher}): k_M {res.stats['k_m']}, "
                  f"{res.stats['healthy_fixes']} fixes judged healthy")
            return
        print(f"  GNSS fixes: {res.stats['accepted']} accepted, {res.stats['rejected']} rejected, "
              f"{res.stats['before_init']} before initialisation, "
              f"{res.stats['degraded_updates']} used with inflated σ while suspect")
        if res.stats.get("shadow_resets"):
            print(f"  drifting GNSS caught: {res.stats['shadow_resets']} reset(s) to the shadow "
                  "dead reckoning")
        if "mounting_deg" in summary:
            print(f"  IMU mounting to the vehicle: pitch {summary['mounting_deg'][0]:.2f}°, "
                  f"yaw {summary['mounting_deg'][1]:.2f}°")
