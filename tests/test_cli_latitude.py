"""`selfnav latitude` end to end, and one clear line for every kind of bad input."""
import json

import numpy as np
import pytest

from support import run_cli as run
from selfnav.io.csvio import write_csv
from selfnav.sim.static import static_imu

DEGH = np.pi / 180 / 3600


def _write_imu(path, imu, t=None, **override):
    cols = {"t": imu.t if t is None else t, "wx": imu.omega_ib_b[:, 0], "wy": imu.omega_ib_b[:, 1],
            "wz": imu.omega_ib_b[:, 2], "fx": imu.f_ib_b[:, 0], "fy": imu.f_ib_b[:, 1],
            "fz": imu.f_ib_b[:, 2]}
    cols.update(override)
    write_csv(path, cols, comments=["simulated static IMU"], fmt="%.12g")
    return path


@pytest.fixture
def imu():
    return static_imu(np.radians(48.0), 120, 0.1, roll=0.02, pitch=-0.03, heading=2.0,
                      arw=np.radians(0.01) / 60, vrw=1e-4, seed=7)


def test_latitude_json_contract(tmp_path, imu, capsys):
    p = _write_imu(tmp_path / "imu.csv", imu)
    code, out, err = run(["latitude", p, "--json"], capsys)
    assert code == 0, err
    d = json.loads(out)
    for k in ("latitude_deg", "sigma_deg", "heading_deg", "pitch_deg", "roll_deg", "samples",
              "duration_s"):
        assert k in d
    assert abs(d["latitude_deg"] - 48.0) < 4 * d["sigma_deg"]
    assert d["samples"] == 1200 and d["duration_s"] == pytest.approx(120.0)
    assert d["heading_deg"] == pytest.approx(np.degrees(2.0), abs=1.0)


def test_latitude_seed_method_and_requirements(tmp_path, imu, capsys):
    p = _write_imu(tmp_path / "imu.csv", imu)
    code, out, _ = run(["latitude", p, "--method", "seed", "--json"], capsys)
    assert code == 0 and json.loads(out)["method"] == "seed"
    code, out, _ = run(["latitude", "--requirements", "--seed-constants", "--json"], capsys)
    rows = json.loads(out)["rows"]
    assert rows[0]["gyro_drift_deg_per_h"] == pytest.approx(5.88577e-05, rel=2e-6)


