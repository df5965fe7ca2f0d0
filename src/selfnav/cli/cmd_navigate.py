"""``selfnav navigate``: INS/GNSS navigation (DESIGN §5, §6) — parses, calls
:func:`selfnav.api.navigate`, writes and reports."""
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


def _magnetometer(imu, mag_path: Path | None):
    """Magnetometer columns from a separate CSV, interpolated onto the IMU times."""
    if mag_path is None:
        return imu
    from selfnav.io.csvio import read_table

    tab = read_table(mag_path, ("t", "mx", "my", "mz"))
    imu.mag_b = np.column_stack([np.interp(imu.t, tab["t"], tab[c]) for c in ("mx", "my", "mz")])
    return imu


def _odometer(imu_path: Path, odo_path: Path | None):
    """Wheel speed from ``--odometer`` or the ``speed_mps`` column of the IMU CSV (or None)."""
    from selfnav.io.odometer import has_odometer, read_odometer

    if odo_path is not None:
        return read_odometer(odo_path)
    return read_odometer(imu_path) if has_odometer(imu_path) else None


def register(app: typer.Typer) -> None:
    @app.command("navigate")
    def navigate_cmd(
        imu: Path = typer.Option(..., "--imu", help="IMU file."),
        gnss: Optional[Path] = typer.Option(None, "--gnss", help="GNSS fixes (csv, RTKLIB .pos, "
                                            "NMEA, PSINS avp csv); optional with --init."),
        init: Optional[Path] = typer.Option(None, "--init", help="Start from the state of this "
                                            "trajectory file (truth/solution CSV, RTKLIB .pos with "
                                            "no attitude excluded, PSINS avp) at the IMU start, "
                                            "instead of aligning from GNSS."),
        out: Path = typer.Option(..., "--out", help="Solution CSV (written atomically)."),
        method: str = typer.Option("ekf", help="ekf (error-state Kalman filter) or seed."),
        map_: Optional[Path] = typer.Option(None, "--map", help="Road map (.osm/.osm.pbf)."),
        smooth: bool = typer.Option(False, "--smooth", help="RTS smoother (post-processing)."),
        imu_format: str = typer.Option("auto", help="csv, psins, rtklibexplorer (applies "
                                       "upstream's -0.125 s time offset), kfgins, auto."),
        gnss_format: str = typer.Option("auto", help="csv, pos, nmea, auto (by extension)."),
        gnss_datum: str = typer.Option("wgs84", help="Datum of the GNSS file: wgs84, pz90.11, pz90, sk42."),
        out_datum: str = typer.Option("wgs84", help="Datum of the solution file."),
        grade: str = typer.Option("auto", help="IMU noise prior: auto (measured from the data), "
                                  "navigation, tactical, industrial, consumer; where the data is "
                                  "noisier than a preset, the measured noise is used (a warning "
                                  "says so)."),
        lever_arm: Optional[str] = typer.Option(None, help="IMU-to-antenna lever arm, body RFU, "
                                                "m: x,y,z (default: estimated, and the solution "
                                                "is the antenna's position)."),
        imu_time_offset: Optional[float] = typer.Option(None, help="Added to the IMU time "
                                                        "stamps after the reader's own (the "
                                                        "rtklibexplorer format applies upstream's "
                                                        "-0.125 s), s (default: estimated)."),
        fix_log: Optional[Path] = typer.Option(None, "--fix-log", help="Write one row per GNSS "
                                               "fix: t, status, reason, NIS."),
        window_test: bool = typer.Option(True, "--window-test/--no-window-test",
                                         help="The outlier window test (off: only the χ² gate)."),
        nhc: bool = typer.Option(True, "--nhc/--no-nhc", help="Non-holonomic constraint (a car)."),
        shadows: bool = typer.Option(True, "--shadows/--no-shadows", help="Shadow dead "
                                     "reckoning against drifting GNSS."),
        scale_factors: bool = typer.Option(False, help="Estimate scale factors (21 states)."),
        mount_states: bool = typer.Option(False, help="Estimate the IMU's pitch and yaw to the "
                                          "vehicle (2 states, seen by the NHC)."),
        nhc_lever: str = typer.Option("0,0,0", help="IMU to the rear-axle centre (where the NHC "
                                      "holds), body RFU, m: x,y,z."),
        matcher: str = typer.Option("seed", help="--method seed identification: seed "
                                    "(residual minimisation, seed 004 §3) or mht (road particles)."),
        ins_datum: str = typer.Option("sk42", help="--method seed: datum of the fast loop."),
        declination_deg: Optional[float] = typer.Option(
            None, help="Magnetic declination, deg (default: field model at the start)."),
        mag: Optional[Path] = typer.Option(None, "--mag", help="Magnetometer CSV t,mx,my,mz "
                                           "(default: mx,my,mz columns of the IMU CSV)."),
        odometer: Optional[Path] = typer.Option(None, "--odometer", help="Wheel speed CSV "
                                                "t,speed_mps on the IMU clock (default: the "
                                                "speed_mps column of the IMU CSV, if any)."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    ):
        """Navigate with an IMU and GNSS; survives unflagged GNSS outliers (window test)."""
        from selfnav import api

        data = _magnetometer(api.read_imu(imu, imu_format), mag)
        if gnss is None and init is None:
            raise SelfnavError("navigate needs --gnss FILE (or an initial state: --init FILE)")
        g = api.read_gnss(gnss, gnss_format, gnss_datum) if gnss is not None else None
        graph = api.read_roads(map_) if map_ is not None else None
        odo = _odometer(imu, odometer)
        t0 = time.perf_counter()
        progress = bar = None
        if not as_json and sys.stderr.isatty():
            from rich.progress import Progress

            bar = Progress(transient=True, console=None)
            bar.start()
            task = bar.add_task("navigating", total=1.0)
            progress = lambda x: bar.update(task, completed=x)  # noqa: E731
        try:
            sol = api.navigate(data, g, graph, method=method, smooth=smooth, grade=grade,
                               lever_arm_m=None if lever_arm is None else _vec3(lever_arm, "--lever-arm"),
                               imu_time_offset_s=imu_time_offset,
                               nhc_lever_m=_vec3(nhc_lever, "--nhc-lever"),
                               window_test=window_test, nhc=nhc, shadows=shadows,
                               mount_states=mount_states, scale_factors=scale_factors or None,
                               matcher=matcher, ins_datum=ins_datum,
                               declination_deg=declination_deg, init=init, progress=progress,
                               odometer=odo)
        finally:
            if bar is not None:
                bar.stop()
        elapsed = time.perf_counter() - t0
        sol.to_csv(out, datum=out_datum, comments=[
            f"selfnav navigate --method {method}{' --smooth' if smooth else ''}"
            f"{' --map ' + map_.name if map_ is not None else ''}; imu {imu.name}; "
            f"gnss {gnss.name if gnss is not None else 'none'}"])
        if fix_log is not None:
            api.write_fix_log(fix_log, sol)
        span = float(data.t[-1] - data.t[0])
        summary = {"method": method, "map": None if map_ is None else str(map_),
                   "epochs": len(sol), "imu_samples": len(data), "duration_s": span,
                   "seconds": elapsed, "real_time_factor": span / max(elapsed, 1e-9),
                   **sol.stats, "out": str(out)}
        if as_json:
            emit_json(summary)
            return
        print(f"{out}: {summary['epochs']} epochs over {span:.1f} s, {elapsed:.1f} s "
              f"({summary['real_time_factor']:.0f}× real time)")
        s = sol.stats
        if method == "seed":
            print(f"  seed 004 slow loop ({matcher}): k_M {s['k_m']}, "
                  f"{s['healthy_fixes']} fixes judged healthy")
            return
        print(f"  GNSS fixes: {s['accepted']} used, {s['rejected']} rejected, "
              f"{s['before_init']} before initialisation, "
              f"{s['degraded_updates']} used with inflated σ while suspect")
        print(f"  IMU time offset {s['imu_time_offset_s']:+.3f} s (applied to its stamps, "
              f"estimate included); lever arm {', '.join(f'{x:.2f}' for x in s['lever_arm_m'])} m "
              f"(RFU); solution at the {s['position_of']}")
        if s.get("shadow_resets"):
            print(f"  drifting GNSS caught: {s['shadow_resets']} reset(s) to the shadow "
                  "dead reckoning")
        if "mounting_deg" in s:
            print(f"  IMU mounting to the vehicle: pitch {s['mounting_deg'][0]:.2f}°, "
                  f"yaw {s['mounting_deg'][1]:.2f}°")
