"""``selfnav match``: GNSS-only map matching onto an OpenStreetMap road graph (DESIGN §6)."""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from selfnav.cli.common import emit_json
from selfnav.errors import InputError


def _to_wgs84(lat, lon, h, datum, path):
    if datum is None:
        return lat, lon, h
    from selfnav.datum import convert, datum_key

    key = datum_key(datum)
    if key == "wgs84":
        return lat, lon, h
    return convert(lat, lon, h, key, "wgs84")


def run_match(gnss: Path, map_path: Path, out: Path, *, sigma_m=10.0, radius_m=None, beta_m=None,
              gnss_datum=None, out_datum=None):
    """Read, match, write; return the JSON summary (the library call behind the command)."""
    from selfnav.io.csvio import check_positive, check_time, read_table, write_csv
    from selfnav.roads.hmm import HmmMatcher
    from selfnav.roads.graph import read_roads

    tab = read_table(gnss, ("t", "lat_deg", "lon_deg"), optional=("h_m", "sigma_m"))
    t = check_time(tab, min_rows=1)
    sigma = check_positive(tab, "sigma_m")
    lat_deg, lon_deg = tab["lat_deg"], tab["lon_deg"]
    bad = ~(np.isfinite(lat_deg) & np.isfinite(lon_deg)) | (np.abs(lat_deg) > 90)
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(gnss, "latitude missing or outside ±90°: columns swapped or not degrees?",
                         row=int(tab["_lines"][k]), column="lat_deg")
    h = tab.get("h_m", np.zeros(len(t)))
    lat, lon, h = _to_wgs84(np.radians(lat_deg), np.radians(lon_deg), h, gnss_datum, gnss)
    graph = read_roads(map_path)
    x, y = graph.to_local(lat, lon)
    xmin, ymin, xmax, ymax = graph.bounds()
    margin = 1000.0
    inside = (x > xmin - margin) & (x < xmax + margin) & (y > ymin - margin) & (y < ymax + margin)
    if not inside.any():
        raise InputError(gnss, f"none of the {len(t)} fixes lies within {margin / 1e3:.0f} km of "
                         f"the map {map_path.name}: wrong map, or a datum/degree mix-up?")
    m = HmmMatcher(graph, sigma=sigma_m, radius=radius_m, beta=beta_m)
    res = m.match(t, np.column_stack([x, y]), sigma)
    olat, olon, oh = res.lat, res.lon, h
    if out_datum is not None:
        from selfnav.datum import convert, datum_key

        if datum_key(out_datum) != "wgs84":
            olat, olon, oh = convert(olat, olon, h, "wgs84", datum_key(out_datum))
    datum_name = "WGS-84" if out_datum is None else out_datum
    write_csv(out, {"t": t, "lat_deg": np.degrees(olat), "lon_deg": np.degrees(olon), "h_m": oh,
                    "cross_m": res.moved},
              comments=[f"selfnav match: GNSS {gnss.name} matched to roads of {map_path.name} "
                        f"(HMM, Newson & Krumm); datum {datum_name}",
                        "cross_m: distance from the fix to its matched road position, m",
                        "map data (c) OpenStreetMap contributors, ODbL"],
              fmt={"lat_deg": "%.10f", "lon_deg": "%.10f", "h_m": "%.4f", "cross_m": "%.3f"})
    s = res.summary()
    return {"gnss": str(gnss), "map": str(map_path), "out": str(out), **s,
            "outside_map": int((~inside).sum()), "map_nodes": graph.n_nodes,
            "map_segments": graph.n_segments, "sigma_m": m.sigma, "beta_m": m.beta,
            "radius_m": m.radius}


def register(app: typer.Typer) -> None:
    @app.command("match")
    def match_cmd(
        gnss: Path = typer.Option(..., "--gnss", help="GNSS CSV: t, lat_deg, lon_deg[, h_m, "
                                  "sigma_m] (WGS-84 unless --gnss-datum)."),
        map_path: Path = typer.Option(..., "--map", help="Road map: OpenStreetMap .osm or "
                                      ".osm.pbf."),
        out: Path = typer.Option(..., "--out", help="Solution CSV: t, lat_deg, lon_deg, h_m, "
                                 "cross_m."),
        sigma_m: float = typer.Option(10.0, "--sigma-m", help="GNSS horizontal sigma, m, where "
                                      "the file has no sigma_m column."),
        radius_m: Optional[float] = typer.Option(None, "--radius-m", help="Candidate search "
                                                 "radius, m (default clip(4 sigma, 30, 200))."),
        beta_m: Optional[float] = typer.Option(None, "--beta-m", help="Transition scale, m "
                                               "(default max(3, sigma/2))."),
        gnss_datum: Optional[str] = typer.Option(None, "--gnss-datum", help="Datum of the GNSS "
                                                 "file: wgs84 (default), pz90, pz90.11, sk42."),
        out_datum: Optional[str] = typer.Option(None, "--out-datum", help="Datum of the output "
                                                "(default wgs84)."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    ):
        """Match GNSS fixes to the road network (hidden Markov model, Viterbi): every fix gets
        a position on a road."""
        if sigma_m <= 0:
            raise InputError("--sigma-m", "must be positive")
        summary = run_match(gnss, map_path, out, sigma_m=sigma_m, radius_m=radius_m,
                            beta_m=beta_m, gnss_datum=gnss_datum, out_datum=out_datum)
        if as_json:
            emit_json(summary)
            return
        s = summary
        print(f"{s['fixes']} fixes matched to {Path(s['map']).name} "
              f"({s['map_nodes']} nodes, {s['map_segments']} directed segments) -> {s['out']}")
        print(f"  road within {s['radius_m']:.0f} m: {100 * s['matched_share']:.1f} %   "
              f"correction mean {s['mean_correction_m']:.2f} m, max "
              f"{s['max_correction_m']:.2f} m   restarts {s['restarts']}")
        print(f"  {s['seconds']:.3f} s ({s['fixes_per_second'] or 0:.0f} fixes/s)")
        if s["outside_map"]:
            print(f"  note: {s['outside_map']} fixes lie more than 1 km outside the map",
                  file=sys.stderr)
