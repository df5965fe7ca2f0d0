"""The Python API (issue 11): the functions exist, read the files the CLI reads, and give what
the command line gives — navigate to 1e-7°, match and evaluate to the same figures.
Simulated data (labelled: `selfnav simulate car`)."""
import json
import types

import numpy as np
import pytest

import selfnav
from selfnav.cli import main
from support import run_cli as run

API = ("read_imu", "read_gnss", "read_roads", "read_solution", "estimate_latitude", "navigate",
       "match", "evaluate", "navigate_moving", "simulate")


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    assert main(["simulate", "car", "--out", str(d), "--seed", "7", "--duration", "120",
                 "--grade", "industrial"]) == 0
    return d


def test_the_api_is_the_package_face():
    # every submodule imported first: none may shadow an API function of the same name
    # (``selfnav.evaluate`` was once the module after ``import selfnav.evaluate``)
    import importlib
    import pkgutil

    for m in pkgutil.walk_packages(selfnav.__path__, "selfnav."):
        if ".cli" not in m.name and not m.name.endswith("__main__"):
            importlib.import_module(m.name)
    for name in API:
        assert not isinstance(getattr(selfnav, name), types.ModuleType), name
        assert callable(getattr(selfnav, name)), name
        assert getattr(selfnav, name).__doc__, f"{name} has no docstring"
    assert set(API) <= set(selfnav.__all__)


@pytest.mark.filterwarnings("ignore:.*of the GNSS fixes were not used:selfnav.errors.SelfnavWarning")  # expected here
def test_navigate_equals_the_command_line(sim, tmp_path, capsys):
    out = tmp_path / "cli.csv"
    code, _, err = run(["navigate", "--imu", sim / "imu.csv", "--gnss", sim / "gnss.csv",
                        "--out", out, "--grade", "industrial"], capsys)
    assert code == 0, err
    cli = selfnav.read_solution(out).trajectory
    sol = selfnav.navigate(selfnav.read_imu(sim / "imu.csv"), selfnav.read_gnss(sim / "gnss.csv"),
                           grade="industrial")
    api = sol.trajectory
    assert len(api.t) == len(cli.t)
    np.testing.assert_allclose(api.t, cli.t, atol=1e-9)
    # the file carries the CLI's rounding; the API result agrees with it to 1e-7°
    assert np.max(np.abs(np.degrees(api.lat) - np.degrees(cli.lat))) < 1e-7
    assert np.max(np.abs(np.degrees(api.lon) - np.degrees(cli.lon))) < 1e-7
    # and the API writes the same file
    again = tmp_path / "api.csv"
    sol.to_csv(again)
    back = selfnav.read_solution(again).trajectory
    np.testing.assert_allclose(back.lat, cli.lat, atol=1e-12)


def test_match_and_evaluate_equal_the_command_line(sim, tmp_path, capsys):
    pbf = next(sim.glob("*.osm.pbf"))
    gnss = selfnav.read_gnss(sim / "gnss.csv")
    m = selfnav.match(gnss, pbf)          # a path: read as the command reads it (every way)
    out = tmp_path / "m.csv"
    code, _, err = run(["match", "--gnss", sim / "gnss.csv", "--map", pbf, "--out", out], capsys)
    assert code == 0, err
    cli = selfnav.read_solution(out).trajectory
    assert np.max(np.abs(np.degrees(m.trajectory.lat) - np.degrees(cli.lat))) < 1e-7
    truth = selfnav.read_solution(sim / "truth.csv")
    metrics = selfnav.evaluate(truth, selfnav.read_solution(out))
    code, js, err = run(["evaluate", "--truth", sim / "truth.csv", "--solution", out, "--json"],
                        capsys)
    assert code == 0, err
    assert json.loads(js)["horizontal_rms_m"] == pytest.approx(metrics["horizontal_rms_m"],
                                                               rel=1e-9)
