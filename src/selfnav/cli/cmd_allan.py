"""``selfnav allan``: Allan deviation and noise terms of an IMU record at rest (DESIGN §6)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from selfnav.cli import options as opt
from selfnav.cli.common import emit_json


def register(app: typer.Typer) -> None:
    @app.command("allan")
    def allan_cmd(
        imu: opt.ImuArgument,
        imu_format: opt.ImuFormat = "auto",
        imu_axes: opt.ImuAxes = None,
        imu_mount: opt.ImuMount = None,
        as_json: opt.Json = False,
        plot: Annotated[Optional[Path], typer.Option(
            "--plot", help="Write the log-log plot to this PNG FILE (no plot without it).")] = None,
        fmt_old: opt.ImuFormatOld = None,
        no_plot: Annotated[bool, typer.Option("--no-plot", hidden=True,
                                              help="Ignored (no plot is the default).")] = False,
    ):
        """Allan deviation of gyros and accelerometers at rest: ARW, VRW, bias instability,
        rate random walk. Gaps: the longest gap-free stretch is analysed (a warning says so)."""
        from selfnav import api
        from selfnav.io.output import check_output_file

        if plot is not None:
            check_output_file(plot, (".png",))
        from selfnav.cli.progress import bar

        with bar(f"reading {imu.name}", enabled=not as_json) as update:
            data = api.read_imu(imu, fmt_old or imu_format, axes=imu_axes, mount=imu_mount)
            update(0.5, "Allan deviation")
            out = api.allan_noise(data, plot=plot, title=f"Allan deviation: {imu.name}")
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
