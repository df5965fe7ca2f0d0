"""`selfnav montecarlo` and Ctrl-C: one line, exit 130, the Dask workers shut down quietly."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from support import run_cli as run
from selfnav import montecarlo as mc

SRC = Path(__file__).resolve().parents[1] / "src"


def _interrupting(seed, params):
    raise KeyboardInterrupt


def test_interrupt_in_process_is_one_line(tmp_path, capsys):
    mc.register_pair("test-interrupt", _interrupting, unit="1")
    out = tmp_path / "r.csv"
    code, o, err = run(["montecarlo", "test-interrupt", "--runs", "5", "--workers", "0",
                        "--out", out, "--json"], capsys)
    assert code == 130 and err.strip() == "selfnav: interrupted" and o == ""
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
@pytest.mark.parametrize("delay", [1.5, 8.0])
def test_ctrl_c_with_dask_workers_is_one_line(delay):
    """SIGINT to the whole process group (as a terminal sends it), during the cluster start-up
    and while the workers compute."""
    env = dict(os.environ, PYTHONPATH=str(SRC))
    p = subprocess.Popen([sys.executable, "-m", "selfnav", "montecarlo", "static-latitude",
                          "--runs", "20000", "--workers", "2", "--json"], env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(delay)
    os.killpg(p.pid, signal.SIGINT)
    try:
        out, err = p.communicate(timeout=90)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err.decode()[-2000:]
    assert err.decode().strip() == "selfnav: interrupted" and out == b""


def test_a_ctrl_c_while_the_fork_server_starts_is_not_lost():
    """The Dask workers' fork server is started with SIGINT blocked, not ignored: a Ctrl-C in
    that moment is delivered afterwards (ignored, it was discarded and the command went on
    computing: a CI hang), and the server and the workers it forks keep SIGINT blocked."""
    code = """if True:
        import os, signal
        signal.signal(signal.SIGINT, signal.default_int_handler)  # pytest-xdist ignores it
        import multiprocessing.forkserver as fs
        from selfnav import cluster
        start = fs.ensure_running
        def ensure_running():
            os.kill(os.getpid(), signal.SIGINT)  # the user's Ctrl-C, as the server starts
            start()
        fs.ensure_running = ensure_running
        try:
            cluster._start_forkserver_blocking_sigint()
            print("lost")
        except KeyboardInterrupt:
            status = open(f"/proc/{fs._forkserver._forkserver_pid}/status").read()
            mask = int(status.split("SigBlk:")[1].split()[0], 16)
            print("interrupted", bool(mask & (1 << (signal.SIGINT - 1))))
    """
    r = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=str(SRC)),
                       capture_output=True, text=True, timeout=60)
    assert r.stdout.split() == ["interrupted", "True"], r.stderr[-2000:]
