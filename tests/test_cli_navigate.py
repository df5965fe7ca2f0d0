"""`selfnav simulate car` → `selfnav navigate` → `selfnav evaluate`, end to end (simulated data),
and one clear line for bad navigate input."""
import json

import pytest

from selfnav.cli import main
from support import run_cli as run


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    code = main(["simulate", "car", "--out", str(d), "--seed", "4", "--duration", "150",
                 "--grade", "industrial", "--json"])
    assert code == 0
    return d


def test_simulate_navigate_evaluate(sim, tmp_path, capsys):
    capsys.readouterr()
    sol = tmp_path / "sol.csv"
    code, out, err = run(["navigate", "--imu", sim / "imu.csv", "--gnss", sim / "gnss.csv",
                          "--out", sol, "--grade", "industrial", "--json"], capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d["method"] == "ekf" and d["accepted"] > 50 and d["real_time_factor"] > 100
    assert sol.read_text().startswith("# selfnav navigate")
    code, out, err = run(["evaluate", "--truth", sim / "truth.csv", "--solution", sol, "--json"],
                         capsys)
    assert code == 0, err
    m = json.loads(out)
    assert m["horizontal_rms_m"] < 15.0  # 10 m σ GNSS, industrial IMU, outlier windows possible
    # with the map (the simulator writes the map it drove on)
    pbf = next(sim.glob("*.osm.pbf"))
    code, out, err = run(["navigate", "--imu", sim / "imu.csv", "--gnss", sim / "gnss.csv",
                          "--out", tmp_path / "solmap.csv", "--grade", "industrial", "--map", pbf,
                          "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["map"] is not None


def test_navigate_vehicle_frame_and_shadow_options(sim, tmp_path, capsys):
    """--mount-states reports the IMU mounting (the simulated IMU is aligned with the car:
    near zero), --nhc-lever is parsed, --no-shadows runs the window test alone."""
    capsys.readouterr()
    base = ["navigate", "--imu", sim / "imu.csv", "--gnss", sim / "gnss.csv", "--grade",
            "industrial", "--json"]
    code, out, err = run(base + ["--out", tmp_path / "a.csv", "--mount-states", "--nhc-lever",
                                 "0,-1.2,-0.5"], capsys)
    assert code == 0, err
    d = json.loads(out)
    assert len(d["mounting_deg"]) == 2 and max(abs(x) for x in d["mounting_deg"]) < 1.0
    code, out, err = run(base + ["--out", tmp_path / "b.csv", "--no-shadows"], capsys)
    assert code == 0, err
    assert json.loads(out)["shadow_resets"] == 0
    _err(capsys, base + ["--out", tmp_path / "c.csv", "--nhc-lever", "1,2"], "--nhc-lever")


def _err(capsys, argv, *needles):
    code, out, err = run(argv, capsys)
    assert code == 2 and out == ""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in lines[0], (n, lines[0])


def test_navigate_bad_input(sim, tmp_path, capsys):
    capsys.readouterr()
    imu, gnss, out = sim / "imu.csv", sim / "gnss.csv", tmp_path / "x.csv"
    _err(capsys, ["navigate", "--imu", tmp_path / "none.csv", "--gnss", gnss, "--out", out],
         "none.csv", "no such file")
    _err(capsys, ["navigate", "--imu", imu, "--gnss", gnss, "--out", out, "--method", "kalman"],
         "'--method'", "kalman", "ekf, seed")
    _err(capsys, ["navigate", "--imu", imu, "--gnss", gnss, "--out", out, "--lever-arm", "1,2"],
         "--lever-arm")
    _err(capsys, ["navigate", "--imu", imu, "--gnss", gnss, "--out", out, "--grade", "superb"],
         "'--grade'", "superb", "consumer")
    # GNSS on another time base (seconds of week vs seconds of day)
    lines = gnss.read_text().splitlines()
    shifted = tmp_path / "shifted.csv"
    body = []
    for ln in lines:
        if ln.startswith("#") or ln.startswith("t,"):
            body.append(ln)
        else:
            p = ln.split(",")
            p[0] = f"{float(p[0]) + 243000.0:.3f}"
            body.append(",".join(p))
    shifted.write_text("\n".join(body) + "\n")
    _err(capsys, ["navigate", "--imu", imu, "--gnss", shifted, "--out", out], "do not overlap")
    assert not out.exists()
    # GNSS latitude in radians
    rad = tmp_path / "rad.csv"
    rad.write_text("t,lat_deg,lon_deg,h_m\n0,1.05,0.47,10\n1,1.05,0.47,10\n")
    code, _, err = run(["navigate", "--imu", imu, "--gnss", rad, "--out", out], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
