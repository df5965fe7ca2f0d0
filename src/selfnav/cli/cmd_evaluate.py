"""``selfnav evaluate``: errors of a solution against truth, plots, an HTML report (DESIGN §6)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from selfnav.cli import options as opt
from selfnav.cli.common import emit_json


def register(app: typer.Typer) -> None:
    @app.command("evaluate")
    def evaluate_cmd(
        truth: Annotated[Path, typer.Option(
            "--truth", help="Truth CSV (t, lat_deg, lon_deg[, h_m, ve, vn, vu, roll_deg, "
                            "pitch_deg, heading_deg]), WGS-84.")],
        solution: Annotated[Path, typer.Option(
            "--solution", help="Solution CSV, same columns.")],
        as_json: opt.Json = False,
        report: Annotated[Optional[Path], typer.Option(
            "--report", help="Write errors.png, track.png, metrics.json and report.html into "
                             "this FOLDER (created with its parents; the four files are "
                             "replaced as one set).")] = None,
        map_path: Annotated[Optional[Path], typer.Option(
            "--map", help="Road map (OpenStreetMap .osm/.osm.pbf): road-relative "
                          "along/cross-track and the map under the track.")] = None,
    ):
        """Horizontal RMS / 95 % / max and vertical RMS error; along/cross-track; coverage
        (the share of the truth's time span the solution covers; the truth is never
        interpolated across its holes)."""
        from selfnav import api
        from selfnav.io.output import check_output_folder

        if report is not None:
            check_output_folder(report)
        from selfnav.cli.progress import bar

        with bar("evaluating" + (" and writing the report" if report is not None else ""),
                 enabled=not as_json):
            out = api.evaluate_report(truth, solution, roads=map_path, report=report,
                                      title=f"selfnav evaluate: {solution.name} against "
                                            f"{truth.name}")
        if as_json:
            emit_json(out)
            return
        m = out
        from selfnav.summary import span_text

        span = span_text(m["t_start_s"], m["t_end_s"], m["truth_start_s"], m["truth_end_s"],
                         "truth")
        print(f"{solution} against {truth}: {m['samples']} epochs {span}")
        print(f"  coverage    {100 * m['coverage']:.1f} % of the truth's time span"
              f"{' less its holes' if m['truth_holes'] else ''} "
              f"({m['covered_s']:.1f} of {m['truth_span_s']:.1f} s); "
              f"{100 * m['solution_compared']:.1f} % of the solution's epochs compared")
        print(f"  horizontal  RMS {m['horizontal_rms_m']:.3f} m   95 % {m['horizontal_p95_m']:.3f}"
              f" m   max {m['horizontal_max_m']:.3f} m")
        print(f"  vertical    RMS {m['vertical_rms_m']:.3f} m   max {m['vertical_max_m']:.3f} m")
        print(f"  along-track RMS {m['along_track_rms_m']:.3f} m   cross-track RMS "
              f"{m['cross_track_rms_m']:.3f} m (truth heading)")
        if "road_along_track_rms_m" in m:
            print(f"  along-track RMS {m['road_along_track_rms_m']:.3f} m   cross-track RMS "
                  f"{m['road_cross_track_rms_m']:.3f} m (road)")
        if report is not None:
            print(f"  report: {out['report']}")
