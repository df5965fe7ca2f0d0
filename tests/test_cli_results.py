"""What a user gets back (issue 22), through the command line: a late-starting solution says
what it covers, the solution file reads back whole (selfnav and plain pandas), and an output
FILE named like a folder is refused. Simulated data (a car on the shipped Karhula map)."""
import json

import numpy as np
import pandas as pd
import pytest

from selfnav import read_solution
from selfnav.summary import coverage, covered_intervals, span_text
from support import run_cli as run

START_S = 30.0
STATUSES = {"gnss", "dead-reckoning", "suspect"}


@pytest.fixture(scope="module")
def late(tmp_path_factory):
    """A 90 s simulated drive whose GNSS fixes start only at 30 s, navigated once."""
    from selfnav.cli import main

    d = tmp_path_factory.mktemp("late")
    assert main(["simulate", "car", "--out", str(d), "--seed", "4", "--duration", "90",
                 "--grade", "industrial", "--json"]) == 0
    lines = (d / "gnss.csv").read_text().splitlines()
    keep = [ln for ln in lines if ln.startswith(("#", "t,")) or float(ln.split(",")[0]) >= START_S]
    (d / "gnss_late.csv").write_text("\n".join(keep) + "\n")
    return d


@pytest.fixture(scope="module")
def navigated(late, tmp_path_factory):
    from selfnav.cli import main
    import contextlib
    import io

    out = tmp_path_factory.mktemp("sol") / "sol.csv"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["navigate", "--imu", str(late / "imu.csv"), "--gnss",
                     str(late / "gnss_late.csv"), "--out", str(out), "--grade", "industrial",
                     "--json"])
    assert code == 0
    return out, json.loads(buf.getvalue())


def test_late_solution_says_what_it_covers(late, navigated, capsys):
    out, d = navigated
    assert d["t_first_s"] >= START_S and d["t_last_s"] == pytest.approx(90.0, abs=0.3)
    assert d["imu_duration_s"] == pytest.approx(90.0, abs=0.02)
    assert d["coverage"] == pytest.approx((d["t_last_s"] - d["t_first_s"]) / d["imu_duration_s"],
                                          abs=0.01)
    assert d["coverage"] < 0.67
    assert d["span"] == (f"from {d['t_first_s']:.1f} s to {d['t_last_s']:.1f} s of a "
                         f"{d['imu_duration_s']:.1f} s IMU record")
    # evaluate measures against the truth's span, not the solution's
    code, o, err = run(["evaluate", "--truth", late / "truth.csv", "--solution", out, "--json"],
                       capsys)
    assert code == 0, err
    m = json.loads(o)
    assert m["coverage"] == pytest.approx(d["coverage"], abs=0.01)
    assert m["solution_compared"] == 1.0
    assert "of the truth's time span" in err


def test_late_solution_text_summary(late, tmp_path, capsys):
    code, o, err = run(["navigate", "--imu", late / "imu.csv", "--gnss", late / "gnss_late.csv",
                        "--out", tmp_path / "s.csv", "--grade", "industrial"], capsys)
    assert code == 0, err
    first = o.splitlines()[0]
    assert " of a 90.0 s IMU record (" in first and "% covered)" in first
    assert float(first.split(" from ")[1].split(" s ")[0]) >= START_S


def test_solution_reads_back_whole(navigated):
    out, d = navigated
    header = out.read_text().splitlines()[0].split(",")
    assert header[:4] == ["t", "lat_deg", "lon_deg", "h_m"]
    sol = read_solution(out)
    assert len(sol) == d["epochs"]
    # every column of the file is there: the σ, sigma_h_m and the status words
    assert sol.sigma_enu.shape == (len(sol), 3)
    assert {"sigma_h_m", "status", "protection_level_m"} <= set(sol.columns)
    assert set(header) == set(sol.table())
    assert set(sol.columns["status"]) <= STATUSES
    assert np.allclose(sol.columns["sigma_h_m"], np.hypot(sol.sigma_enu[:, 0], sol.sigma_enu[:, 1]),
                       atol=2e-4)
    # the sidecar gives what produced it
    assert sol.method == "ekf" and sol.stats["fix_status"] == d["fix_status"]
    side = json.loads(out.with_name(out.name + ".json").read_text())
    assert side["datum"] == "wgs84" and set(side["columns"]) == set(header)
    assert all(side["columns"][c] for c in header)


