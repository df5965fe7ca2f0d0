"""`selfnav allan` through the command line: no stray plot, one line for a bad plot name, gaps
and deg/s data said in one warning each (issue 12)."""
import json
import stat

import numpy as np

from support import run_cli as run
from selfnav.io.csvio import write_csv
from selfnav.sim.static import static_imu


def _write(path, imu, t=None, scale_w=1.0):
    t = imu.t if t is None else t
    cols = {"t": t, **{k: imu.omega_ib_b[:, j] * scale_w for j, k in enumerate(("wx", "wy", "wz"))},
            **{k: imu.f_ib_b[:, j] for j, k in enumerate(("fx", "fy", "fz"))}}
    write_csv(path, cols, comments=["simulated static IMU"], fmt="%.12g")
    return path


def _imu(seed=3):
    return static_imu(np.radians(50.0), 200.0, 0.01, arw=np.radians(0.15) / 60, vrw=5e-4,
                      gyro_bias=(1e-4, -2e-4, 5e-5), seed=seed)


def test_no_png_in_the_working_folder_unless_asked(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    p = _write(tmp_path / "rest.csv", _imu())
    code, out, err = run(["allan", p, "--json"], capsys)
    assert code == 0, err
    assert list(tmp_path.glob("*.png")) == [] and "plot" not in json.loads(out)
    code, out, err = run(["allan", p], capsys)
    assert code == 0 and list(tmp_path.glob("*.png")) == []
    code, out, err = run(["allan", p, "--plot", tmp_path / "plots" / "a.png"], capsys)
    assert code == 0
    png = tmp_path / "plots" / "a.png"
    assert png.stat().st_size > 10000 and stat.S_IMODE(png.stat().st_mode) == 0o666 & ~_umask()


def _umask():
    from selfnav.io.output import umask

    return umask()


def test_plot_with_another_extension_is_one_line(tmp_path, capsys):
    p = _write(tmp_path / "rest.csv", _imu())
    code, out, err = run(["allan", p, "--plot", tmp_path / "x.csv"], capsys)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "x.csv" in err and ".png" in err and "Traceback" not in err
    assert not (tmp_path / "x.csv").exists()


def test_deg_per_s_data_is_warned(tmp_path, capsys):
    p = _write(tmp_path / "degs.csv", _imu(), scale_w=np.degrees(1.0))
    code, out, err = run(["allan", p, "--json"], capsys)
    assert code == 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("selfnav: warning:") and "deg/s" in lines[0]


def test_gap_uses_the_longest_stretch_and_says_so(tmp_path, capsys):
    imu = _imu()
    t = imu.t.copy()
    t[15000:] += 3 * 3600.0          # a 3 h gap after 150 s
    p = _write(tmp_path / "gap.csv", imu, t=t)
    code, out, err = run(["allan", p, "--json"], capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d["samples"] == 15000 and d["t_end_s"] < 151.0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "IMU gap" in lines[0] and "longest gap-free stretch" in lines[0]
    assert "a 3 h IMU gap at t = 150.000 s" in lines[0]


def test_moving_record_is_not_taken_for_deg_per_s(shared_data, capsys):
    """The real car drive is not at rest: one warning saying so, not a false units warning."""
    imu = shared_data / "rtklibexplorer_drive_0708" / "imu_1934.csv"
    code, out, err = run(["allan", imu, "--json"], capsys)
    assert code == 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "not at rest" in lines[0] and "deg/s" not in lines[0]
