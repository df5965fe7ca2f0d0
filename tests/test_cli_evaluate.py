"""`selfnav evaluate` never invents truth: no interpolation across holes in the truth, the share
compared reported; report folders written as one set (issue 12)."""
import json

import numpy as np
import pytest

from support import run_cli as run
from selfnav.io.trajectory import read_truth, write_truth
from selfnav.types import Trajectory


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    from selfnav import api

    d = tmp_path_factory.mktemp("drive")
    api.simulate_files("car", d, seed=5, duration=240.0)
    return d


def _noisy(truth, sigma_m, seed):
    rng = np.random.default_rng(seed)
    dlat = rng.normal(0, sigma_m, len(truth)) / 6.37e6
    dlon = rng.normal(0, sigma_m, len(truth)) / (6.37e6 * np.cos(truth.lat))
    return Trajectory(truth.t, truth.lat + dlat, truth.lon + dlon, truth.h, truth.velocity_n,
                      truth.C_nb, "simulated solution")


def test_truth_hole_is_not_interpolated(drive, tmp_path, capsys):
    truth = read_truth(drive / "truth.csv")
    sol = tmp_path / "sol.csv"
    write_truth(sol, _noisy(truth, 0.3, 1))
    hole = (truth.t > 100.0) & (truth.t < 160.0)         # 60 s without truth rows
    cut = tmp_path / "truth_hole.csv"
    write_truth(cut, truth.select(~hole))
    code, out, err = run(["evaluate", "--truth", drive / "truth.csv", "--solution", sol, "--json"],
                         capsys)
    full = json.loads(out)
    code, out, err = run(["evaluate", "--truth", cut, "--solution", sol, "--json"], capsys)
    assert code == 0, err
    d = json.loads(out)
    # the solution is the truth plus 0.3 m noise: compared only where the truth is
    assert d["horizontal_rms_m"] == pytest.approx(full["horizontal_rms_m"], rel=0.1)
    assert d["horizontal_rms_m"] < 0.6 and d["horizontal_max_m"] < 2.0
    # the share of the solution compared leaves out the epochs in the hole; the coverage of
    # the truth's time span (less its hole) stays whole: the solution covers all there is
    assert d["solution_compared"] == pytest.approx(1.0 - hole.sum() / len(truth), abs=1e-12)
    assert d["coverage"] == pytest.approx(1.0, abs=1e-9)
    assert d["truth_span_s"] == pytest.approx(240.0 - 60.1, abs=0.11)
    assert full["coverage"] == 1.0 and d["truth_holes"] == 1
    assert d["truth_hole_max_s"] == pytest.approx(60.1, abs=0.11)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("selfnav: warning:") and "hole" in lines[0]


def test_report_under_a_file_is_one_line_and_a_report_is_one_set(drive, tmp_path, capsys):
    (tmp_path / "afile").write_text("x")
    code, out, err = run(["evaluate", "--truth", drive / "truth.csv", "--solution",
                          drive / "truth.csv", "--report", tmp_path / "afile" / "rep"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "is a file, not a folder" in err
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "notes.txt").write_text("mine")
    code, out, err = run(["evaluate", "--truth", drive / "truth.csv", "--solution",
                          drive / "truth.csv", "--report", rep, "--json"], capsys)
    assert code == 0, err
    names = sorted(p.name for p in rep.iterdir())
    assert names == ["errors.png", "metrics.json", "notes.txt", "report.html", "track.png"]
    assert json.loads((rep / "metrics.json").read_text())["coverage"] == 1.0


def test_late_start_and_hole_count_against_the_truth_span(drive, tmp_path, capsys):
    """A solution that starts late (37.2 s of a 240 s truth) or has a hole covers that much
    of the truth's time span, whatever share of its own epochs was compared; the text says
    from when to when, and a warning says the metrics describe only that part (issue 22)."""
    truth = read_truth(drive / "truth.csv")
    late = tmp_path / "late.csv"
    write_truth(late, _noisy(truth, 0.3, 2).select(truth.t >= 37.2))
    code, out, err = run(["evaluate", "--truth", drive / "truth.csv", "--solution", late,
                          "--json"], capsys)
    assert code == 0, err
    d = json.loads(out)
    span = truth.t[-1] - truth.t[0]
    assert d["coverage"] == pytest.approx((truth.t[-1] - 37.2) / span, abs=1e-3)
    assert d["solution_compared"] == 1.0
    assert d["longest_uncovered_s"] == pytest.approx(37.2, abs=0.11)
    assert "covers 84.5 % of the truth's time span" in err and "from 37.2 s to 240.0 s" in err
    code, out, err = run(["evaluate", "--truth", drive / "truth.csv", "--solution", late], capsys)
    assert code == 0, err
    assert "from 37.2 s to 240.0 s of a 240.0 s truth" in out
    assert "coverage    84.5 % of the truth's time span" in out
    # a 60 s hole in the middle of the solution
    holed = tmp_path / "holed.csv"
    sol = _noisy(truth, 0.3, 3)
    write_truth(holed, sol.select((sol.t < 100.0) | (sol.t > 160.0)))
    code, out, err = run(["evaluate", "--truth", drive / "truth.csv", "--solution", holed,
                          "--json"], capsys)
    d = json.loads(out)
    assert d["coverage"] == pytest.approx(1.0 - 60.0 / span, abs=2e-3)
    assert d["solution_gaps"] == 1 and d["longest_uncovered_s"] == pytest.approx(60.0, abs=0.2)


def test_another_citys_map_is_refused(drive, capsys):
    """A drive simulated on Karhula evaluated against the Helsinki map: one line, exit 2, no
    road metrics (issue 22); the map of the drive gives them."""
    from selfnav.roads.graph import packaged_map

    code, out, err = run(["evaluate", "--truth", drive / "truth.csv", "--solution",
                          drive / "truth.csv", "--map", packaged_map("helsinki_centre"),
                          "--json"], capsys)
    assert code == 2 and out == "" and "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "helsinki_centre" in lines[0] and "another place" in lines[0]
    code, out, err = run(["evaluate", "--truth", drive / "truth.csv", "--solution",
                          drive / "truth.csv", "--map", packaged_map("kotka_karhula"), "--json"],
                         capsys)
    assert code == 0, err
    assert json.loads(out)["road_cross_track_rms_m"] < 1e-6
