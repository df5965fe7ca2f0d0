"""``selfnav demo`` on the data shipped inside the package."""
import json

import pytest

from support import run_cli as run


@pytest.mark.slow
def test_demo_runs_on_shipped_data(tmp_path, capsys):
    code, out, err = run(["demo", "--out", tmp_path / "demo", "--json"], capsys)
    assert code == 0, err
    d = json.loads(out)
    assert abs(d["error_deg"]) < 0.1
    assert (tmp_path / "demo" / "index.html").exists()
    assert (tmp_path / "demo" / "latitude_windows.png").stat().st_size > 10000