def test_plain_pandas_reads_the_solution(navigated):
    out, d = navigated
    df = pd.read_csv(out)
    assert len(df) == d["epochs"] and df.columns[0] == "t"
    assert df["status"].isin(sorted(STATUSES)).all()
    mine = read_solution(out).to_pandas()
    assert list(mine.columns) == list(df.columns)
    for c in df.columns:
        if c == "status":
            assert (mine[c].astype(str).values == df[c].astype(str).values).all()
        else:
            assert np.allclose(mine[c].to_numpy(float), df[c].to_numpy(float), atol=1e-9), c
    assert mine.attrs["method"] == "ekf"


def test_old_files_with_comment_lines_still_read(navigated, tmp_path):
    out, _ = navigated
    old = tmp_path / "old.csv"
    old.write_text("# selfnav navigate --method ekf\n# datum wgs84\n" + out.read_text())
    a, b = read_solution(old), read_solution(out)
    assert np.array_equal(a.t, b.t) and set(a.columns) == set(b.columns)
    assert a.method == "file"


def test_other_datum_reads_back_as_wgs84(navigated, tmp_path):
    out, _ = navigated
    sol = read_solution(out)
    sk = tmp_path / "sk42.csv"
    sol.to_csv(sk, datum="sk42")
    raw = pd.read_csv(sk)
    assert abs(raw["lat_deg"][0] - sol.lat_deg[0]) * 111e3 > 5.0  # in SK-42: 9 m off
    back = read_solution(sk)
    assert np.abs(back.lat_deg - sol.lat_deg).max() * 111e3 < 1e-3    # read back to WGS-84


@pytest.mark.parametrize("cmd", ["navigate", "moving", "match"])
def test_out_folder_with_trailing_slash_is_refused(late, tmp_path, capsys, cmd, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = {"navigate": ["navigate", "--imu", late / "imu.csv", "--gnss", late / "gnss.csv"],
            "moving": ["moving", "--imu", late / "imu.csv", "--attitude", late / "truth.csv",
                       "--lat0-deg", "60", "--lon0-deg", "27"],
            "match": ["match", "--gnss", late / "gnss.csv", "--map",
                      next(late.glob("*.osm.pbf"))]}[cmd]
    code, o, err = run(args + ["--out", "newdir/"], capsys)
    assert code == 2 and o == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert "'newdir/' names a folder" in lines[0] and "newdir/solution.csv" in lines[0]
    assert not (tmp_path / "newdir").exists()          # no FILE named newdir, nothing at all


def test_folder_outputs_take_a_trailing_slash(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, o, err = run(["simulate", "static", "--out", "newdir/", "--duration", "20"], capsys)
    assert code == 0, err
    assert (tmp_path / "newdir").is_dir() and (tmp_path / "newdir" / "imu.csv").is_file()


def test_python_api_refuses_a_folder_name_too(navigated, tmp_path, monkeypatch):
    from selfnav.errors import OutputError

    monkeypatch.chdir(tmp_path)
    with pytest.raises(OutputError, match="names a folder"):
        read_solution(navigated[0]).to_csv("newdir/")
    assert not (tmp_path / "newdir").exists()


# ------------------------------------------------------------------ the coverage arithmetic
def test_coverage_of_a_span():
    t = np.linspace(37.2, 60.0, 229)
    c = coverage(t, 0.0, 60.0)
    assert c["coverage"] == pytest.approx(22.8 / 60.0, abs=1e-9)
    assert c["longest_gap_s"] == pytest.approx(37.2) and c["gaps"] == 0
    # a hole of 10 s inside, and a hole of the reference that does not count
    t2 = np.concatenate([np.linspace(0, 20, 101), np.linspace(30, 60, 151)])
    c2 = coverage(t2, 0.0, 60.0)
    assert c2["coverage"] == pytest.approx(50.0 / 60.0, abs=1e-9) and c2["gaps"] == 1
    c3 = coverage(t2, 0.0, 60.0, holes=[(20.0, 30.0)])
    assert c3["coverage"] == pytest.approx(1.0) and c3["span_s"] == pytest.approx(50.0)
    # irregular steps (0.05-0.2 s, as the navigator's rows) are not holes
    rng = np.random.default_rng(1)
    t4 = np.cumsum(rng.uniform(0.05, 0.2, 600))
    assert covered_intervals(t4) == [(t4[0], t4[-1])]
    assert span_text(37.2, 60.0, 0.0, 60.0, "IMU record") == \
        "from 37.2 s to 60.0 s of a 60.0 s IMU record"
