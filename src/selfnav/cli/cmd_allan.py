"""``selfnav allan``: Allan deviation and noise terms of an IMU record at rest (DESIGN §6)."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer

from selfnav.cli.common import emit_json

RAD_S_TO_DEG_H = np.degrees(1.0) * 3600.0
SQRT_S_TO_SQRT_H = 60.0  # (x)/√s -> (x)/√h


def summary(res: dict) -> dict:
    """The DESIGN §6 keys (lists of three, x y z) plus the details, in the units named."""
    g, a = res["gyro"], res["accel"]
    return {
        "arw_deg_per_sqrt_h": [np.degrees(x.white) * SQRT_S_TO_SQRT_H for x in g],
        "bias_instability_deg_per_h": [x.bias_instability * RAD_S_TO_DEG_H for x in g],
        "vrw_m_per_s_per_sqrt_h": [x.white * SQRT_S_TO_SQRT_H for x in a],
        "accel_bias_instability_m_per_s2": [x.bias_instability for x in a],
        "gyro_rate_random_walk_deg_per_h_per_sqrt_h": [
            x.random_walk * RAD_S_TO_DEG_H * SQRT_S_TO_SQRT_H for x in g],
        "accel_random_walk_m_per_s2_per_sqrt_h": [x.random_walk * SQRT_S_TO_SQRT_H for x in a],
        "gyro_bias_instability_tau_s": [x.bias_instability_tau for x in g],
        "accel_bias_instability_tau_s": [x.bias_instability_tau for x in a],
        "gyro_bias_instability_is_upper_bound": [x.bias_instability_bound for x in g],
        "accel_bias_instability_is_upper_bound": [x.bias_instability_bound for x in a],
        "samples": res["samples"], "dt_s": res["dt"],
    }


def register(app: typer.Typer) -> None:
    @app.command("allan")
    def allan_cmd(
        imu: Path = typer.Argument(..., help="IMU record at rest (CSV or PSINS .imu)."),
        fmt: str = typer.Option("auto", "--format", help="csv, psins or auto (by extension)."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
        plot: Optional[Path] = typer.Option(None, "--plot", help="Log-log plot PNG (default "
                                            "<IMU name>_allan.png in the current folder)."),
        no_plot: bool = typer.Option(False, "--no-plot", help="Do not write the plot."),
    ):
        """Allan deviation of gyros and accelerometers; ARW, VRW, bias instability, random walk."""
        from selfnav.allan import analyze_imu, plot_allan
        from selfnav.errors import InputError
        from selfnav.io.readers import read_imu

        data = read_imu(imu, fmt)
        if len(data) < 100:
            raise InputError(imu, f"has {len(data)} samples: too short for an Allan analysis")
        res = analyze_imu(data)
        out = summary(res)
        if not no_plot:
            name = imu.name.split(".")[0]
            path = plot or Path(f"{name}_allan.png")
            plot_allan(res, path, f"Allan deviation: {imu.name}")
            out["plot"] = str(path)
        if as_json:
            emit_json(out)
            return
        print(f"{imu}: {out['samples']} samples at {out['dt_s']:.4g} s "
              f"({out['samples'] * out['dt_s'] / 3600:.2f} h)")
        print(f"{'axis':>5} {'ARW °/√h':>11} {'gyro BI °/h':>12} {'VRW m/s/√h':>11} "
              f"{'accel BI m/s²':>14}")
        for k, ax in enumerate("xyz"):
            ub = "≤" if out["gyro_bias_instability_is_upper_bound"][k] else " "
            ua = "≤" if out["accel_bias_instability_is_upper_bound"][k] else " "
            print(f"{ax:>5} {out['arw_deg_per_sqrt_h'][k]:11.4g} "
                  f"{ub}{out['bias_instability_deg_per_h'][k]:11.4g} "
                  f"{out['vrw_m_per_s_per_sqrt_h'][k]:11.4g} "
                  f"{ua}{out['accel_bias_instability_m_per_s2'][k]:13.4g}")
        print("  (≤: σ(τ) still falling, the bias instability is an upper bound; nan: no slope "
              "-1/2 region)")
        if "plot" in out:
            print(f"  plot: {out['plot']}")
