"""``selfnav evaluate``: errors of a solution against truth, plots, an HTML report (DESIGN §6)."""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import typer

from selfnav.cli.common import emit_json


def register(app: typer.Typer) -> None:
    @app.command("evaluate")
    def evaluate_cmd(
        truth: Path = typer.Option(..., "--truth", help="Truth CSV (t, lat_deg, lon_deg[, h_m, "
                                   "ve, vn, vu, roll_deg, pitch_deg, heading_deg]), WGS-84."),
        solution: Path = typer.Option(..., "--solution", help="Solution CSV, same columns."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
        report: Optional[Path] = typer.Option(None, "--report", help="Folder for errors.png, "
                                              "track.png, metrics.json and report.html."),
        map_path: Optional[Path] = typer.Option(None, "--map", help="Road map (OpenStreetMap "
                                                ".osm/.osm.pbf): road-relative along/cross-track "
                                                "and the map under the track (needs "
                                                "selfnav.roads.graph)."),
    ):
        """Horizontal RMS / 95 % / max and vertical RMS error; along/cross-track."""
        from selfnav.evaluate import evaluate, load_road_polylines
        from selfnav.io.trajectory import read_truth

        tr = read_truth(truth)
        sol = read_truth(solution)
        roads = load_road_polylines(map_path) if map_path is not None else None
        ev = evaluate(tr, sol, roads=roads, truth_name=str(truth), solution_name=str(solution))
        out = {"truth": str(truth), "solution": str(solution), **ev.metrics,
               "warnings": list(ev.warnings)}
        if report is not None:
            from selfnav.report import write_report

            files = write_report(ev, report, roads=roads,
                                 title=f"selfnav evaluate: {solution.name} against {truth.name}",
                                 sources={"truth": truth, "solution": solution})
            out["report"] = files["report.html"]
            out["figures"] = [files["errors.png"], files["track.png"]]
        if as_json:
            emit_json(out)
            return
        m = ev.metrics
        print(f"{solution} against {truth}: {m['samples']} epochs over {m['duration_s']:.1f} s")
        print(f"  horizontal  RMS {m['horizontal_rms_m']:.3f} m   95 % {m['horizontal_p95_m']:.3f}"
              f" m   max {m['horizontal_max_m']:.3f} m")
        print(f"  vertical    RMS {m['vertical_rms_m']:.3f} m   max {m['vertical_max_m']:.3f} m")
        print(f"  along-track RMS {m['along_track_rms_m']:.3f} m   cross-track RMS "
              f"{m['cross_track_rms_m']:.3f} m (truth heading)")
        if "road_along_track_rms_m" in m:
            print(f"  along-track RMS {m['road_along_track_rms_m']:.3f} m   cross-track RMS "
                  f"{m['road_cross_track_rms_m']:.3f} m (road)")
        for w in ev.warnings:
            print(f"  note: {w}", file=sys.stderr)
        if report is not None:
            print(f"  report: {out['report']}")
