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
    assert d["method"] == "ekf" and d["fix_status"]["used"] > 50
    # the CSV starts with its header row; what produced it is in the JSON sidecar
    assert sol.read_text().startswith("t,lat_deg,lon_deg,h_m")
    side = json.loads((tmp_path / "sol.csv.json").read_text())
    assert side["notes"][0].startswith("selfnav navigate") and side["datum"] == "wgs84"
    assert side["stats"]["fix_status"] == d["fix_status"]
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


def test_navigate_vehicle_frame_options(sim, tmp_path, capsys):
    """--mount-states reports the IMU mounting (the simulated IMU is aligned with the car:
    near zero), --nhc-lever is parsed, --no-nhc runs without the constraint."""
    capsys.readouterr()
    base = ["navigate", "--imu", sim / "imu.csv", "--gnss", sim / "gnss.csv", "--grade",
            "industrial", "--json"]
    code, out, err = run(base + ["--out", tmp_path / "a.csv", "--mount-states", "--nhc-lever",
                                 "0,-1.2,-0.5"], capsys)
    assert code == 0, err
    d = json.loads(out)
    assert len(d["mounting_deg"]) == 2 and max(abs(x) for x in d["mounting_deg"]) < 1.0
    code, out, err = run(base + ["--out", tmp_path / "b.csv", "--no-nhc"], capsys)
    assert code == 0, err
    assert json.loads(out)["fix_status"]["used"] > 50
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
    lines = err.strip().splitlines()
    errors = [ln for ln in lines if ln.startswith("selfnav: error:")]
    assert code == 2 and len(errors) == 1
    # … and one warning says why: the positions look like radians
    assert [ln for ln in lines if ln not in errors] == [
        ln for ln in lines if ln.startswith("selfnav: warning:") and "look like radians" in ln]
    assert len(lines) == 2


# ---------------------------------------------------------------- issue 12: real-world files
def _cut_rows(src, dst, t0, t1):
    """Copy a CSV without its data rows whose first column lies in [t0, t1)."""
    out = []
    for ln in src.read_text().splitlines():
        if ln[:1].isdigit() or ln[:1] == "-":
            if t0 <= float(ln.split(",", 1)[0]) < t1:
                continue
        out.append(ln)
    dst.write_text("\n".join(out) + "\n")
    return dst


@pytest.mark.parametrize("length", [5.0, 60.0])
def test_imu_gap_is_named_in_one_line(sim, tmp_path, capsys, length):
    imu = _cut_rows(sim / "imu.csv", tmp_path / "imu_gap.csv", 70.0, 70.0 + length)
    code, out, err = run(["navigate", "--imu", imu, "--gnss", sim / "gnss.csv", "--out",
                          tmp_path / "sol.csv", "--json"], capsys)
    assert code == 0, err
    gap = [ln for ln in err.splitlines() if "gap" in ln]
    assert len(gap) == 1 and gap[0].startswith("selfnav: warning:"), err
    assert f"a {length:g} s IMU gap at t = 69.990 s" in gap[0]


def test_short_imu_gaps_are_bridged_silently(sim, tmp_path, capsys):
    imu = _cut_rows(sim / "imu.csv", tmp_path / "imu_drop.csv", 70.0, 70.03)   # 3 samples
    code, out, err = run(["navigate", "--imu", imu, "--gnss", sim / "gnss.csv", "--out",
                          tmp_path / "sol.csv", "--json"], capsys)
    assert code == 0 and "gap" not in err


def test_two_sample_imu_is_one_clean_line(sim, tmp_path, capsys):
    lines = (sim / "imu.csv").read_text().splitlines()
    head = [ln for ln in lines if not ln[:1].isdigit()]
    two = tmp_path / "two.csv"
    two.write_text("\n".join(head + [ln for ln in lines if ln[:1].isdigit()][:2]) + "\n")
    _err(capsys, ["navigate", "--imu", two, "--gnss", sim / "gnss.csv", "--out",
                  tmp_path / "o.csv"], "two.csv", "2 samples", "navigate needs at least")


def test_map_of_another_city_is_refused_like_match(sim, tmp_path, capsys):
    from selfnav.roads.graph import packaged_map

    _err(capsys, ["navigate", "--imu", sim / "imu.csv", "--gnss", sim / "gnss.csv", "--map",
                  packaged_map("helsinki_centre"), "--out", tmp_path / "o.csv"],
         "helsinki_centre", "none of the", "GNSS fixes")
    assert not (tmp_path / "o.csv").exists()


