"""`selfnav moving`: coordinates in range, deg/s gyros blamed on the IMU file (issue 12)."""
import numpy as np
import pytest

from support import run_cli as run
from selfnav.io.csvio import write_csv


def test_start_coordinates_out_of_range_are_one_line(tmp_path, capsys):
    for opt, val in (("--lon0-deg", "400"), ("--lat0-deg", "95")):
        args = {"--lat0-deg": "45", "--lon0-deg": "30", opt: val}
        code, out, err = run(["moving", "--imu", "i.csv", "--attitude", "a.csv", "--out",
                              tmp_path / "o.csv", *[x for kv in args.items() for x in kv]], capsys)
        assert code == 2 and len(err.strip().splitlines()) == 1 and opt in err


@pytest.fixture(scope="module")
def ship(tmp_path_factory):
    from selfnav import api
    from selfnav import attitude as att
    from selfnav.io.csvio import read_table
    from selfnav.io.trajectory import read_truth

    d = tmp_path_factory.mktemp("ship")
    api.simulate_files("ship", d, duration=120.0, seed=1)
    tr = read_truth(d / "truth.csv")
    r, p, h = att.euler_from_dcm_nb(tr.C_nb)
    write_csv(d / "att.csv", {"t": tr.t, "roll_deg": np.degrees(r), "pitch_deg": np.degrees(p),
                              "heading_deg": np.degrees(h)})
    tab = read_table(d / "imu.csv", ("t", "wx", "wy", "wz", "fx", "fy", "fz"))
    cols = {k: tab[k] * (np.degrees(1.0) if k[0] == "w" else 1.0)
            for k in ("t", "wx", "wy", "wz", "fx", "fy", "fz")}
    write_csv(d / "imu_degs.csv", cols, fmt="%.12g")
    return d


def test_deg_per_s_gyros_are_blamed_on_the_imu_file(ship, tmp_path, capsys):
    code, out, err = run(["moving", "--imu", ship / "imu_degs.csv", "--attitude",
                          ship / "att.csv", "--lat0-deg", "45", "--lon0-deg", "30", "--out",
                          tmp_path / "o.csv"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "imu_degs.csv, column 'wx'" in err and "deg/s" in err and "att.csv" not in err
