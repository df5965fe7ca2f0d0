"""``selfnav moving``: latitude and longitude of a moving object from gyros and attitude (seed 002)."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer

from selfnav.cli import options as opt
from selfnav.errors import InputError, SelfnavError

GRADE_CHOICES = ("navigation", "tactical", "industrial", "consumer")   # selfnav.sensors.GRADE_NAMES
RATE_CHOICES = ("interval-mean", "instantaneous")                     # selfnav.moving.RATE_CONVENTIONS


def _is_simulated(path: Path) -> bool:
    """True when the file's leading comment lines say it is simulated."""
    try:
        with open(path, "r", encoding="utf-8", errors="replace") as fh:
            head = [fh.readline() for _ in range(5)]
    except OSError:
        return False
    return any(h.startswith(("#", "%")) and "simulated" in h.lower() for h in head)


def _choice(name, value, choices):
    if value not in choices:
        raise SelfnavError(f"unknown {name} '{value}' (use {', '.join(choices)})")
    return value


def register(app: typer.Typer) -> None:
    @app.command("moving")
    def moving(
        imu: opt.ImuFile,
        out: opt.out_file("Solution CSV: t, lat_deg, lon_deg, sigma_lat_deg, sigma_lon_deg, "
                          "one row per IMU sample (or per --out-step-s)."),
        attitude: Path = typer.Option(..., "--attitude", help="attitude CSV t,roll_deg,pitch_deg,heading_deg "
                                      "(extra columns, e.g. a truth file, are ignored)"),
        lat0_deg: float = typer.Option(..., "--lat0-deg", callback=opt.check_latitude_deg, help="start latitude, deg (only fixes the branch)"),
        lon0_deg: float = typer.Option(..., "--lon0-deg", callback=opt.check_longitude_deg, help="start longitude, deg (starts (14))"),
        json_out: opt.Json = False,
        imu_format: opt.ImuFormat = "auto",
        fmt_old: opt.ImuFormatOld = None,
        imu_axes: opt.ImuAxes = None,
        imu_mount: opt.ImuMount = None,
        imu_rates: str = typer.Option(
            "interval-mean", "--imu-rates", metavar="[" + "|".join(RATE_CHOICES) + "]",
            help="what an IMU rate row is: interval-mean (default, the package's convention: the "
                 "mean rate over the interval ending at t, as selfnav simulate writes and "
                 "increment IMUs give) or instantaneous (a point sample at t)"),
        attitude_time_offset: Optional[float] = typer.Option(
            None, "--attitude-time-offset",
            help="attitude time stamps minus the IMU clock, s (positive: attitude stamped late). "
                 "Default: estimated from the data (attitude rotation against the gyros); give it "
                 "to fix it by hand (no estimation)"),
        gain: Optional[float] = typer.Option(None, "--gain", help="observer gain K, 1/s"),
        bandwidth_hz: Optional[float] = typer.Option(None, "--bandwidth-hz", help="observer bandwidth B, Hz (K = 2πB; default 0.01)"),
        observer: str = typer.Option("stable", "--observer", metavar="[stable|printed]",
                                     help="stable (default) or printed (seed (16), diverges after ~90° of turn)"),
        method: str = typer.Option("observer", "--method", metavar="[observer|discrete|euler]",
                                   help="observer, discrete (form b) or euler (form a, seed (6)-(12))"),
        grade: str = typer.Option("navigation", "--grade", metavar="[" + "|".join(GRADE_CHOICES) + "]",
                                  help="sensor grade of selfnav.sensors.GRADES for the sigmas"),
        out_step_s: float = typer.Option(0.0, "--out-step-s", help="write one row per this many seconds (0: every sample)"),
        drift_deg_h: Optional[str] = typer.Option(None, "--drift-deg-h", help="known gyro drift x,y,z in deg/h, removed (seed's ω_d)"),
    ) -> None:
        """Latitude by seed 002 (13) and longitude by (14) from gyros and an attitude source.

        The attitude–gyro time offset is estimated from the data unless --attitude-time-offset
        is given: on a rolling ship 1 ms of offset is about 0.1-0.2° of latitude.
        """
        from selfnav.cli.common import emit_json
        from selfnav.io.attitude_file import read_attitude
        from selfnav.io.readers import read_imu
        from selfnav.moving_driver import navigate_moving

        if not -90.0 <= lat0_deg <= 90.0:
            raise InputError("--lat0-deg", f"{lat0_deg} is not a latitude in degrees")
        if gain is not None and bandwidth_hz is not None:
            raise SelfnavError("give --gain or --bandwidth-hz, not both")
        for name, v in (("--gain", gain), ("--bandwidth-hz", bandwidth_hz)):
            if v is not None and not v > 0:
                raise SelfnavError(f"{name} must be positive (got {v})")
        _choice("--observer", observer, ("stable", "printed"))
        _choice("--method", method, ("observer", "discrete", "euler"))
        grade = _choice("--grade", grade.lower().strip(), GRADE_CHOICES)
        _choice("--imu-rates", imu_rates, RATE_CHOICES)
        if attitude_time_offset is not None and not abs(attitude_time_offset) < 10.0:
            raise SelfnavError(f"--attitude-time-offset {attitude_time_offset} s: give seconds "
                               "(a clock offset, not a time base; |offset| < 10 s)")
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
            imu_data = read_imu(imu, fmt_old or imu_format, axes=imu_axes, mount=imu_mount)
            att_data = read_attitude(attitude)
            if st is not None:
                st.update(f"moving-base latitude/longitude on {len(imu_data)} samples ...")
            sol = navigate_moving(imu_data, att_data, np.radians(lat0_deg), np.radians(lon0_deg),
                                  rates=imu_rates, attitude_time_offset=attitude_time_offset,
                                  grade=grade, gain=gain, bandwidth_hz=bandwidth_hz, method=method,
                                  observer=observer, drift_b=drift)
        if not np.all(np.isfinite(sol.lat)):
            sol.warnings.append("non-finite output (observer diverged): rows written as nan")
        info = sol.info
        how = "estimated" if info["attitude_time_offset_estimated"] else "given"
        comments = [f"selfnav moving: seed 002 (13)/(14), method {sol.method}, observer {sol.observer}, "
                    f"K = {sol.gain:.6g} 1/s; sigmas for grade '{grade}'",
                    f"IMU rows: {imu_rates}; attitude time offset {1e3 * info['attitude_time_offset_s']:+.4f} ms "
                    f"({how}, σ {1e3 * info['attitude_time_offset_sigma_s']:.4f} ms); latitude error "
                    f"{info['lat_error_per_ms_deg']:.3g}° per ms of residual offset on this motion",
                    f"inputs: {imu_data.source} + {att_data.source}"]
        if any(_is_simulated(p) for p in (imu, attitude)):
            comments.insert(0, "simulated input (a simulated IMU or attitude file was read)")
        rows = sol.to_csv(out, step_s=out_step_s, comments=comments)
        summary = sol.summary()
        summary.update(out=str(out), rows=rows, grade=grade, lat0_deg=lat0_deg, lon0_deg=lon0_deg)
        if abs(summary["latitude_mean_deg"] - lat0_deg) > 5.0:
            sol.warnings.append(f"computed latitude differs from --lat0-deg by "
                                f"{summary['latitude_mean_deg'] - lat0_deg:+.1f}° (it only fixes the branch)")
            summary["warnings"] = list(sol.warnings)
        if json_out:
            emit_json(summary)
        else:
            typer.echo(f"latitude {summary['latitude_end_deg']:.6f}° ± {summary['sigma_lat_end_deg']:.4f}°, "
                       f"longitude {summary['longitude_end_deg']:.6f}° ± {summary['sigma_lon_end_deg']:.4f}° "
                       f"(end, t = {sol.t[-1]:.3f} s), attitude time offset "
                       f"{1e3 * info['attitude_time_offset_s']:+.3f} ms ({how}) -> {out}")
            for w in sol.warnings:
                typer.echo(f"warning: {w}", err=True)
