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
