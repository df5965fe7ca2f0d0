"""`selfnav match` does not take σ ≤ 0 silently (issue 12): a fleet file's bad value is one
warning line naming the line (the fix is used with its σ unknown, issue 14: the other rows and
tracks still come back); ``--sigma-m`` ≤ 0 is refused."""
import pytest

from support import run_cli as run


@pytest.mark.parametrize("sigma", ["0", "-5"])
def test_sigma_in_the_file_must_be_positive(tmp_path, capsys, sigma):
    from selfnav.roads.graph import packaged_map

    g = tmp_path / "g.csv"
    g.write_text("t,lat_deg,lon_deg,h_m,sigma_m\n" + "".join(
        f"{k},60.5306,26.9602,20,{3 if k != 2 else sigma}\n" for k in range(5)))
    out = tmp_path / "m.csv"
    code, o, err = run(["match", "--gnss", g, "--map", packaged_map("kotka_karhula"), "--out",
                        out, "--json"], capsys)
    assert code == 0, err
    warn = [ln for ln in err.splitlines() if "sigma_m" in ln]
    assert len(warn) == 1 and warn[0].startswith("selfnav: warning:")
    assert f"line 4, column 'sigma_m': sigma_m {sigma} must be positive" in warn[0]
    assert out.exists()
    code, o, err = run(["match", "--gnss", g, "--map", packaged_map("kotka_karhula"), "--out", out,
                        "--sigma-m", sigma], capsys)
    assert code == 2 and "--sigma-m" in err
