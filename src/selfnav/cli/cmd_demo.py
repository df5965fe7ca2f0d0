"""``selfnav demo``: run the main job on data shipped with the package and write a report."""
from __future__ import annotations

from pathlib import Path

import typer

from selfnav.cli import options as opt
from selfnav.cli.common import emit_json


def register(app: typer.Typer) -> None:
    @app.command("demo")
    def demo_cmd(
        out: opt.out_folder("Folder for the report (index.html, latitude.json, three PNG "
                            "plots).") = Path("selfnav-demo"),
        as_json: opt.Json = False,
    ):
        """Latitude from the shipped real RLG recording (Xi'an); report in OUT/index.html."""
        from selfnav.demo import SITE_LAT_DEG, latitude_rows, run_demo

        from selfnav.cli.progress import bar

        with bar("selfnav demo", enabled=not as_json) as update:
            s = run_demo(out, progress=lambda x, description=None: update(x, description))
        if as_json:
            emit_json(s)
            return
        a = s["optimal"]
        print("selfnav demo — latitude from a real ring-laser-gyro IMU at rest (PSINS, Xi'an)")
        print(f"  {'site latitude':44s} {SITE_LAT_DEG:.4f}°")
        for label, lat, sig, err in latitude_rows(s):     # the rows of the HTML page
            print(f"  {label:44s} {lat:.4f}° ± {sig:.4f}° (1σ)  error {err:+.4f}°")
        print(f"  heading {a['heading_deg']:.3f}°  pitch {a['pitch_deg']:.4f}°  roll "
              f"{a['roll_deg']:.4f}°")
        for w in a["warnings"]:
            print(f"  note: {w}")
        nav = s["navigation_simulated"]
        print(f"selfnav demo — {nav['note']}:")
        for k, v in nav.items():
            if k != "note":
                print(f"  {k:20s} horizontal RMS {v['horizontal_rms_m']:6.1f} m, max "
                      f"{v['horizontal_max_m']:6.1f} m (over the drives)")
        print(f"  report: {out / 'index.html'}")