def test_multiposition_from_several_files(tmp_path, capsys):
    paths = []
    for k, hdg in enumerate([0.0, 1.6, 3.1, 4.7]):
        im = static_imu(np.radians(55.0), 300, 0.1, heading=hdg, arw=np.radians(0.001) / 60,
                        vrw=1e-5, gyro_bias=(0, 0, 0.01 * DEGH), seed=k)
        paths.append(_write_imu(tmp_path / f"p{k}.csv", im))
    code, out, err = run(["latitude", *paths, "--json"], capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d["positions"] == 4 and d["method"] == "multiposition"
    assert abs(d["latitude_deg"] - 55.0) < 4 * d["sigma_deg"]


def _expect_error(capsys, argv, *needles):
    code, out, err = run(argv, capsys)
    assert code == 2
    assert out == ""
    lines = [ln for ln in err.strip().splitlines() if ln]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def test_bad_inputs(tmp_path, imu, capsys):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    _expect_error(capsys, ["latitude", empty], "empty.csv", "empty")

    hdr = tmp_path / "hdronly.csv"
    hdr.write_text("t,wx,wy,wz,fx,fy,fz\n")
    _expect_error(capsys, ["latitude", hdr], "no data rows")

    miss = _write_imu(tmp_path / "miss.csv", imu)
    txt = miss.read_text().replace("fz", "f_z")
    miss.write_text(txt)
    _expect_error(capsys, ["latitude", miss], "missing column 'fz'", "f_z")

    nan = _write_imu(tmp_path / "nan.csv", imu)
    lines = nan.read_text().splitlines()
    parts = lines[10].split(",")
    parts[3] = "nan"
    lines[10] = ",".join(parts)
    nan.write_text("\n".join(lines) + "\n")
    _expect_error(capsys, ["latitude", nan], "line 11", "column 'wz'", "NaN")

    txtval = _write_imu(tmp_path / "txt.csv", imu)
    lines = txtval.read_text().splitlines()
    parts = lines[20].split(",")
    parts[5] = "abc"
    lines[20] = ",".join(parts)
    txtval.write_text("\n".join(lines) + "\n")
    _expect_error(capsys, ["latitude", txtval], "line 21", "column 'fy'", "not a number")

    t = imu.t.copy()
    t[50] = t[49]
    _expect_error(capsys, ["latitude", _write_imu(tmp_path / "rep.csv", imu, t=t)], "repeated",
                  "column 't'")
    t = imu.t.copy()
    t[60], t[61] = t[61], t[60]
    _expect_error(capsys, ["latitude", _write_imu(tmp_path / "uns.csv", imu, t=t)], "unsorted")

    short = imu.select(slice(0, 50))
    _expect_error(capsys, ["latitude", _write_imu(tmp_path / "short.csv", short)], "50 samples",
                  "at least 100")

    w = imu.omega_ib_b * 180 / np.pi
    _expect_error(capsys, ["latitude", _write_imu(tmp_path / "degs.csv", imu, wx=w[:, 0],
                                                  wy=w[:, 1], wz=w[:, 2])], "deg/s")
    w = imu.omega_ib_b * 180 / np.pi * 3600
    _expect_error(capsys, ["latitude", _write_imu(tmp_path / "degh.csv", imu, wx=w[:, 0],
                                                  wy=w[:, 1], wz=w[:, 2])], "deg/h")
    f = imu.f_ib_b / 9.80665
    _expect_error(capsys, ["latitude", _write_imu(tmp_path / "g.csv", imu, fx=f[:, 0], fy=f[:, 1],
                                                  fz=f[:, 2])], "g units")
    f = imu.f_ib_b * 0.2
    _expect_error(capsys, ["latitude", _write_imu(tmp_path / "lowf.csv", imu, fx=f[:, 0],
                                                  fy=f[:, 1], fz=f[:, 2])], "far from gravity")
    # turning: a 1°/s yaw rate
    w = imu.omega_ib_b + np.array([0, 0, np.radians(1.0)])
    _expect_error(capsys, ["latitude", _write_imu(tmp_path / "turn.csv", imu, wz=w[:, 2])],
                  "not at rest")
    _expect_error(capsys, ["latitude", tmp_path / "nope.csv"], "nope.csv", "no such file")
    bad = tmp_path / "bad.imu"
    bad.write_text("% header\n1 2 3\n")
    _expect_error(capsys, ["latitude", bad], "PSINS")


def test_no_partial_output_on_error(tmp_path):
    from selfnav.io.csvio import write_csv as wc

    target = tmp_path / "out.csv"
    with pytest.raises(ValueError):
        wc(target, {"a": np.arange(3), "b": np.arange(4)})
    assert not target.exists() and list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------- issue 12: real-world files
def test_gap_uses_the_longest_stretch_and_says_so(tmp_path, imu, capsys):
    t = imu.t.copy()
    t[400:] += 3 * 3600.0           # 3 h without rows after 40 s
    p = _write_imu(tmp_path / "gap.csv", imu, t=t)
    code, out, err = run(["latitude", p, "--json"], capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d["samples"] == 800 and d["duration_s"] == pytest.approx(80.0)
    gap = [ln for ln in err.splitlines() if "IMU gap" in ln]
    assert len(gap) == 1 and gap[0].startswith("selfnav: warning:")
    assert "a 3 h IMU gap at t = 40.000 s" in gap[0] and "longest gap-free stretch" in gap[0]
    assert abs(d["latitude_deg"] - 48.0) < 4 * d["sigma_deg"]


def test_requirements_latitude_out_of_range_is_one_line(capsys):
    line = _expect_error(capsys, ["latitude", "--requirements", "--lat-deg", "95"], "--lat-deg")
    assert line.startswith("selfnav: error:") and "90" in line


def test_seed_formula_without_solution_is_one_line_not_90_degrees(tmp_path, capsys):
    from selfnav import api

    # a tactical record whose gyro bias pushes (ω·f)/(Ω g) past 1 (seed 7, found by search)
    api.simulate_files("static", tmp_path / "s", seed=7, grade="tactical", duration=120.0)
    p = tmp_path / "s" / "imu.csv"
    line = _expect_error(capsys, ["latitude", p, "--method", "seed"], "imu.csv",
                         "no solution", "--method optimal")
    assert "e+" not in line
    # the optimal method on the same record: an honest, capped σ and a warning
    code, out, err = run(["latitude", p, "--json"], capsys)
    assert code == 0
    d = json.loads(out)
    assert d["sigma_deg"] <= 90.0 and abs(d["latitude_deg"] - 50.45) < 2 * d["sigma_deg"]
    assert "Earth rate" in err and all(ln.startswith("selfnav: warning:")
                                       for ln in err.strip().splitlines())
