"""``selfnav spp`` from the command line: outputs, JSON, errors (one line, exit 2)."""
import json

import numpy as np
import pytest

from selfnav.io.csvio import read_table
from selfnav.solution import read_solution
from support import run_cli


@pytest.mark.slow
def test_spp_android_writes_solution_and_logs(shared_data, tmp_path, capsys):
    d = shared_data / "android_raw_static_mtv"
    out, sats, rec = tmp_path / "sol.csv", tmp_path / "sats.csv", tmp_path / "fix.csv"
    code, so, se = run_cli(["spp", "--gnss-raw", d / "pseudoranges_log_2016_06_30_21_26_07.txt",
                            "--nav", d / "hour1820.16n", "--out", out, "--sat-log", sats,
                            "--receiver-out", rec, "--json"], capsys)
    assert code == 0, se
    js = json.loads(so)
    assert js["epochs_out"] == 223 and js["ionosphere"] == "klobuchar-gps"
    sol = read_solution(out)
    assert len(sol) == 223
    tab = read_table(out, ("t", "lat_deg", "lon_deg", "h_m", "sigma_h_m", "sigma_m", "n_used",
                           "dof"))
    assert np.all(tab["n_used"] >= 4) and abs(np.median(tab["lat_deg"]) - 37.422578) < 1e-4
    st = read_table(sats, ("t", "residual_m", "elevation_deg"), numeric=False)
    assert len(st["t"]) == 1370
    assert len(read_solution(rec)) == 216
    code, so, se = run_cli(["evaluate", "--truth", rec, "--solution", out, "--json"], capsys)
    assert code == 0 and json.loads(so)["horizontal_rms_m"] < 8.0


def test_spp_bad_inputs_are_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.txt"
    bad.write_text("nothing here\n")
    code, so, se = run_cli(["spp", "--gnss-raw", bad, "--out", tmp_path / "o.csv"], capsys)
    assert code == 2 and se.count("\n") == 1 and "not a raw GNSS file" in se
    assert not (tmp_path / "o.csv").exists()
    code, _, se = run_cli(["spp", "--gnss-raw", tmp_path / "missing.obs", "--out",
                           tmp_path / "o.csv"], capsys)
    assert code == 2 and "not found" in se
    code, _, se = run_cli(["spp", "--gnss-raw", bad, "--out", tmp_path / "o.csv",
                           "--systems", "GX"], capsys)
    assert code == 2 and "system letter" in se


def test_spp_simulated_rinex_less_record_needs_nav(tmp_path, capsys):
    """An Android log without --nav: the error says to give a navigation file."""
    log = tmp_path / "gl.txt"
    log.write_text("# Raw,TimeNanos,FullBiasNanos,Svid,State,ReceivedSvTimeNanos,"
                   "ConstellationType,Cn0DbHz\n"
                   "Raw,1000000000,-1151285108458178048,5,15,422785326362991,1,40\n")
    code, _, se = run_cli(["spp", "--gnss-raw", log, "--out", tmp_path / "o.csv"], capsys)
    assert code == 2 and "--nav" in se
