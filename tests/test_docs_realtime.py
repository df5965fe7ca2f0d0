"""docs/realtime.md: the loop on the page runs as written (simulated drive), its fixes handed
over as a receiver delivers them; the rows stay within their σ of the batch run's (which hands
the fixes over up to 1 s early) and of the truth."""
import re
from pathlib import Path

import numpy as np

import selfnav
from selfnav.earth import radii

PAGE = Path(__file__).resolve().parents[1] / "docs" / "realtime.md"


def _horizontal(a, lat, lon):
    rm, rn = radii(lat)
    return np.hypot((a.lat - lat) * rm, (a.lon - lon) * rn * np.cos(lat))


def test_the_realtime_loop_runs_as_written(capsys):
    code = re.findall(r"```python\n(.*?)```", PAGE.read_text(), re.S)[0]
    ns = {}
    exec(compile(code, str(PAGE), "exec"), ns)
    rows, sim = ns["rows"], ns["sim"]
    out = capsys.readouterr().out
    assert "gnss" in out and "rows," in out
    st = rows.stats["fix_status"]
    assert st["used"] >= 0.9 * (rows.stats["fixes"] - st["aligning"] - st["pending"])
    batch = selfnav.navigate(sim.imu, sim.gnss.as_gnss())
    a, b = rows.trajectory, batch.trajectory
    assert len(a.t) == len(b.t) and np.allclose(a.t, b.t)
    sig = rows.sigma_h
    assert np.all(_horizontal(a, b.lat, b.lon) <= 0.5 * sig)
    tr = sim.truth
    e = _horizontal(a, np.interp(a.t, tr.t, tr.lat), np.interp(a.t, tr.t, tr.lon))
    assert np.percentile(e / sig, 95) < 3.0
