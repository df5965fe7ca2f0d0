"""``selfnav moving``: latitude and longitude of a moving object from gyros and attitude (seed 002)."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer

from selfnav.cli import options as opt
from selfnav.errors import InputError, SelfnavError


def _is_simulated(path: Path) -> bool:
    """True when the file's leading comment lines say it is simulated."""
    try:
        with open(path, "r", encoding="utf-8", errors="replace") as fh:
            head = [fh.readline() for _ in range(5)]
    except OSError:
        return False
    return any(h.startswith(("#", "%")) and "simulated" in h.lower() for h in head)


def register(app: typer.Typer) -> None:
    @app.command("moving")
    def moving(
        imu: Path = typer.Option(..., "--imu", help="IMU file (CSV t,wx,wy,wz,fx,fy,fz or PSINS .imu)"),
        attitude: Path = typer.Option(..., "--attitude", help="attitude CSV t,roll_deg,pitch_deg,heading_deg"),
        lat0_deg: float = typer.Option(..., "--lat0-deg", callback=opt.check_latitude_deg, help="start latitude, deg (only fixes the branch)"),
        lon0_deg: float = typer.Option(..., "--lon0-deg", callback=opt.check_longitude_deg, help="start longitude, deg (starts (14))"),
        out: Path = typer.Option(..., "--out", help="solution CSV: t, lat_deg, lon_deg, sigma_lat_deg, sigma_lon_deg"),
        json_out: bool = typer.Option(False, "--json", help="print one JSON summary on stdout"),
        fmt: str = typer.Option("auto", "--format", help="IMU format: auto, csv or psins"),
        gain: Optional[float] = typer.Option(None, "--gain", help="observer gain K, 1/s"),
        bandwidth_hz: Optional[float] = typer.Option(None, "--bandwidth-hz", help="observer bandwidth B, Hz (K = 2πB; default 0.01)"),
        observer: str = typer.Option("stable", "--observer", help="stable (default) or printed (seed (16), diverges after ~90° of turn)"),
        method: str = typer.Option("observer", "--method", help="observer, discrete (form b) or euler (form a, seed (6)-(12))"),
        grade: str = typer.Option("navigation", "--grade", help="sensor grade for the sigmas: navigation, tactical, mems"),
        out_step_s: float = typer.Option(0.0, "--out-step-s", help="write one row per this many seconds (0: every sample)"),
        drift_deg_h: Optional[str] = typer.Option(None, "--drift-deg-h", help="known gyro drift x,y,z in deg/h, removed (seed's ω_d)"),
    ) -> None:
        """Latitude by seed 002 (13) and longitude by (14) from gyros and an attitude source."""
        from selfnav.cli.common import emit_json
        from selfnav.io.csvio import write_csv
        from selfnav.io.readers import read_imu
        from selfnav.io.attitude_file import read_attitude
        from selfnav.io.attitude_file import navigate_imu_attitude
        from selfnav.moving import GRADES

        if not -90.0 <= lat0_deg <= 90.0:
            raise InputError("--lat0-deg", f"{lat0_deg} is not a latitude in degrees")
        if gain is not None and bandwidth_hz is not None:
            raise SelfnavError("give --gain or --bandwidth-hz, not both")
        for name, v in (("--gain", gain), ("--bandwidth-hz", bandwidth_hz)):
            if v is not None and not v > 0:
                raise SelfnavError(f"{name} must be positive (got {v})")
        if observer not in ("stable", "printed"):
            raise SelfnavError(f"unknown --observer '{observer}' (stable or printed)")
        if method not in ("observer", "discrete", "euler"):
            raise SelfnavError(f"unknown --method '{method}' (observer, discrete or euler)")
        if grade not in GRADES:
            raise SelfnavError(f"unknown --grade '{grade}' ({', '.join(GRADES)})")
        drift = None
        if drift_deg_h is not None:
            try:
                drift = np.radians([float(v) for v in drift_deg_h.split(",")]) / 3600.0
            except ValueError:
                drift = np.zeros(0)
            if drift.shape != (3,):
                raise SelfnavError(f"--drift-deg-h needs three numbers x,y,z (got '{drift_deg_h}')")
        import contextlib

        from rich.console import Console

        status = (contextlib.nullcontext() if json_out
                  else Console(stderr=True).status("reading IMU and attitude ..."))
        with status as st:
            imu_data = read_imu(imu, fmt)
            att_data = read_attitude(attitude)
            if st is not None:
                st.update(f"moving-base latitude/longitude on {len(imu_data)} samples ...")
            sol = navigate_imu_attitude(imu_data, att_data, np.radians(lat0_deg),
                                        np.radians(lon0_deg), gain=gain, bandwidth_hz=bandwidth_hz,
                                        method=method, observer=observer, sensor=GRADES[grade],
                                        drift_b=drift)
        lat_deg = np.degrees(sol.lat)
        if not np.all(np.isfinite(lat_deg)):
            sol.warnings.append("non-finite output (observer diverged): rows written as nan")
        keep = np.ones(len(sol.t), bool)
        if out_step_s > 0:
            b = np.floor((sol.t - sol.t[0]) / out_step_s)
            keep = np.r_[True, np.diff(b) > 0]
            keep[-1] = True
        src = f"{imu_data.source} + {att_data.source}"
        comments = [f"selfnav moving: seed 002 (13)/(14), method {sol.method}, observer {sol.observer}, "
                    f"K = {sol.gain:.6g} 1/s; sigmas for grade '{grade}'", f"inputs: {src}"]
        if any(_is_simulated(p) for p in (imu, attitude)):
            comments.insert(0, "simulated input (a simulated IMU or attitude file was read)")
        write_csv(out, {"t": sol.t[keep], "lat_deg": lat_deg[keep], "lon_deg": np.degrees(sol.lon[keep]),
                        "sigma_lat_deg": np.degrees(sol.sigma_lat[keep]),
                        "sigma_lon_deg": np.degrees(sol.sigma_lon[keep])},
                  comments=comments, fmt={"t": "%.6f", "lat_deg": "%.9f", "lon_deg": "%.9f"})
        summary = sol.summary()
        summary.update(out=str(out), rows=int(keep.sum()), grade=grade, lat0_deg=lat0_deg,
                       lon0_deg=lon0_deg)
        if abs(summary["latitude_mean_deg"] - lat0_deg) > 5.0:
            sol.warnings.append(f"computed latitude differs from --lat0-deg by "
                                f"{summary['latitude_mean_deg'] - lat0_deg:+.1f}° (it only fixes the branch)")
            summary["warnings"] = list(sol.warnings)
        if json_out:
            emit_json(summary)
        else:
            typer.echo(f"latitude {summary['latitude_end_deg']:.6f}° ± {summary['sigma_lat_end_deg']:.4f}°, "
                       f"longitude {summary['longitude_end_deg']:.6f}° ± {summary['sigma_lon_end_deg']:.4f}° "
                       f"(end, t = {sol.t[-1]:.3f} s) -> {out}")
            for w in sol.warnings:
                typer.echo(f"warning: {w}", err=True)
