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


def register(app: typer.Typer) -> None:
    @app.command("navigate")
    def navigate_cmd(
        imu: Path = typer.Option(..., "--imu", help="IMU file."),
        gnss: Path = typer.Option(..., "--gnss", help="GNSS fixes (csv, RTKLIB .pos, NMEA)."),
        out: Path = typer.Option(..., "--out", help="Solution CSV (written atomically)."),
        method: str = typer.Option("ekf", help="ekf (error-state Kalman filter) or seed."),
        map_: Optional[Path] = typer.Option(None, "--map", help="Road map (.osm/.osm.pbf)."),
        smooth: bool = typer.Option(False, "--smooth", help="RTS smoother (post-processing)."),
        imu_format: str = typer.Option("auto", help="csv, psins, rtklibexplorer (applies "
                                       "upstream's -0.125 s time offset), kfgins, auto."),
        gnss_format: str = typer.Option("auto", help="csv, pos, nmea, auto (by extension)."),
        gnss_datum: str = typer.Option("wgs84", help="Datum of the GNSS file: wgs84, pz90.11, pz90, sk42."),
        out_datum: str = typer.Option("wgs84", help="Datum of the solution file."),
        grade: str = typer.Option("consumer", help="IMU noise model: navigation, tactical, "
                                  "industrial, consumer."),
        lever_arm: str = typer.Option("0,0,0", help="IMU-to-antenna lever arm, body RFU, m: x,y,z."),
        imu_time_offset: float = typer.Option(0.0, help="Added to the IMU time stamps, s."),
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
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    ):
        """Navigate with an IMU and GNSS; survives unflagged GNSS outliers (window test)."""
        from selfnav import api

        data = _magnetometer(api.read_imu(imu, imu_format, time_offset_s=imu_time_offset), mag)
        g = api.read_gnss(gnss, gnss_format, gnss_datum)
        graph = api.read_roads(map_) if map_ is not None else None
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
                               lever_arm_m=_vec3(lever_arm, "--lever-arm"),
                               nhc_lever_m=_vec3(nhc_lever, "--nhc-lever"),
                               window_test=window_test, nhc=nhc, shadows=shadows,
                               mount_states=mount_states, scale_factors=scale_factors or None,
                               matcher=matcher, ins_datum=ins_datum,
                               declination_deg=declination_deg, progress=progress)
        finally:
            if bar is not None:
                bar.stop()
        elapsed = time.perf_counter() - t0
        sol.to_csv(out, datum=out_datum, comments=[
            f"selfnav navigate --method {method}{' --smooth' if smooth else ''}"
            f"{' --map ' + map_.name if map_ is not None else ''}; imu {imu.name}; "
            f"gnss {gnss.name}"])
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
        print(f"  GNSS fixes: {s['accepted']} accepted, {s['rejected']} rejected, "
              f"{s['before_init']} before initialisation, "
              f"{s['degraded_updates']} used with inflated σ while suspect")
        if s.get("shadow_resets"):
            print(f"  drifting GNSS caught: {s['shadow_resets']} reset(s) to the shadow "
                  "dead reckoning")
        if "mounting_deg" in s:
            print(f"  IMU mounting to the vehicle: pitch {s['mounting_deg'][0]:.2f}°, "
                  f"yaw {s['mounting_deg'][1]:.2f}°")
