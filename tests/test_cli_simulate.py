"""`selfnav simulate` writes its files as one set: an interrupt leaves the old set or the new one
(issue 12); implausible scenarios are one line."""
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from support import run_cli as run

SRC = Path(__file__).resolve().parents[1] / "src"


def _set(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _seeds(folder):
    """The seed each file's '# simulated' line names."""
    out = set()
    for p in folder.glob("*.csv"):
        head = [ln for ln in p.read_text().splitlines()[:3] if "seed " in ln][0]
        out.add(head.split("seed ")[1].split(",")[0])
    return out


def test_interrupt_while_writing_leaves_the_old_set(tmp_path, capsys, monkeypatch):
    import selfnav.io.trajectory as traj

    out = tmp_path / "sim"
    code, _, err = run(["simulate", "car", "--out", out, "--seed", "1", "--duration", "60"],
                       capsys)
    assert code == 0, err
    old = _set(out)
    assert all(stat.S_IMODE((out / n).stat().st_mode) == 0o666 & ~_umask() for n in old)

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(traj, "write_truth", interrupted)   # imu.csv is already written then
    code, out_, err = run(["simulate", "car", "--out", out, "--seed", "2", "--duration", "60"],
                          capsys)
    assert code == 130 and err.strip() == "selfnav: interrupted"
    assert _set(out) == old and sorted(p.name for p in tmp_path.iterdir()) == ["sim"]


def test_ctrl_c_inside_a_c_extensions_import_is_an_interrupt(tmp_path, capsys, monkeypatch):
    """A Ctrl-C that lands while a C extension initialises (osmium, under CI load) comes back
    as 'ImportError: initialization failed': still one line and exit 130, nothing written."""
    import selfnav.io.trajectory as traj
    from selfnav.errors import interrupt_requested

    def import_interrupted(*a, **k):
        interrupt_requested.set()          # what the SIGINT handler does first
        raise ImportError("initialization failed")

    monkeypatch.setattr(traj, "write_truth", import_interrupted)
    out = tmp_path / "sim"
    code, _, err = run(["simulate", "car", "--out", out, "--seed", "2", "--duration", "60"],
                       capsys)
    assert code == 130 and err.strip() == "selfnav: interrupted"
    assert not out.exists()


def _umask():
    from selfnav.io.output import umask

    return umask()


def test_implausible_scenarios_are_one_line(tmp_path, capsys):
    for argv, needle in ((["car", "--dt", "5"], "cannot follow a moving car"),
                         (["car", "--dt", "-1"], "'--dt'"),
                         (["static", "--duration", "0.5"], "at least 100")):
        code, out, err = run(["simulate", *argv, "--out", tmp_path / "x"], capsys)
        assert code == 2 and out == "" and len(err.strip().splitlines()) == 1, err
        assert needle in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()
    toml = tmp_path / "s.toml"
    toml.write_text('[scenario]\nkind = "static"\nlat_deg = 95.0\n')
    code, out, err = run(["simulate", toml, "--out", tmp_path / "x"], capsys)
    assert code == 2 and "lat_deg = 95" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
@pytest.mark.long
def test_real_ctrl_c_old_set_or_new_set(tmp_path):
    """SIGINT to the process group at several moments of a run into an existing folder."""
    env = dict(os.environ, PYTHONPATH=str(SRC))
    out = tmp_path / "sim"
    cmd = [sys.executable, "-m", "selfnav", "simulate", "car", "--out", str(out),
           "--duration", "200"]
    subprocess.run(cmd + ["--seed", "1"], env=env, check=True, capture_output=True)
    t0 = time.perf_counter()
    subprocess.run(cmd + ["--seed", "2"], env=env, check=True, capture_output=True)
    full = time.perf_counter() - t0
    seen = set()
    for frac in (0.5, 0.75, 0.85, 0.95):
        p = subprocess.Popen(cmd + ["--seed", "3"], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, start_new_session=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        time.sleep(frac * full)
        os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=60)
        seeds = _seeds(out)
        assert len(seeds) == 1, seeds            # never a mix
        seen |= seeds
        if p.returncode == 130:
            assert err.decode().strip() == "selfnav: interrupted"
        else:
            # (once, under CI load, exit 1 at one of these moments: what it said, to find why)
            assert p.returncode == 0, (frac, p.returncode, err.decode()[-2000:])
        assert sorted(x.name for x in tmp_path.iterdir()) == ["sim"]
    assert seen <= {"2", "3"}
