"""What a new user sees (issue 22): the one-line compile notice on a cold numba cache, and the
HTML reports as a browser renders them (headless Chromium screenshot; simulated data)."""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from selfnav.cli.progress import COMPILE_LINE
from support import run_cli as run

SRC = Path(__file__).resolve().parents[1] / "src"


def _selfnav(args, env):
    return subprocess.run([sys.executable, "-m", "selfnav", *map(str, args)], env=env,
                          capture_output=True, text=True, timeout=600)


@pytest.mark.slow
def test_compile_line_on_a_cold_cache_only(tmp_path):
    """A cold numba cache (an empty NUMBA_CACHE_DIR) prints the line once, before the work;
    the second run loads the cache and prints nothing of the kind."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = _selfnav(["simulate", "static", "--out", tmp_path / "s", "--duration", "30",
                  "--grade", "navigation"], env)
    assert r.returncode == 0, r.stderr
    first = _selfnav(["latitude", tmp_path / "s" / "imu.csv", "--json"], env)
    assert first.returncode == 0, first.stderr
    assert first.stderr.splitlines().count(COMPILE_LINE) == 1
    assert json.loads(first.stdout)["samples"] == 3000          # stdout stays one JSON object
    second = _selfnav(["latitude", tmp_path / "s" / "imu.csv", "--json"], env)
    assert second.returncode == 0 and COMPILE_LINE not in second.stderr


# ------------------------------------------------------------------ pages in a browser
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
#: the flags this workplace's machines need (no network, root, no GPU)
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--hide-scrollbars")


def screenshot(page: Path, png: Path, size=(1000, 2600)) -> np.ndarray:
    """Render ``page`` in headless Chromium to ``png``; returns the image (H, W, 3) floats."""
    import matplotlib.image as mpimg

    r = subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={png.parent / 'profile'}",
                        f"--window-size={size[0]},{size[1]}", f"--screenshot={png}",
                        page.resolve().as_uri()], capture_output=True, text=True, timeout=180)
    assert png.is_file(), r.stderr[-2000:]
    return mpimg.imread(png)[..., :3]


def _figure_rows(img) -> int:
    """Rows of the screenshot that hold a picture: many distinct colours (text is black on
    white; a plot has lines, a legend and coloured tracks)."""
    q = (img * 15).astype(int)
    keys = q[..., 0] * 256 + q[..., 1] * 16 + q[..., 2]
    return int(sum(len(np.unique(row)) > 6 for row in keys))


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium is not installed (Debian "
                    "package chromium: apt-get install -y chromium)")
def test_evaluate_report_renders_with_its_figures(tmp_path, capsys):
    from selfnav import api

    d = tmp_path / "drive"
    api.simulate_files("car", d, seed=5, duration=120.0)
    rep = tmp_path / "rep"
    code, out, err = run(["evaluate", "--truth", d / "truth.csv", "--solution", d / "truth.csv",
                          "--map", next(d.glob("*.osm.pbf")), "--report", rep], capsys)
    assert code == 0, err
    html = (rep / "report.html").read_text()
    assert "Horizontal error, RMS" in html and "horizontal_rms_m</th>" not in html
    img = screenshot(rep / "report.html", tmp_path / "report.png")
    assert img.shape[1] >= 900
    # both figures are drawn: several hundred picture rows, and the page is not blank
    assert _figure_rows(img) > 600
    assert img.mean() < 0.985


@pytest.mark.slow
@pytest.mark.long
def test_demo_runs_on_shipped_data_and_its_page_renders_its_three_figures(tmp_path, capsys,
                                                                           monkeypatch):
    """README's first command: the terminal summary, the JSON, the page and its figures, from
    one run of the demo (45-80 s; two runs were the slowest two tests of CI)."""
    import selfnav.demo

    real, kept = selfnav.demo.run_demo, {}

    def run_demo(out, progress=None):
        kept["summary"] = real(out, progress=progress)
        return kept["summary"]

    monkeypatch.setattr(selfnav.demo, "run_demo", run_demo)
    code, out, err = run(["demo", "--out", tmp_path / "demo"], capsys)
    assert code == 0, err
    html = (tmp_path / "demo" / "index.html").read_text()
    for name in ("latitude_windows.png", "navigation.png", "navigation_errors.png"):
        assert f'src="{name}"' in html and (tmp_path / "demo" / name).stat().st_size > 10000
    # every σ of the page's latitude table is in the terminal's summary too
    for row in html.split("<tr>")[2:5]:
        sigma = row.split("<td>")[3].split("</td>")[0]
        assert f"± {sigma}° (1σ)" in out, (sigma, out)
    on_disk = json.loads((tmp_path / "demo" / "latitude.json").read_text())
    assert abs(on_disk["error_deg"]) < 0.1
    # --json prints the same run's summary as one JSON object (the run itself is the one above)
    monkeypatch.setattr(selfnav.demo, "run_demo", lambda out, progress=None: kept["summary"])
    code, out, err = run(["demo", "--out", tmp_path / "demo2", "--json"], capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d["error_deg"] == on_disk["error_deg"] and abs(d["error_deg"]) < 0.1
    assert set(d["navigation_simulated"]) == set(kept["summary"]["navigation_simulated"])
    if CHROMIUM is None:
        pytest.skip("the page's screenshot: headless Chromium is not installed (Debian package "
                    "chromium: apt-get install -y chromium)")
    img = screenshot(tmp_path / "demo" / "index.html", tmp_path / "demo.png", (1000, 3600))
    assert _figure_rows(img) > 900
