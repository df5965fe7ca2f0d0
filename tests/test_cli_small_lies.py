"""The small lies of issue 22, each through the command line (simulated data unless named)."""
import json

import numpy as np
import pytest
import typer.main

from selfnav.cli import app
from selfnav.cli.options import HELP_PANELS, OTHER_PANEL, help_panel
from support import run_cli as run


@pytest.fixture(scope="module")
def sims(tmp_path_factory):
    from selfnav import api

    d = tmp_path_factory.mktemp("sims")
    for grade in ("navigation", "perfect"):
        for seed in (0, 1):
            api.simulate_files("static", d / f"{grade}{seed}", seed=seed, grade=grade,
                               duration=600.0)
    api.simulate_files("car", d / "car", seed=1, duration=120.0)
    api.simulate_files("ship", d / "ship", seed=1, duration=120.0)
    return d


@pytest.mark.parametrize("name", ["navigation0", "navigation1", "perfect0", "perfect1"])
def test_clean_simulated_static_data_raises_no_warning(sims, capsys, name):
    """A navigation-grade or perfect IMU that never moved: no 'disturbed rest' (the
    accelerometer's bias drift is not a tilt that matters), no 'off Earth rate' (the file's
    rounding is not a gyro error), and the latitude within 3σ of the truth."""
    code, out, err = run(["latitude", sims / name / "imu.csv", "--json"], capsys)
    assert code == 0, err
    assert err == "", err
    d = json.loads(out)
    assert d["rest"] == "still" and d["method"] == "optimal"
    assert abs(d["latitude_deg"] - 50.45) < max(3 * d["sigma_deg"], 1e-6)


@pytest.mark.parametrize("name", ["car", "ship"])
def test_allan_on_a_moving_base_warns(sims, capsys, name):
    code, out, err = run(["allan", sims / name / "imu.csv", "--json"], capsys)
    assert code == 0, err
    lines = err.strip().splitlines()
    assert any(ln.startswith("selfnav: warning:") and "not at rest" in ln and "turning" in ln
               for ln in lines), err


def test_allan_at_rest_says_nothing(sims, capsys):
    code, out, err = run(["allan", sims / "navigation0" / "imu.csv", "--json"], capsys)
    assert code == 0 and "not at rest" not in err


def test_latitude_result_in_degrees_and_labelled(shared_data):
    """The real Xi'an record: degree fields equal to_dict's; the plain estimate on this
    disturbed record is labelled 'plain', not 'optimal'."""
    import warnings

    from selfnav import estimate_latitude, read_imu

    imu = read_imu(shared_data / "psins_lasergyro_static" / "lasergyro.imu")
    with pytest.warns(Warning, match="disturbed rest"):
        r = estimate_latitude(imu)
    d = r.to_dict()
    assert r.latitude_deg == pytest.approx(d["latitude_deg"]) == pytest.approx(34.175, abs=1e-3)
    assert r.lat_deg == r.latitude_deg and r.sigma_deg == pytest.approx(d["sigma_deg"])
    assert (r.heading_deg, r.pitch_deg, r.roll_deg) == pytest.approx(
        (d["heading_deg"], d["pitch_deg"], d["roll_deg"]))
    assert d["method"] == "optimal" and d["rest"] == "disturbed"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = estimate_latitude(imu, rest="still").to_dict()
    assert plain["method"] == "plain" and "no tilt compensation" in plain["estimate"]


def test_moving_takes_imu_format_and_the_old_spelling(sims, tmp_path, capsys):
    base = ["moving", "--imu", sims / "ship" / "imu.csv", "--attitude",
            sims / "ship" / "truth.csv", "--lat0-deg", "30", "--lon0-deg", "30", "--json"]
    a = run(base + ["--out", tmp_path / "a.csv", "--imu-format", "csv"], capsys)
    b = run(base + ["--out", tmp_path / "b.csv", "--format", "csv"], capsys)
    assert a[0] == 0 and b[0] == 0, (a[2], b[2])
    assert json.loads(a[1])["latitude_end_deg"] == json.loads(b[1])["latitude_end_deg"]
    code, out, err = run(["moving", "--help"], capsys)
    assert "--imu-format" in out and "--format" not in out.replace("--imu-format", "")


def test_evaluate_report_with_a_map_prints_no_library_noise(sims, tmp_path, capsys):
    d = sims / "car"
    code, out, err = run(["evaluate", "--truth", d / "truth.csv", "--solution", d / "truth.csv",
                          "--map", next(d.glob("*.osm.pbf")), "--report", tmp_path / "r"], capsys)
    assert code == 0
    assert err == "", err          # no "Ignoring fixed x limits..." from matplotlib
    html = (tmp_path / "r" / "report.html").read_text()
    assert "Coverage of the truth&#x27;s time span" in html or "Coverage of the truth's" in html


def test_every_option_is_in_a_help_panel(capsys):
    """navigate's ~30 options (and every other command's) are grouped in --help; a new option
    without a panel fails here (add it to options.HELP_PANELS)."""
    group = typer.main.get_command(app)
    for name, cmd in group.commands.items():
        for p in cmd.params:
            if p.param_type_name == "option" and not getattr(p, "hidden", False) \
                    and p.name != "help":
                assert help_panel(name, p) != OTHER_PANEL, (name, p.name)
    code, out, err = run(["navigate", "--help"], capsys)
    assert code == 0
    heads = [ln[:-1] for ln in out.splitlines() if ln.endswith(":") and not ln.startswith(" ")]
    assert [h for h in heads if h in HELP_PANELS["navigate"]] == list(HELP_PANELS["navigate"])
    assert out.index("Inputs:") < out.index("--imu ") < out.index("Outputs:") < out.index("--out ")
