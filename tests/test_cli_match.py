"""`selfnav match` refuses σ ≤ 0 as `navigate` does (issue 12)."""
import pytest

from support import run_cli as run


@pytest.mark.parametrize("sigma", ["0", "-5"])
def test_sigma_in_the_file_must_be_positive(tmp_path, capsys, sigma):
    from selfnav.roads.graph import packaged_map

    g = tmp_path / "g.csv"
    g.write_text("t,lat_deg,lon_deg,h_m,sigma_m\n" + "".join(
        f"{k},60.4846,26.9480,20,{3 if k != 2 else sigma}\n" for k in range(5)))
    out = tmp_path / "m.csv"
    for cmd in (["match", "--gnss", g, "--map", packaged_map("kotka_karhula"), "--out", out],):
        code, o, err = run(cmd, capsys)
        assert code == 2 and o == "" and len(err.strip().splitlines()) == 1
        assert f"line 4, column 'sigma_m': sigma_m {sigma} must be positive" in err
        assert not out.exists()
    code, o, err = run(["match", "--gnss", g, "--map", packaged_map("kotka_karhula"), "--out", out,
                        "--sigma-m", sigma], capsys)
    assert code == 2 and "--sigma-m" in err
