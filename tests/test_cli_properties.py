"""Property-based tests (hypothesis): every reader and command fed random and mutated files
answers with a result or one line (exit 2), never a traceback, never a half-written output."""
import gzip
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from selfnav.cli import main
from selfnav.errors import SelfnavError

#: mutated files are meant to draw warnings; these tests check only that nothing crashes
pytestmark = pytest.mark.filterwarnings("ignore::selfnav.errors.SelfnavWarning")

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                      HealthCheck.too_slow])
VALUES = ["", "nan", "inf", "-inf", "abc", "1e400", "0x10", " ", "NaN", "--", "1,2", "٣", "1e-320",
          "-0", "+5", "9" * 40]


# ---------------------------------------------------------------- base files (small, valid)
def _csv(header, rows, comments=("simulated",)):
    return "".join(f"# {c}\n" for c in comments) + ",".join(header) + "\n" + "".join(
        ",".join(f"{v:.10g}" for v in r) + "\n" for r in rows)


def _imu_rows(n=150, dt=0.1, moving=False):
    t = dt * np.arange(1, n + 1)
    rng = np.random.default_rng(0)
    w = np.tile([0.0, 5.2e-5, 6.0e-5], (n, 1)) + rng.normal(0, 1e-6, (n, 3))
    f = np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0, 1e-3, (n, 3))
    if moving:
        f[:, 1] += 0.5 * np.sin(0.3 * t)
        w[:, 2] += 0.05 * np.sin(0.2 * t)
    return np.column_stack([t, w, f])


IMU = _csv(("t", "wx", "wy", "wz", "fx", "fy", "fz"), _imu_rows())
IMU_MOVING = _csv(("t", "wx", "wy", "wz", "fx", "fy", "fz"), _imu_rows(1000, 0.01, True))
GNSS = _csv(("t", "lat_deg", "lon_deg", "h_m", "sigma_m"),
            [(k, 60.48 + 1e-6 * k, 26.95, 20.0, 3.0) for k in range(11)])
TRUTH = _csv(("t", "lat_deg", "lon_deg", "h_m"),
             [(0.5 * k, 60.48 + 2e-6 * k, 26.95 + 1e-6 * k * k, 20.0) for k in range(40)])
ATT = _csv(("t", "roll_deg", "pitch_deg", "heading_deg"),
           [(0.1 * k, 0.5, -0.2, 30.0 + 0.01 * k) for k in range(1, 151)])
def _nmea_line(body):
    """``$body*hh`` with the sentence's checksum (XOR of the body's characters)."""
    x = 0
    for ch in body:
        x ^= ord(ch)
    return f"${body}*{x:02X}\n"


NMEA = "".join(_nmea_line(f"GPGGA,1200{k:02d}.00,6028.800,N,02657.000,E,1,08,0.9,20.0,M,17.0,M,,")
               for k in range(12))


def _pos_text(shared):
    p = shared / "rtklibexplorer_drive_0708" / "gnss_1934_sf.pos"
    return "\n".join(p.read_text().splitlines()[:60]) + "\n"


