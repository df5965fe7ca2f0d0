"""``selfnav spp``: single-point positioning from raw GNSS measurements (docs/gnss.md)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, List, Optional

import typer

from selfnav.cli import options as opt
from selfnav.cli.common import emit_json


def register(app: typer.Typer) -> None:
    @app.command("spp")
    def spp_cmd(
        gnss_raw: Annotated[Path, typer.Option(
            "--gnss-raw", help="Raw measurements: RINEX 2/3 observation file, u-blox .ubx "
                               "(RXM-RAWX + RXM-SFRBX), Android GnssLogger log (Raw lines), "
                               "smartLoc *_Input.txt, PSINS insgpseo .mat.")],
        out: opt.out_file("Solution CSV: t (GPS s of the first week), lat_deg, lon_deg, h_m, "
                          "ve, vn, vu, σ, excluded satellites per epoch (docs/gnss.md)."),
        nav: Annotated[Optional[List[Path]], typer.Option(
            "--nav", help="RINEX 2/3 navigation file with the broadcast ephemerides (and "
                          "Klobuchar parameters); repeat for several.")] = None,
        fmt: Annotated[str, opt.choice_option(
            "--format", choices=opt.RAW_FORMATS,
            help="Format of --gnss-raw; auto: by name and content.")] = "auto",
        elevation_mask_deg: Annotated[float, typer.Option(
            "--elevation-mask-deg", min=0.0, max=90.0,
            help="Satellites below this elevation are not used.")] = 5.0,
        smoothing_s: Annotated[float, typer.Option(
            "--smoothing-s", min=0.0,
            help="Time constant of the Doppler-aided code smoothing, s (0: off).")] = 30.0,
        systems: Annotated[Optional[str], typer.Option(
            "--systems", metavar="LETTERS",
            help="Constellations to use, RINEX letters (e.g. GEC); default all "
                              "of G, R, E, C, J.")] = None,
        fde: Annotated[bool, typer.Option(
            "--fde/--no-fde", help="Exclude faulty satellites (largest consistent subset, "
                                   "several at once).")] = True,
        sat_log: Annotated[Optional[Path], typer.Option(
            "--sat-log", help="Also write per satellite and epoch: t, sat, used, residual_m, "
                              "elevation, azimuth, iono, tropo (CSV).")] = None,
        receiver_out: Annotated[Optional[Path], typer.Option(
            "--receiver-out", help="Also write the receiver's own solution (u-blox NAV-PVT, "
                                   "Android Fix) as a solution CSV on the same time base, "
                                   "with its quality flag: a reference for selfnav "
                                   "evaluate.")] = None,
        as_json: opt.Json = False,
    ):
        """Positions, Doppler velocities and per-epoch satellite exclusions from raw
        pseudoranges and broadcast ephemerides."""
        from selfnav import api
        from selfnav.io.output import check_output_file

        check_output_file(out)
        for p in (sat_log, receiver_out):
            if p is not None:
                check_output_file(p)
        letters = None
        if systems:
            letters = [c for c in systems.upper() if not c.isspace() and c != ","]
            bad = [c for c in letters if c not in "GRECJ"]
            if bad:
                raise typer.BadParameter(f"'{''.join(bad)}' is not a system letter (G, R, E, C, "
                                         "J)", param_hint="--systems")
        raw = api.read_gnss_raw(gnss_raw, nav or None, fmt=fmt)
        sol = api.spp(raw, elevation_mask_deg=elevation_mask_deg, smoothing_s=smoothing_s,
                      fde=fde, systems=letters)
        sol.to_csv(out, comments=[f"selfnav spp {gnss_raw.name}",
                                  "t: GPS seconds from the start of GPS week "
                                  f"{sol.stats['week0']}" if sol.stats["week0"] else
                                  "t: the file's time"])
        if sat_log is not None:
            api.write_sat_log(sat_log, sol)
        if receiver_out is not None:
            api.receiver_solution(raw).to_csv(receiver_out,
                                              comments=[f"receiver solution of {gnss_raw.name}"])
        st = sol.stats
        if as_json:
            emit_json({k: st[k] for k in (
                "epochs", "epochs_out", "no_fix", "satellites", "observations", "systems",
                "excluded", "epochs_with_exclusion", "doppler_excluded", "passed",
                "median_sigma_h_m", "sigma_scale_median") if k in st}
                | {"ionosphere": st.get("ionosphere", "none"), "out": str(out)})
            return
        print(f"{gnss_raw}: {st['epochs_out']} fixes of {st['epochs']} epochs, "
              f"{st['satellites']} satellites; {st['excluded']} pseudoranges excluded in "
              f"{st['epochs_with_exclusion']} epochs; median σ_h {st['median_sigma_h_m']:.2f} m")
        print(f"  written: {out}")
