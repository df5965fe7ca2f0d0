"""``selfnav latitude``: latitude, heading and tilt from an IMU at rest (seed 000, DESIGN §3, §6)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, List, Optional

import numpy as np
import typer

from selfnav.cli import options as opt
from selfnav.cli.common import emit_json
from selfnav.errors import SelfnavError


def _requirements(lat_deg: float, seed_constants: bool, as_json: bool) -> None:
    from selfnav import api

    rows = api.latitude_requirements(lat_deg, seed_constants=seed_constants)
    if as_json:
        emit_json({"latitude_deg": lat_deg, "seed_constants": seed_constants, "rows": rows})
        return
    print(f"Sensor requirements at latitude {lat_deg}° (seed 000 (4.5), (4.8)"
          f"{'; seed constants: Ω = 15 °/h, π = 3.14' if seed_constants else ''}):")
    print(f"{'Δφ, deg':>14} {'Δφ, arcmin':>14} {'ΔΩz, deg/h':>14} {'Δg, g':>14}")
    for r in rows:
        print(f"{r['dphi_deg']:14.6g} {r['dphi_arcmin']:14.6g} {r['gyro_drift_deg_per_h']:14.6g} "
              f"{r['accel_error_g']:14.6g}")


def register(app: typer.Typer) -> None:
    @app.command("latitude")
    def latitude_cmd(
        imu: Annotated[Optional[List[Path]], typer.Argument(
            help="IMU file(s) at rest; several files = several positions.")] = None,
        imu_format: opt.ImuFormat = "auto",
        imu_axes: opt.ImuAxes = None,
        imu_mount: opt.ImuMount = None,
        method: Annotated[str, opt.choice_option(
            "--method", choices=("optimal", "seed"),
            help="optimal (reaches the Cramér–Rao bound) or seed (formula (1.4) with "
                 "Ω = 15.041 °/h, g = 9.81).")] = "optimal",
        rest: Annotated[str, opt.choice_option(
            "--rest", choices=("auto", "still", "disturbed"),
            help="disturbed: compensate tilt changes seen by the accelerometers; auto: when "
                 "they are significant.")] = "auto",
        h_m: Annotated[Optional[float], typer.Option(
            "--h-m", min=-1000.0, max=100000.0, help="Height for the gravity check, m.")] = None,
        as_json: opt.Json = False,
        budget: Annotated[bool, typer.Option(
            "--budget", help="Also print the error budget per sensor error.")] = False,
        gyro_bias_deg_h: Annotated[float, typer.Option(
            help="Gyro bias for --budget, deg/h.")] = 0.005,
        accel_bias_ug: Annotated[float, typer.Option(
            help="Accelerometer bias for --budget, µg.")] = 50.0,
        requirements: Annotated[bool, typer.Option(
            "--requirements", help="Print the seed's sensor-requirements table instead (no IMU "
                                   "needed).")] = False,
        lat_deg: opt.latitude_deg("--lat-deg", help="Latitude for --requirements, deg.") = 60.0,
        seed_constants: Annotated[bool, typer.Option(
            "--seed-constants", help="--requirements with the seed's own constants (reproduces "
                                     "its printed table).")] = False,
        fmt_old: opt.ImuFormatOld = None,
    ):
        """Latitude (and heading, pitch, roll) of a site from an IMU at rest (seed 000).
        Gaps: the longest gap-free stretch is used (a warning says so)."""
        from selfnav import api

        if requirements:
            _requirements(lat_deg, seed_constants, as_json)
            return
        if not imu:
            raise SelfnavError("give an IMU file (or --requirements); see selfnav latitude --help")
        from selfnav.cli.progress import bar

        with bar("reading the IMU", enabled=not as_json) as update:
            data = api.read_imu_positions(imu, fmt_old or imu_format, axes=imu_axes,
                                              mount=imu_mount)
            multi = data.position is not None and len(np.unique(data.position)) > 1
            kw = {"h": h_m} if multi else {"rest": rest, "h": h_m}
            update(0.5, "estimating the latitude")
            res = api.estimate_latitude(data, method=method, **kw)
        out = res.to_dict()
        if budget:
            out["error_budget_deg"] = api.latitude_error_budget(
                res, gyro_bias_deg_h=gyro_bias_deg_h, accel_bias_ug=accel_bias_ug)
        if as_json:
            emit_json(out)
            return
        print(f"{data.source}: {out['samples']} samples, {out['duration_s']:.1f} s, method "
              f"{out['method']}")
        print(f"  latitude  {out['latitude_deg']:.5f}° ± {out['sigma_deg']:.5f}° (1σ; noise "
              f"{out['sigma_noise_deg']:.5f}°)")
        print(f"  heading   {out['heading_deg']:.3f}° ± {out['sigma_heading_deg']:.3f}°   pitch "
              f"{out['pitch_deg']:.4f}°   roll {out['roll_deg']:.4f}°")
        print(f"  |ω|/Ω = {out['earth_rate_ratio']:.5f}   |f|/γ = {out['gravity_ratio']:.6f}")
        if multi:
            print(f"  gyro bias  {np.round(out['gyro_bias_deg_per_h'], 5)} °/h ± "
                  f"{np.round(out['gyro_bias_sigma_deg_per_h'], 5)}")
            print(f"  accel bias {np.round(out['accel_bias_ug'], 2)} µg ± "
                  f"{np.round(out['accel_bias_sigma_ug'], 2)}")
        if budget:
            print("  error budget (deg): " + ", ".join(
                f"{k} {v:.2e}" for k, v in out["error_budget_deg"].items()))
        if "lat0_deg" in data.meta:
            print(f"  (file header site latitude {data.meta['lat0_deg']}°: difference "
                  f"{out['latitude_deg'] - data.meta['lat0_deg']:+.4f}°)")