# ---------------------------------------------------------------- mutations
@st.composite
def mutated(draw, text):
    """``text`` with a few random edits, as bytes (sometimes gzipped, CRLF, BOM or binary)."""
    lines = text.splitlines()
    for _ in range(draw(st.integers(0, 4))):
        if not lines:
            break
        k = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["cell", "cell", "drop", "dup", "swap", "cut", "header",
                                   "scale", "garbage", "sep"]))
        parts = lines[k].split(",")
        if op == "cell":
            parts[draw(st.integers(0, len(parts) - 1))] = draw(st.sampled_from(VALUES))
            lines[k] = ",".join(parts)
        elif op == "drop":
            del lines[k]
        elif op == "dup":
            lines.insert(k, lines[k])
        elif op == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[k], lines[j] = lines[j], lines[k]
        elif op == "cut":
            lines[k] = lines[k][:draw(st.integers(0, max(len(lines[k]) - 1, 0)))]
        elif op == "header":
            lines[k] = draw(st.sampled_from(["t,wx,wy", "time,lat,lon", "T;LAT;LON", "a b c",
                                             "t,lat_deg,lon_deg,h_m,sigma_m,x"]))
        elif op == "scale":
            j = draw(st.integers(0, len(parts) - 1))
            f = draw(st.sampled_from([1e-3, 57.29577951308232, 1e3, -1.0, 0.0]))
            try:
                parts[j] = f"{float(parts[j]) * f:.10g}"
            except ValueError:
                pass
            lines[k] = ",".join(parts)
        elif op == "garbage":
            lines.insert(k, draw(st.text(max_size=30)))
        elif op == "sep":
            lines[k] = lines[k].replace(",", draw(st.sampled_from([";", "\t", " ", ",,"])))
    body = "\n".join(lines) + ("\n" if draw(st.booleans()) else "")
    form = draw(st.sampled_from(["plain"] * 6 + ["crlf", "bom", "gzip", "binary", "empty"]))
    if form == "crlf":
        return body.replace("\n", "\r\n").encode()
    if form == "bom":
        return ("\ufeff" + body).encode("utf-8")
    if form == "gzip":
        return gzip.compress(body.encode("utf-8", "surrogatepass"))
    if form == "binary":
        return draw(st.binary(min_size=0, max_size=200))
    if form == "empty":
        return b""
    return body.encode("utf-8", "surrogatepass")


def _one_line_or_result(call):
    """Run a reader: it returns, or raises a SelfnavError whose message is one line."""
    try:
        call()
    except SelfnavError as e:
        assert "\n" not in str(e) and str(e).strip()


def _check_cli(capsys, argv, out=None, folder=None):
    """Exit 0, or exit 2 with one error line (warnings aside); no traceback; nothing half
    written: on failure the output does not exist, and no temporary file is left."""
    capsys.readouterr()
    before = set(os.listdir(folder)) if folder else set()
    code = main([str(a) for a in argv])
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err
    lines = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert all(ln.startswith("selfnav: ") or not ln.startswith(" ") for ln in lines)
    if code != 0:
        assert code == 2, cap.err
        errors = [ln for ln in lines if ln.startswith("selfnav: error:")]
        others = [ln for ln in lines if not ln.startswith("selfnav: warning:")]
        assert len(errors) == 1 and others == errors, cap.err
        assert cap.out == ""
        if out is not None:
            assert not Path(out).exists()
    if folder:
        left = set(os.listdir(folder)) - before - ({Path(out).name} if out else set())
        assert not left, left                         # no temporary file left behind
    return code


# ---------------------------------------------------------------- readers
@settings(max_examples=60, **SETTINGS)
@given(data=st.data())
def test_readers_never_crash(data):
    from selfnav.io.attitude_file import read_attitude
    from selfnav.io.readers import read_gnss, read_imu
    from selfnav.io.trajectory import read_truth

    cases = [(IMU, ".csv", lambda p: read_imu(p, "csv")),
             (GNSS, ".csv", lambda p: read_gnss(p, "csv")),
             (TRUTH, ".csv", read_truth),
             (ATT, ".csv", read_attitude),
             (NMEA, ".nmea", lambda p: read_gnss(p, "nmea"))]
    text, ext, reader = data.draw(st.sampled_from(cases))
    raw = data.draw(mutated(text))
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / f"f{ext}"
        p.write_bytes(raw)
        _one_line_or_result(lambda: reader(p))


