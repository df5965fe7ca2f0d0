"""``selfnav attitude``: attitude from gyros, accelerometers and a magnetometer (an AHRS), and its
comparison with a reference attitude (a PX4 log's own, a truth file)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from selfnav.cli import options as opt
from selfnav.cli.common import emit_json


def register(app: typer.Typer) -> None:
    @app.command("attitude")
    def attitude_cmd(
        imu: opt.ImuFile,
        out: opt.out_file("Attitude CSV: t, roll_deg, pitch_deg, heading_deg and their 1σ "
                          "(sigma_roll_deg, ...), one row per IMU sample from the start on."),
        imu_format: opt.ImuFormat = "auto",
        imu_axes: opt.ImuAxes = None,
        imu_mount: opt.ImuMount = None,
        grade: Annotated[str, opt.choice_option(
            "--grade", choices=opt.GRADES,
            help="IMU noise prior (selfnav.sensors.GRADES); the gyro noise is measured at "
                 "rest where the record has a rest.")] = "consumer",
        declination_deg: Annotated[Optional[float], typer.Option(
            min=-180.0, max=180.0, help="Magnetic declination, deg (default: IGRF-14 at "
                                        "--lat-deg/--lon-deg or the first GNSS fix, else the "
                                        "file's own, else 0: magnetic heading).")] = None,
        lat_deg: Annotated[Optional[float], typer.Option(
            "--lat-deg", callback=opt.check_latitude_deg,
            help="Latitude of the place, deg (IGRF declination, Earth rate).")] = None,
        lon_deg: Annotated[Optional[float], typer.Option(
            "--lon-deg", callback=opt.check_longitude_deg,
            help="Longitude of the place, deg.")] = None,
        gnss: Annotated[Optional[Path], typer.Option(
            "--gnss", help="GNSS file whose first fix gives the place (a PX4 .ulg IMU log's "
                           "own GPS is used when it has one).")] = None,
        no_mag: Annotated[bool, typer.Option(
            "--no-mag", help="Ignore the magnetometer (heading from the gyros only).")] = False,
        reference: Annotated[Optional[Path], typer.Option(
            "--reference", help="Attitude to compare with: a PX4 .ulg (its vehicle_attitude) "
                                "or a CSV with t, roll_deg, pitch_deg, heading_deg.")] = None,
        step: opt.at_least(1, "--step", help="Write every N-th row.") = 1,
        as_json: opt.Json = False,
    ):
        """Attitude (roll, pitch, heading with σ) from an IMU with or without magnetometer:
        levelled at rest (bias-aware stillness), then an error-state filter; --reference
        compares it with another attitude (RMS, max after the start)."""
        from selfnav import api
        from selfnav.errors import InputError, SelfnavError
        from selfnav.io.csvio import write_csv
        from selfnav.io.output import check_output_file

        check_output_file(out)
        if (lat_deg is None) != (lon_deg is None):
            raise SelfnavError("give both --lat-deg and --lon-deg (or neither)")
        data = api.read_imu(imu, imu_format, axes=imu_axes, mount=imu_mount)
        g = None
        if gnss is not None:
            g = api.read_gnss(gnss)
        elif data.meta.get("format") == "ulog" and lat_deg is None and declination_deg is None:
            try:
                g = api.read_gnss(imu, "ulog")
            except InputError:
                g = None              # a log without GPS: the file's own declination, or none
        res = api.estimate_attitude(data, gnss=g, grade=grade, declination_deg=declination_deg,
                                    lat_deg=lat_deg, lon_deg=lon_deg, use_mag=not no_mag)
        cols = res.columns(step)
        info = res.info
        write_csv(out, cols, comments=[
            f"selfnav attitude: imu {imu.name} ({data.meta.get('axes', 'RFU')} axes), start "
            f"{info['start']} at t = {info['t_start']:.3f} s, declination "
            f"{info['declination_deg']:.3f} deg ({info['declination_source']})"],
            fmt={"t": "%.6f"})
        summary = {"out": str(out), "rows": len(cols["t"]), "samples": len(data),
                   "start": info["start"], "t_start": info["t_start"],
                   "heading_source": info["heading_source"],
                   "initial_heading_deg": info["initial_heading_deg"],
                   "initial_heading_sigma_deg": info["initial_heading_sigma_deg"],
                   "declination_deg": info["declination_deg"],
                   "declination_source": info["declination_source"],
                   "levelling": info.get("levelling"),
                   "accel_updates": info["accel_updates"], "mag_updates": info["mag_updates"],
                   "end": {k: float(v[-1]) for k, v in cols.items() if k != "t"}}
        if reference is not None:
            ref = api.read_reference_attitude(reference)
            cmp = api.compare_attitude(res, ref)
            if not cmp["epochs"]:
                raise SelfnavError(f"{reference}: its attitude does not overlap the IMU's time "
                                   "span after the start (another time base?)")
            summary["comparison"] = {"reference": ref.source, **cmp}
        if as_json:
            emit_json(summary)
            return
        e = summary["end"]
        print(f"{out}: {summary['rows']} rows; start {info['start']} at t = "
              f"{info['t_start']:.3f} s; declination {info['declination_deg']:.2f}° "
              f"({info['declination_source']})")
        print(f"  end: roll {e['roll_deg']:.2f}° ± {e['sigma_roll_deg']:.2f}°, pitch "
              f"{e['pitch_deg']:.2f}° ± {e['sigma_pitch_deg']:.2f}°, heading "
              f"{e['heading_deg']:.2f}° ± {e['sigma_heading_deg']:.2f}°")
        if "comparison" in summary:
            c = summary["comparison"]
            print(f"  against {c['reference']} after the start ({c['epochs']} epochs): "
                  + ", ".join(f"{n} RMS {c[n + '_rms_deg']:.2f}° max {c[n + '_max_deg']:.2f}°"
                              for n in ("roll", "pitch", "heading")))
