"""CSV reading messages (issue 12): plain numbers in messages, gzip whatever the name."""
import gzip

import pytest

from selfnav.errors import InputError
from selfnav.io.csvio import check_positive, check_time, open_text, read_table
from selfnav.io.readers import read_imu


def test_time_in_messages_is_a_plain_number(tmp_path):
    """(GNSS files are ordered with a note since issue 14; IMU files must be in order.)"""
    from selfnav.io.readers import read_imu

    p = tmp_path / "imu.csv"
    p.write_text("t,wx,wy,wz,fx,fy,fz\n30.0,0,0,0,0,0,9.8\n30.01,0,0,0,0,0,9.8\n"
                 "30.005,0,0,0,0,0,9.8\n")
    with pytest.raises(InputError) as e:
        read_imu(p)
    msg = str(e.value)
    assert "np.float64" not in msg and "time 30.005 is going backwards" in msg
    assert "line 4" in msg


def test_gzip_named_csv_is_read(tmp_path):
    text = "t,wx,wy,wz,fx,fy,fz\n" + "".join(
        f"{0.01 * (k + 1):.2f},0,0,0,0,0,9.8\n" for k in range(200))
    plain = tmp_path / "plain.csv"
    plain.write_text(text)
    disguised = tmp_path / "imu.csv"
    disguised.write_bytes(gzip.compress(text.encode()))
    a, b = read_imu(plain), read_imu(disguised)
    assert len(a) == len(b) == 200 and (a.t == b.t).all()


def test_check_positive_names_the_row(tmp_path):
    p = tmp_path / "g.csv"
    p.write_text("t,sigma_m\n0,3\n1,0\n")
    tab = read_table(p, ("t",), optional=("sigma_m",))
    check_time(tab)
    with pytest.raises(InputError, match=r"line 3, column 'sigma_m': sigma_m 0 must be positive"):
        check_positive(tab, "sigma_m")


def test_truncated_gzip_is_one_line_not_an_interrupt(tmp_path):
    """Two bytes of gzip magic: gzip raises EOFError, which the command line would take for
    Ctrl-D ("interrupted", exit 130) — found by the CLI property test."""
    p = tmp_path / "sol.csv"
    p.write_bytes(b"\x1f\x8b")
    with pytest.raises(InputError, match="gzip"):
        open_text(p)


def test_partial_first_or_last_row_skipped_with_one_warning(tmp_path):
    """A logger cut off mid-line (issue 20 item 4): the partial row is skipped with one warning
    naming its line; a bad row elsewhere stays an error naming its line."""
    import warnings

    from selfnav.errors import InputError, SelfnavWarning
    from selfnav.io.imu import read_imu_csv

    rows = [f"{0.01 * k:.2f},0,0,0,0,0,9.8" for k in range(1, 8)]
    p = tmp_path / "imu.csv"
    p.write_text("t,wx,wy,wz,fx,fy,fz\n" + "\n".join(rows[:-1] + ["0.07,0,0,0"]))
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        imu = read_imu_csv(p)
    msgs = [str(x.message) for x in w if issubclass(x.category, SelfnavWarning)]
    assert len(imu) == 6 and len(msgs) == 1 and "line 8 is a partial row" in msgs[0]
    p.write_text("t,wx,wy,wz,fx,fy,fz\n" + "\n".join(["0,0,0,", *rows[1:-1], "0.07,0,0,0,0,0,9."
                                                     "8e"]))
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        imu = read_imu_csv(p)
    msgs = [str(x.message) for x in w if issubclass(x.category, SelfnavWarning)]
    assert len(imu) == 5 and len(msgs) == 1 and "lines 2 and 8 are partial rows" in msgs[0]
    p.write_text("t,wx,wy,wz,fx,fy,fz\n" + "\n".join(rows[:3] + ["0.04,0,0"] + rows[4:]))
    with pytest.raises(InputError, match="line 5: has 3 fields where the header has 7"):
        read_imu_csv(p)
