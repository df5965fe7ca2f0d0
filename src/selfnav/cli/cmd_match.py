"""``selfnav match``: GNSS-only map matching of one track or a fleet onto OpenStreetMap roads
(DESIGN §6; issue 14). Parses, calls :func:`selfnav.api.match_files`, formats (imported from
:mod:`selfnav.roads.fleet`, where it lives: :mod:`selfnav.api` also loads the inertial stack,
~1 s of start-up the command does not need)."""
from __future__ import annotations

import contextlib
import sys
import warnings
from enum import Enum
from pathlib import Path
from typing import List, Optional

import typer

from selfnav.cli import options as opt
from selfnav.cli.common import emit_json
from selfnav.errors import InputError


class Datum(str, Enum):
    wgs84 = "wgs84"
    pz90_11 = "pz90.11"
    pz90 = "pz90"
    sk42 = "sk42"


@contextlib.contextmanager
def _one_line_warnings():
    """Each :class:`~selfnav.errors.SelfnavWarning` as one ``selfnav: warning: ...`` line on
    stderr (other libraries' warnings hidden)."""
    from selfnav.errors import SelfnavWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("ignore")
        warnings.simplefilter("always", SelfnavWarning)
        try:
            yield
        finally:
            seen = set()
            for w in caught:
                text = str(w.message).replace("\n", " ")
                if issubclass(w.category, SelfnavWarning) and text not in seen:
                    seen.add(text)
                    print(f"selfnav: warning: {text}", file=sys.stderr)


@contextlib.contextmanager
def _progress_bar(enabled: bool):
    """A rich progress bar over tracks on stderr (only on a terminal); yields the callback."""
    if not enabled or not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                               TimeElapsedColumn, TimeRemainingColumn)

    with Progress(TextColumn("matching tracks"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), TimeRemainingColumn(), console=Console(stderr=True),
                  transient=True) as bar:
        task = bar.add_task("tracks", total=None)

        def update(done, total):
            bar.update(task, completed=done, total=total)

        yield update


def register(app: typer.Typer) -> None:
    @app.command("match")
    def match_cmd(
        gnss: List[Path] = typer.Option(..., "--gnss", help="GNSS file(s) or folder(s), CSV or "
                                        "Parquet: t, lat_deg, lon_deg[, h_m, sigma_m, track_id]; "
                                        "t in seconds or ISO-8601 (WGS-84 unless --gnss-datum). "
                                        "Repeatable."),
        map_path: Path = typer.Option(..., "--map", help="Road map: OpenStreetMap .osm or "
                                      ".osm.pbf."),
        out: Path = typer.Option(..., "--out", parser=opt.file_path, metavar="FILE", help="Matched fixes, .csv or .parquet: "
                                 "[track_id,] t, lat_deg, lon_deg, h_m, cross_m, way_id, "
                                 "matched, match_p, piece."),
        route_out: Optional[Path] = typer.Option(None, "--route-out", help="Each track's driven "
                                                 "route as GeoJSON (OSM way ids)."),
        workers: Optional[int] = typer.Option(None, "--workers", help="Local Dask workers "
                                              "(processes); 0 = in this process. Default: in "
                                              "this process below 200,000 fixes, else one per "
                                              "core."),
        scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Address of an "
                                                "existing Dask scheduler (tcp://host:8786)."),
        sigma_m: Optional[float] = typer.Option(None, "--sigma-m", help="GNSS horizontal "
                                                "sigma, m, where the file has no sigma_m "
                                                "column (default: estimated per track from its "
                                                "fixes)."),
        radius_m: Optional[float] = typer.Option(None, "--radius-m", help="Candidate search "
                                                 "radius, m (default clip(4 sigma, 30, 200))."),
        beta_m: Optional[float] = typer.Option(None, "--beta-m", help="Transition scale, m "
                                               "(default max(3, sigma/2))."),
        gnss_datum: Datum = typer.Option(Datum.wgs84, "--gnss-datum", case_sensitive=False,
                                         help="Datum of the GNSS file(s)."),
        out_datum: Datum = typer.Option(Datum.wgs84, "--out-datum", case_sensitive=False,
                                        help="Datum of the output."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    ):
        """Match GNSS fixes to the road network (hidden Markov model, Viterbi): every fix gets
        a position on a road, a match_p (posterior of that road) and a matched flag (the match
        is plausible); the chain breaks where no transition is. A file with a track_id column
        (or several files) is a fleet: each track is matched on its own, in parallel on Dask
        when large."""
        from selfnav.roads.fleet import match_files

        if sigma_m is not None and sigma_m <= 0:
            raise InputError("--sigma-m", "must be positive")
        with _one_line_warnings(), _progress_bar(not as_json) as progress:
            s = match_files(gnss, map_path, out, route_out=route_out, sigma_m=sigma_m,
                                radius_m=radius_m, beta_m=beta_m, gnss_datum=gnss_datum.value,
                                out_datum=out_datum.value, workers=workers,
                                scheduler=scheduler, progress=progress)
        if as_json:
            emit_json(s)
            return
        tracks = (f"{s['tracks_matched']} of {s['tracks']} tracks, " if s["tracks"] > 1 else "")
        print(f"{tracks}{s['fixes']} fixes matched to {Path(s['map']).name} "
              f"({s['map_nodes']} nodes, {s['map_segments']} directed segments) -> {s['out']}")
        print(f"  matched (plausible): {100 * s['matched_share']:.1f} %   "
              f"correction mean {s['mean_correction_m']:.2f} m, max "
              f"{s['max_correction_m']:.2f} m   breaks {s['breaks']}"
              + (f"   tracks below 90 % matched: {s['tracks_below_90pct_matched']}"
                 if s["tracks"] > 1 else ""))
        if s["map_snapped"]:
            print(f"  map: {s['map_snapped']} dead ends of unjoined ways snapped within "
                  f"{s['snap_m']:g} m")
        print(f"  {s['seconds']:.2f} s end to end ({s['fixes_per_second'] or 0:,.0f} fixes/s; "
              f"matching {s['matcher_fixes_per_second'] or 0:,.0f} fixes/s per core, "
              f"{s['mode']}{'' if not s['workers'] else ', %d workers' % s['workers']})")
        if s["route_out"]:
            print(f"  routes: {s['route_out']}")
        if s["outside_map"]:
            print(f"  note: {s['outside_map']} fixes lie more than 1 km outside the map",
                  file=sys.stderr)
