"""One command-line style (issue 11 item 5): shared options with the library's choices, choices
listed in --help, one-line usage errors, positive flags, one-line warnings."""
import re
import warnings

import pytest

from support import run_cli as run
from selfnav.cli import main
from selfnav.cli import options as opt

COMMANDS = ("latitude", "moving", "navigate", "simulate", "evaluate", "match", "allan",
            "montecarlo", "demo", "spp", "attitude")


def test_choice_lists_equal_the_librarys():
    from selfnav import datum, sensors
    from selfnav.io import readers

    assert opt.IMU_FORMATS == readers.IMU_FORMATS
    assert opt.GNSS_FORMATS == readers.GNSS_FORMATS
    assert opt.DATUMS == datum.DATUMS
    assert opt.GRADES == sensors.GRADE_NAMES
    from selfnav.io import raw_readers

    assert opt.RAW_FORMATS == raw_readers.RAW_FORMATS
    from selfnav import axes
    assert opt.AXES_PRESETS == axes.preset_names()


def _help(capsys, cmd):
    capsys.readouterr()
    assert main([cmd, "--help"]) == 0
    return capsys.readouterr().out


def test_help_lists_choices_and_no_negative_negatives(capsys):
    for cmd in COMMANDS:
        text = _help(capsys, cmd)
        assert "--no-no-" not in text, cmd
        if cmd not in ("moving", "match"):    # their owners move them to cli.options next
            opts = [ln for ln in text.splitlines() if ln.strip().startswith("--")]
            assert not [ln for ln in opts if "<str>" in ln], cmd   # free text has a metavar
    nav = _help(capsys, "navigate")
    for needle in ("[ekf|seed]", "[auto|csv|psins|psins-csv|psins-mat|rtklibexplorer|kfgins|ulog]",
                   "[wgs84|pz90.11|pz90|sk42]", "[auto|navigation|tactical|industrial|consumer]",
                   "--nhc / --no-nhc", "--out-rate HZ", "A FILE"):
        assert needle in " ".join(nav.split()).replace("[ ", "["), needle
    assert "A FOLDER" in " ".join(_help(capsys, "simulate").split())
    assert "A FOLDER" in " ".join(_help(capsys, "demo").split())
    assert "--imu-format" in _help(capsys, "allan") and "--imu-format" in _help(capsys, "latitude")
    assert "--format" not in _help(capsys, "allan").replace("--imu-format", "")


def test_old_format_spelling_still_works_hidden(tmp_path, capsys):
    from selfnav.io.csvio import write_csv
    from selfnav.sim.static import static_imu
    import numpy as np

    imu = static_imu(np.radians(40.0), 30.0, 0.1, seed=1)
    p = tmp_path / "i.csv"
    write_csv(p, {"t": imu.t, **{k: imu.omega_ib_b[:, j] for j, k in enumerate(("wx", "wy", "wz"))},
                  **{k: imu.f_ib_b[:, j] for j, k in enumerate(("fx", "fy", "fz"))}})
    code, out, err = run(["latitude", p, "--format", "csv", "--json"], capsys)
    assert code == 0, err


@pytest.mark.parametrize("argv,needle", [
    (["navigate", "--imu", "a", "--gnss", "b", "--out", "c", "--gnss-datum", "mars"],
     "'--gnss-datum': 'mars' is not one of wgs84, pz90.11, pz90, sk42"),
    (["navigate", "--imu", "a", "--gnss", "b", "--out", "c", "--imu-format", "xls"],
     "'--imu-format'"),
    (["simulate", "car", "--out", "x", "--grade", "mems"], "'--grade'"),
    (["latitude", "--rest", "sleepy"], "'--rest'"),
    (["montecarlo", "static-latitude", "--runs", "0"], "at least 1"),
    (["simulate", "car", "--out", "x", "--duration", "0"], "must be positive")])
def test_bad_values_are_one_usage_line(argv, needle, capsys):
    code, out, err = run(argv, capsys)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("selfnav: error:") and needle in lines[0], err
    assert re.search(r"see 'selfnav \w+ --help'", lines[0])


def test_datum_aliases_are_accepted():
    assert opt.checked_choice(opt.DATUMS, opt.datum_key_lazy)("PZ-90.11") == "pz90.11"
    assert opt.checked_choice(opt.DATUMS, opt.datum_key_lazy)("SK-42") == "sk42"


def test_warnings_are_one_line_each_and_other_libraries_quiet(capsys, monkeypatch):
    """The mechanism: a SelfnavWarning is one `selfnav: warning:` line (once per text), a
    numpy RuntimeWarning nothing."""
    import numpy as np
    import typer

    from selfnav.cli import app
    from selfnav.errors import warn

    @app.command("zz-test-warnings", hidden=True)
    def _zz():
        warn("first\nsecond line folded")
        warn("first\nsecond line folded")
        np.mean(np.array([]))                      # RuntimeWarning: Mean of empty slice
        warnings.warn("a library's own", UserWarning)
        typer.echo("done")

    try:
        code, out, err = run(["zz-test-warnings"], capsys)
    finally:
        app.registered_commands[:] = [c for c in app.registered_commands
                                      if c.name != "zz-test-warnings"]
    assert code == 0 and out == "done\n"
    assert err == "selfnav: warning: first second line folded\n"