@pytest.mark.filterwarnings("ignore:loadtxt. input contained no data:UserWarning")
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # mutated rows
@settings(max_examples=25, **SETTINGS)
@given(data=st.data())
def test_pos_and_rtklibexplorer_readers_never_crash(data, shared_data):
    from selfnav.io.readers import read_gnss, read_imu

    d0 = shared_data / "rtklibexplorer_drive_0708"
    imu_text = "\n".join((d0 / "imu_1934.csv").read_text().splitlines()[:300]) + "\n"
    which = data.draw(st.sampled_from(["pos", "imu"]))
    raw = data.draw(mutated(_pos_text(shared_data) if which == "pos" else imu_text))
    with tempfile.TemporaryDirectory() as d:
        if which == "pos":
            p = Path(d) / "g.pos"
            p.write_bytes(raw)
            _one_line_or_result(lambda: read_gnss(p))
        else:
            p = Path(d) / "imu.csv"
            p.write_bytes(raw)
            (Path(d) / "imu.csv.tag").write_bytes((d0 / "imu_1934.csv.tag").read_bytes())
            _one_line_or_result(lambda: read_imu(p))


# ---------------------------------------------------------------- commands
@settings(max_examples=25, **SETTINGS)
@given(data=st.data())
def test_latitude_and_allan_commands(data, capsys):
    cmd = data.draw(st.sampled_from([["latitude"], ["latitude", "--method", "seed"], ["allan"],
                                     ["allan", "--json"]]))
    raw = data.draw(mutated(IMU))
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "imu.csv"
        p.write_bytes(raw)
        _check_cli(capsys, [*cmd, p], folder=d)


def _run_with_one_mutated(data, capsys, files: dict, argv, out: str):
    """Write the valid ``files`` ({name: text}) with one of them mutated, and run the command
    ``argv(folder)`` whose output is ``folder/out``."""
    which = data.draw(st.sampled_from(sorted(files)))
    raw = data.draw(mutated(files[which]))
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        for name, text in files.items():
            (d / name).write_text(text)
        (d / which).write_bytes(raw)
        _check_cli(capsys, argv(d), out=d / out, folder=d)


@settings(max_examples=20, **SETTINGS)
@given(data=st.data())
def test_evaluate_command(data, capsys):
    _run_with_one_mutated(data, capsys, {"truth.csv": TRUTH, "sol.csv": TRUTH}, lambda d: [
        "evaluate", "--truth", d / "truth.csv", "--solution", d / "sol.csv", "--report",
        d / "rep"], "rep")


@settings(max_examples=12, **SETTINGS)
@given(data=st.data())
def test_navigate_command(data, capsys):
    _run_with_one_mutated(data, capsys, {"imu.csv": IMU_MOVING, "gnss.csv": GNSS}, lambda d: [
        "navigate", "--imu", d / "imu.csv", "--gnss", d / "gnss.csv", "--out", d / "sol.csv"],
        "sol.csv")


@settings(max_examples=15, **SETTINGS)
@given(args=st.lists(st.sampled_from(
    ["--dt", "--duration", "--grade", "--seed", "0", "-1", "5", "0.001", "1e9", "nan", "x",
     "perfect", "consumer", "static", "car"]), max_size=4))
@example(args=["--seed", "-1"])           # was a numpy traceback
def test_simulate_arguments(args, capsys):
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "sim"
        argv = ["simulate", "static", "--out", out, "--duration", "2", *args]
        if any(a in ("1e9",) for a in args):
            return              # a real, long simulation: not a malformed input
        _check_cli(capsys, argv, out=out, folder=d)


@pytest.mark.parametrize("argv", [
    ["latitude", "--imu-format", "zz", "x.csv"], ["navigate", "--grade", "superb"],
    ["simulate", "car", "--out", "x", "--dt", "abc"], ["evaluate", "--truth"],
    ["allan"], ["montecarlo", "nope", "--workers", "-1"], ["latitude", "--method", "exact"],
    ["navigate", "--imu", "a", "--gnss", "b", "--out", "c", "--gnss-datum", "mars"]])
def test_bad_arguments_are_one_usage_line(argv, capsys):
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("selfnav: error:") and "\n" not in err and "Traceback" not in err
