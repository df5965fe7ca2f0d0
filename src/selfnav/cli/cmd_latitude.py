"""``selfnav latitude``: latitude, heading and tilt from an IMU at rest (seed 000, DESIGN §3, §6)."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import numpy as np
import typer

from selfnav.cli.common import emit_json
from selfnav.errors import SelfnavError


def _requirements(lat_deg: float, seed_constants: bool, as_json: bool) -> None:
    from selfnav.latitude import SEED_TABLE_DPHI_DEG, requirements_table

    tab = requirements_table(SEED_TABLE_DPHI_DEG, lat_deg, seed_constants=seed_constants)
    rows = [dict(zip(tab, vals)) for vals in zip(*tab.values())]
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
        imu: Optional[List[Path]] = typer.Argument(
            None, help="IMU file(s) at rest; several files = several positions."),
        fmt: str = typer.Option("auto", "--format", help="csv, psins or auto (by extension)."),
        method: str = typer.Option("optimal", help="optimal (reaches the Cramér–Rao bound) or "
                                   "seed (formula (1.4) with Ω = 15.041 °/h, g = 9.81)."),
        rest: str = typer.Option("auto", help="auto, still or disturbed (compensate tilt changes "
                                 "seen by the accelerometers)."),
        h_m: Optional[float] = typer.Option(None, "--h-m", help="Height for the gravity check, m."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
        budget: bool = typer.Option(False, help="Also print the error budget per sensor error."),
        gyro_bias_deg_h: float = typer.Option(0.005, help="Gyro bias for --budget, deg/h."),
        accel_bias_ug: float = typer.Option(50.0, help="Accelerometer bias for --budget, µg."),
        requirements: bool = typer.Option(False, "--requirements", help="Print the seed's "
                                          "sensor-requirements table instead (no IMU needed)."),
        lat_deg: float = typer.Option(60.0, "--lat-deg", help="Latitude for --requirements."),
        seed_constants: bool = typer.Option(False, help="--requirements with the seed's own "
                                            "constants (reproduces its printed table)."),
    ):
        """Latitude (and heading, pitch, roll) of a site from an IMU at rest (seed 000)."""
        from selfnav import latitude as lat_mod
        from selfnav.io.readers import read_imu_positions

        if requirements:
            _requirements(lat_deg, seed_constants, as_json)
            return
        if not imu:
            raise SelfnavError("give an IMU file (or --requirements); see selfnav latitude --help")
        data = read_imu_positions(imu, fmt)
        multi = data.position is not None and len(np.unique(data.position)) > 1
        if multi:
            res = lat_mod.estimate_latitude_multiposition(data, h=h_m)
        else:
            res = lat_mod.estimate_latitude(data, method=method, rest=rest, h=h_m)
        out = res.to_dict()
        if budget:
            b = lat_mod.error_budget(res, gyro_bias_deg_h * lat_mod.DEG_PER_H,
                                     accel_bias_ug * 1e-6 * lat_mod.G_STD)
            out["error_budget_deg"] = {k: float(np.degrees(v)) for k, v in b.items()}
        if as_json:
            emit_json(out)
            return
        src = data.source
        print(f"{src}: {out['samples']} samples, {out['duration_s']:.1f} s, method {out['method']}")
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
        for w in out["warnings"]:
            print(f"  note: {w}")
        if "lat0_deg" in data.meta:
            print(f"  (file header site latitude {data.meta['lat0_deg']}°: difference "
                  f"{out['latitude_deg'] - data.meta['lat0_deg']:+.4f}°)")
