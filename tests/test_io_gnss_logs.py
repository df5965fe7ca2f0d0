"""GNSS logs as they come from the field (issue 20, part 4): an RTKLIB ``.pos`` copied while it
was being written, NMEA with corrupted bytes, a logger's time stamps and a sentence cut short.
A cut last row is skipped with one warning; corruption inside a file is refused or skipped by
its checksum, never read as a wrong position."""
import warnings

import numpy as np
import pytest

from selfnav.errors import InputError, SelfnavWarning
from selfnav.io.gnss import read_nmea, read_rtklib_pos


def _nmea(body):
    x = 0
    for ch in body:
        x ^= ord(ch)
    return f"${body}*{x:02X}"


GGA = [_nmea(f"GPGGA,1200{k:02d}.00,6028.{800 + k:03d},N,02657.000,E,1,08,0.9,20.0,M,17.0,M,,")
       for k in range(10)]


def _read(reader, path):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        g = reader(path)
    return g, [str(x.message) for x in w if issubclass(x.category, SelfnavWarning)]


def test_a_pos_file_cut_mid_row_loses_that_row_only(shared_data, tmp_path):
    text = (shared_data / "rtklibexplorer_drive_0708" / "gnss_1934_sf.pos").read_text()
    lines = text.splitlines()
    whole = tmp_path / "whole.pos"
    whole.write_text("\n".join(lines[:400]) + "\n")
    ref, warned = _read(read_rtklib_pos, whole)
    assert warned == []
    for cut_at in (30, 60, 120):                     # characters kept of row 401
        cut = tmp_path / f"cut{cut_at}.pos"
        cut.write_text("\n".join(lines[:400]) + "\n" + lines[400][:cut_at])
        g, warned = _read(read_rtklib_pos, cut)
        assert len(warned) == 1 and "line 401 is a partial row" in warned[0]
        assert len(g.t) == len(ref.t)
        np.testing.assert_array_equal(g.lat, ref.lat)
        np.testing.assert_array_equal(g.t, ref.t)


def test_a_pos_row_broken_inside_the_file_is_an_error_naming_its_line(shared_data, tmp_path):
    pos = shared_data / "rtklibexplorer_drive_0708" / "gnss_1934_sf.pos"
    lines = pos.read_text().splitlines()
    p = tmp_path / "bad.pos"
    p.write_text("\n".join(lines[:200] + [lines[200][:40]] + lines[201:400]) + "\n")
    with pytest.raises(InputError, match="line 201"):
        read_rtklib_pos(p)


def test_nmea_sentences_with_a_wrong_checksum_are_skipped_not_read(tmp_path):
    bad = GGA[4].replace("6028.804", "6028.894")     # one corrupted byte: 90 m north
    p = tmp_path / "log.nmea"
    p.write_text("\n".join(GGA[:4] + [bad] + GGA[5:]) + "\n")
    g, warned = _read(read_nmea, p)
    assert len(g.t) == 9 and 12 * 3600 + 4.0 not in g.t
    assert len(warned) == 1 and "1 GGA sentence with a wrong checksum" in warned[0]
    assert "line 5" in warned[0]
    lat_min = np.degrees(g.lat) * 60 - 60 * 60       # minutes past 60°
    assert np.all(np.abs(lat_min - 28.8) < 0.011)


def test_nmea_with_logger_time_stamps_and_a_last_sentence_cut_short(tmp_path):
    stamped = [f"2026-12-06T07:{k:02d}:00Z {s}" for k, s in enumerate(GGA)]
    p = tmp_path / "log.nmea"
    p.write_text("\n".join(stamped) + "\n" + GGA[0][:30])
    g, warned = _read(read_nmea, p)
    assert len(g.t) == 10
    assert len(warned) == 1 and "line 11 is a partial GGA sentence" in warned[0]


def test_nmea_whose_every_sentence_fails_its_checksum_is_refused_saying_so(tmp_path):
    p = tmp_path / "log.nmea"
    p.write_text("\n".join(s[:-2] + "00" for s in GGA) + "\n")
    with pytest.raises(InputError, match="wrong checksum"):
        read_nmea(p)


def test_positions_in_radians_are_named_so(tmp_path):
    """A native GNSS CSV whose lat_deg/lon_deg hold radians reads as a 30 m track off West
    Africa: one warning says what they look like (the navigator's "never started" alone did
    not); degrees read without it."""
    from selfnav.io.gnss import read_gnss_csv

    t = np.arange(20.0)
    lat, lon = np.radians(60.52 + 1e-4 * t), np.radians(26.94 + 1e-4 * t)
    for values, expect in (((lat, lon), 1), ((np.degrees(lat), np.degrees(lon)), 0)):
        p = tmp_path / f"g{expect}.csv"
        p.write_text("t,lat_deg,lon_deg,h_m\n" + "".join(
            f"{a},{b:.9f},{c:.9f},20\n" for a, b, c in zip(t, *values)))
        _, warned = _read(read_gnss_csv, p)
        hits = [w for w in warned if "look like radians" in w]
        assert len(hits) == expect, warned
