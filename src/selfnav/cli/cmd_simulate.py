"""``selfnav simulate``: IMU, GNSS, magnetometer and truth files of a scenario (DESIGN §6)."""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import typer

from selfnav.cli.common import emit_json

STAGES = ("trajectory", "inverse strapdown", "sensor errors", "magnetometer", "GNSS", "writing")


def register(app: typer.Typer) -> None:
    @app.command("simulate")
    def simulate_cmd(
        scenario: str = typer.Argument(..., help="static, multiposition, ship, aircraft, car, "
                                       "or a TOML scenario file."),
        out: Path = typer.Option(..., "--out", help="Output folder (created)."),
        seed: int = typer.Option(0, help="Random seed: the same seed gives the same files."),
        grade: Optional[str] = typer.Option(None, help="IMU grade: navigation, tactical, "
                                            "industrial, consumer or perfect."),
        duration: Optional[float] = typer.Option(None, help="Length, s (scenario default)."),
        dt: Optional[float] = typer.Option(None, help="IMU sample interval, s (default 0.01)."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    ):
        """Simulate a scenario and write imu.csv, gnss.csv, truth.csv, mag.csv and the map."""
        from selfnav.simulate.scenarios import simulate, write_simulation

        if as_json or not sys.stderr.isatty():
            stage = lambda name: None  # noqa: E731
            ctx = None
        else:
            from rich.console import Console
            from rich.progress import Progress

            ctx = Progress(transient=True, console=Console(stderr=True))
            ctx.start()
            task = ctx.add_task("simulating", total=len(STAGES))

            def stage(name):
                ctx.update(task, advance=1, description=name)
        try:
            sim = simulate(scenario, seed=seed, grade=grade, duration=duration, dt=dt,
                           progress=stage)
            stage("writing")
            paths = write_simulation(sim, out)
        finally:
            if ctx is not None:
                ctx.stop()
        g = sim.gnss
        res = {
            "scenario": sim.name, "kind": sim.config["scenario"]["kind"], "seed": seed,
            "grade": sim.config["imu"]["grade"], "out": str(out),
            "files": [p.name for p in paths], "imu_samples": len(sim.imu),
            "dt_s": sim.imu.dt, "duration_s": float(sim.imu.t[-1] - sim.truth.t[0]),
            "gnss_fixes": 0 if g is None else len(g.t),
            "outlier_windows": [] if g is None else [
                {"start_s": w.start, "end_s": w.end, "sigma_m": w.sigma, "kind": w.kind}
                for w in g.windows],
            "simulated": True,
        }
        if as_json:
            emit_json(res)
            return
        print(f"simulated {res['scenario']} ({res['kind']}), seed {seed}, IMU {res['grade']}: "
              f"{res['imu_samples']} IMU samples over {res['duration_s']:.1f} s, "
              f"{res['gnss_fixes']} GNSS fixes")
        for w in res["outlier_windows"]:
            print(f"  unflagged GNSS outliers {w['start_s']:.1f}-{w['end_s']:.1f} s, "
                  f"{w['kind']}, σ {w['sigma_m']:g} m")
        print(f"  wrote {', '.join(res['files'])} to {out}")