def test_output_places(sim, tmp_path, capsys):
    import os
    import stat

    base = ["navigate", "--imu", sim / "imu.csv", "--gnss", sim / "gnss.csv"]
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for out, needle in ((tmp_path / "adir", "is a folder"), (fifo, "special file"),
                        (tmp_path / "afile" / "x.csv", "is a file, not a folder"),
                        ("/dev/null", "special file"),
                        ("/proc/selfnav.csv", "cannot create a file")):
        _err(capsys, base + ["--out", out], needle)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and stat.S_ISCHR(os.stat("/dev/null").st_mode)
    real = tmp_path / "real.csv"
    link = tmp_path / "link.csv"
    link.symlink_to(real)
    code, _, err = run(base + ["--out", link, "--json"], capsys)
    assert code == 0, err
    assert link.is_symlink() and real.stat().st_size > 1000
    assert stat.S_IMODE(real.stat().st_mode) == 0o666 & ~_umask()


def _umask():
    from selfnav.io.output import umask

    return umask()


@pytest.mark.filterwarnings("ignore:.*lie outside the truth's time span:selfnav.errors.SelfnavWarning")  # expected here
@pytest.mark.filterwarnings("ignore:.*covers .* of the truth's time span:selfnav.errors.SelfnavWarning")  # expected here
@pytest.mark.slow
def test_real_drive_60s_imu_gap_reinitialises(tmp_path, capsys, shared_data):
    """Issue 12 acceptance: 60 s of IMU rows cut from the real drive (RTK as truth): error at
    most 5 m outside the gap and the 30 s after it, no solution row inside the gap, and one
    stderr line naming the gap."""
    import shutil

    import numpy as np

    from selfnav import api
    from selfnav.evaluation import evaluate
    from selfnav.types import Trajectory

    d = shared_data / "rtklibexplorer_drive_0708"
    rows = (d / "imu_1934.csv").read_text().splitlines()
    ticks = np.array([float(r.split(",")[6]) for r in rows])
    t_cut = ticks[1] + 200e3                       # 200 s into the drive (ms counter)
    keep = ~((ticks >= t_cut) & (ticks < t_cut + 60e3))
    imu = tmp_path / "imu_gap.csv"
    imu.write_text("\n".join(r for r, k in zip(rows, keep) if k) + "\n")
    shutil.copyfile(d / "imu_1934.csv.tag", tmp_path / "imu_gap.csv.tag")
    sol = tmp_path / "sol.csv"
    code, out, err = run(["navigate", "--imu", imu, "--gnss", d / "gnss_1934_sf.pos",
                          "--out", sol], capsys)
    assert code == 0, err
    assert len([ln for ln in err.splitlines() if "gap" in ln]) == 1, err
    data = api.read_imu(imu)
    g = api.read_gnss(d / "gnss_1934_sf.pos")
    gap = api.imu_gaps(data, 6)[0]
    s = api.read_solution(sol)
    inside = (s.t > gap.t_before) & (s.t < gap.t_after)
    assert not inside.any(), f"{inside.sum()} solution rows inside the gap"
    n = len(g.t)
    truth = Trajectory(g.t, g.lat, g.lon, g.h, np.full((n, 3), np.nan),
                       np.full((n, 3, 3), np.nan), "RTK")
    ev = evaluate(truth, s.trajectory)
    after = (ev.t > gap.t_before) & (ev.t < gap.t_after + 30.0)
    assert ev.horizontal[~after].max() <= 5.0


def _shift_after(src, dst, t0, dt):
    out = []
    for ln in src.read_text().splitlines():
        if ln[:1].isdigit():
            p = ln.split(",")
            if float(p[0]) >= t0:
                p[0] = f"{float(p[0]) + dt:.6f}"
            ln = ",".join(p)
        out.append(ln)
    dst.write_text("\n".join(out) + "\n")
    return dst


def test_three_hour_gap_is_never_a_traceback(sim, tmp_path, capsys):
    """IMU and GNSS both resume 3 h later (the issue's LinAlgError traceback): a result, or one
    error line naming the gap (until the navigator re-initialises after gaps)."""
    imu = _shift_after(sim / "imu.csv", tmp_path / "imu.csv", 60.0, 3 * 3600.0)
    gnss = _shift_after(sim / "gnss.csv", tmp_path / "gnss.csv", 60.0, 3 * 3600.0)
    out = tmp_path / "sol.csv"
    code, o, err = run(["navigate", "--imu", imu, "--gnss", gnss, "--out", out], capsys)
    assert "Traceback" not in err and code in (0, 2)
    lines = err.strip().splitlines()
    assert any("a 3 h IMU gap at t = 59.990 s" in ln for ln in lines)
    if code == 2:
        assert len([ln for ln in lines if ln.startswith("selfnav: error:")]) == 1
        assert not out.exists()
