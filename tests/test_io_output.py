"""The one output helper (selfnav.io.output): through symlinks, never over special files, modes
from the umask, parent folders, one line for an impossible place, file sets replaced whole."""
import os
import stat
from pathlib import Path

import numpy as np
import pytest

from selfnav.errors import OutputError
from selfnav.io import output as O
from selfnav.io.csvio import write_csv


def _umask(m):
    old = os.umask(m)
    return old


def test_new_files_follow_the_umask(tmp_path):
    old = _umask(0o022)
    try:
        p = write_csv(tmp_path / "a.csv", {"t": np.arange(3.0)})
        assert stat.S_IMODE(p.stat().st_mode) == 0o644
        os.umask(0o027)
        q = O.atomic_write_bytes(tmp_path / "b.png", b"x")
        assert stat.S_IMODE(q.stat().st_mode) == 0o640
        # a replaced file keeps its mode
        os.chmod(p, 0o600)
        write_csv(p, {"t": np.arange(4.0)})
        assert stat.S_IMODE(p.stat().st_mode) == 0o600
    finally:
        os.umask(old)


def test_symlink_is_written_through_and_stays(tmp_path):
    real = tmp_path / "real.csv"
    real.write_text("old\n")
    link = tmp_path / "link.csv"
    link.symlink_to(real)
    write_csv(link, {"t": np.arange(2.0)})
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert real.read_text().startswith("t\n0")
    # a dangling link: the target is created, the link stays
    dang = tmp_path / "dangling.csv"
    dang.symlink_to(tmp_path / "sub" / "target.csv")
    write_csv(dang, {"t": np.arange(2.0)})
    assert dang.is_symlink() and (tmp_path / "sub" / "target.csv").is_file()


def test_special_files_are_refused_and_left_alone(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(OutputError, match="special file"):
        write_csv(fifo, {"t": np.arange(2.0)})
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    with pytest.raises(OutputError, match="special file"):
        O.check_output_file("/dev/null")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_impossible_places_are_one_line(tmp_path):
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    cases = [(tmp_path / "adir", "is a folder"),
             (tmp_path / "afile" / "x.csv", "is a file, not a folder"),
             (tmp_path / "afile" / "deeper" / "x.csv", "is a file, not a folder"),
             (Path("/proc/selfnav-test.csv"), "cannot create a file")]
    for path, msg in cases:
        with pytest.raises(OutputError, match=msg) as e:
            write_csv(path, {"t": np.arange(2.0)})
        assert "\n" not in str(e.value)
    with pytest.raises(OutputError, match="is a file, not a folder"):
        with O.atomic_folder(tmp_path / "afile"):
            pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir", "afile"]


def test_missing_parents_are_created(tmp_path):
    p = write_csv(tmp_path / "a" / "b" / "c.csv", {"t": np.arange(2.0)})
    assert p.is_file()


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_unwritable_folder_is_one_line(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(OutputError, match="permission denied"):
            write_csv(ro / "x.csv", {"t": np.arange(2.0)})
    finally:
        ro.chmod(0o700)


def test_failure_leaves_no_temporary_and_the_old_file(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text("old\n")
    with pytest.raises(KeyboardInterrupt):
        with O.atomic_path(p) as tmp:
            Path(tmp).write_text("half")
            raise KeyboardInterrupt
    assert p.read_text() == "old\n"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["a.csv"]


def test_folder_set_is_replaced_whole_or_not_at_all(tmp_path):
    out = tmp_path / "out"
    owned = ("a.csv", "b.csv", "c.csv")
    with O.atomic_folder(out, owned) as d:
        for n in ("a.csv", "b.csv", "c.csv"):
            O.atomic_write_text(d / n, "old")
    (out / "mine.txt").write_text("user file")
    assert stat.S_IMODE(out.stat().st_mode) == 0o777 & ~O.umask()
    # an interrupt half-way: the old set stays, nothing temporary is left
    with pytest.raises(KeyboardInterrupt):
        with O.atomic_folder(out, owned) as d:
            O.atomic_write_text(d / "a.csv", "new")
            raise KeyboardInterrupt
    assert {p.name: p.read_text() for p in out.iterdir()} == {
        "a.csv": "old", "b.csv": "old", "c.csv": "old", "mine.txt": "user file"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    # a complete new set without c.csv: the old c.csv goes, the user's file stays
    with O.atomic_folder(out, owned) as d:
        O.atomic_write_text(d / "a.csv", "new")
        O.atomic_write_text(d / "b.csv", "new")
    assert {p.name: p.read_text() for p in out.iterdir()} == {
        "a.csv": "new", "b.csv": "new", "mine.txt": "user file"}


def test_folder_through_a_symlink(tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real)
    with O.atomic_folder(link, ("x.txt",)) as d:
        O.atomic_write_text(d / "x.txt", "1")
    assert link.is_symlink() and (real / "x.txt").read_text() == "1"


def test_uninterrupted_delivers_ctrl_c_after_the_block():
    import signal

    done = []
    # Python's own handler in force (a test runner's worker may have another)
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            with O.uninterrupted():
                os.kill(os.getpid(), signal.SIGINT)
                done.append(1)          # the block is not cut short
    finally:
        signal.signal(signal.SIGINT, old)
    assert done == [1]


def test_plots_must_be_png(tmp_path):
    with pytest.raises(OutputError, match=r"\.png"):
        O.check_output_file(tmp_path / "x.csv", (".png",))
