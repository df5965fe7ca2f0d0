"""``selfnav simulate``: IMU, GNSS, magnetometer and truth files of a scenario (DESIGN §6)."""
from __future__ import annotations

import sys
from typing import Annotated, Optional

import typer

from selfnav.cli import options as opt
from selfnav.cli.common import emit_json

STAGES = ("trajectory", "inverse strapdown", "sensor errors", "magnetometer", "GNSS", "writing")


def _city(out, seed: int, duration, as_json: bool) -> None:
    """``simulate city``: :func:`selfnav.api.simulate_city_files`, reported."""
    from selfnav import api

    prs, odo, _, paths = api.simulate_city_files(out, seed=seed, duration=duration)
    epochs = len(set(prs.t.tolist()))
    res = {"scenario": "city", "seed": seed, "out": str(out), "files": [p.name for p in paths],
           "duration_s": float(odo.t[-1] - odo.t[0]), "epochs": epochs,
           "pseudoranges": len(prs.t), "satellites_per_epoch": len(prs.t) / max(epochs, 1),
           "simulated": True}
    if as_json:
        emit_json(res)
        return
    print(f"simulated city drive, seed {seed}: {epochs} epochs over {res['duration_s']:.1f} s, "
          f"{res['satellites_per_epoch']:.1f} satellites per epoch (reflections in the streets)")
    print(f"  wrote {', '.join(res['files'])} to {out}")


def register(app: typer.Typer) -> None:
    @app.command("simulate")
    def simulate_cmd(
        scenario: Annotated[str, typer.Argument(
            metavar="SCENARIO", help="static, multiposition, ship, aircraft, car; the platforms "
                                     "pedestrian, rover, boat, drone; city (raw pseudoranges "
                                     "and odometry in city streets, smartLoc files for "
                                     "navigate --gnss-raw); or a TOML scenario file.")],
        out: opt.out_folder("Folder for imu.csv, gnss.csv, gnss_errors.csv, truth.csv, "
                            "mag.csv and the map (car)."),
        seed: opt.Seed = 0,
        grade: opt.SimGrade = None,
        duration: opt.positive("--duration", help="Length, s (default: the scenario's).",
                               optional=True) = None,
        dt: opt.positive("--dt", help="IMU sample interval, s (default 0.01; at most 0.1 for a "
                                      "moving vehicle).", optional=True) = None,
        start: Annotated[Optional[str], opt.choice_option(
            "--start", choices=("rest", "moving"),
            help="Platforms (pedestrian, rover, boat, drone): start at rest (the default) or "
                 "already moving.")] = None,
        imu_axes: Annotated[Optional[str], typer.Option(
            "--imu-axes", metavar="AXES", callback=opt.check_axes,
            help="Write imu.csv and mag.csv in these sensor axes (FRD, FLU, x=-F,y=R,z=U, a "
                 "preset, ...; see selfnav navigate --help); default body RFU.")] = None,
        imu_mount: Annotated[Optional[str], typer.Option(
            "--imu-mount", metavar="R,P,Y", callback=opt.check_mount,
            help="Write the IMU as mounted at roll, pitch, yaw deg on the vehicle.")] = None,
        as_json: opt.Json = False,
    ):
        """Simulate a scenario and write imu.csv, gnss.csv, truth.csv, mag.csv and the map."""
        from selfnav import api
        from selfnav.io.output import check_output_folder

        check_output_folder(out)
        if scenario == "city":
            _city(out, seed, duration, as_json)
            return
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
            sim, paths = api.simulate_files(scenario, out, seed=seed, grade=grade,
                                            duration=duration, dt=dt, progress=stage,
                                            start=start, imu_axes=imu_axes,
                                            imu_mount=imu_mount)
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
            "start": sim.config["scenario"].get("start"),
            "imu_axes": imu_axes or "RFU",
            "imu_mount_deg": list(imu_mount) if imu_mount is not None else [0.0, 0.0, 0.0],
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
