"""Fleet GNSS files (selfnav.io.fleet) and the tolerant native GNSS CSV reader: ISO-8601 times,
repeated stamps, unsorted rows, column spellings, bad rows per track, Parquet."""
import datetime as dt
import warnings

import numpy as np
import pytest

from selfnav.errors import InputError, SelfnavWarning
from selfnav.io.csvio import parse_times
from selfnav.io.fleet import read_fleet
from selfnav.io.gnss import read_gnss_csv


def _notes(fn):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        out = fn()
    return out, [str(x.message) for x in w if issubclass(x.category, SelfnavWarning)]


def test_iso_times_with_and_without_zone_are_the_same_instants():
    t, form, bad = parse_times(["2019-03-11T08:33:24+00:00", "2019-03-11T10:33:25+02:00",
                                "2019-03-11T08:33:26Z", "2019-03-11 08:33:27",
                                "2019-03-11T08:33:27.5+0000"])
    assert form == "iso" and len(bad) == 0
    t0 = dt.datetime(2019, 3, 11, 8, 33, 24, tzinfo=dt.timezone.utc).timestamp()
    np.testing.assert_allclose(t - t0, [0.0, 1.0, 2.0, 3.0, 3.5], atol=1e-6)
    t, form, bad = parse_times(["12.5", "13", "x", ""])
    assert form == "seconds" and bad.tolist() == [2, 3] and t[1] == 13.0
    t, form, _ = parse_times(["1552293204000", "1552293205500"])       # epoch milliseconds
    assert form == "milliseconds" and t[1] - t[0] == pytest.approx(1.5)


def _write(path, text):
    path.write_text(text)
    return path


def test_fleet_csv_merges_orders_groups_and_keeps_the_time_text(tmp_path):
    p = _write(tmp_path / "fleet.csv", "\n".join([
        "# logger export",
        "trip_id;timestamp;latitude;longitude;alt",
        "a;2019-03-11T08:33:24+00:00;60.2001;26.7999;10",
        "a;2019-03-11T08:33:24+00:00;60.1999;26.8001;20",   # same second, 16 m: merged (mean)
        "b;2019-03-11T08:33:20+00:00;60.17;24.94;1",
        "a;2019-03-11T08:33:20+00:00;60.00;27.00;5",      # out of order: ordered
        "b;2019-03-11T08:33:29+00:00;60.17;24.95;1",
    ]) + "\n")
    fleet, notes = _notes(lambda: read_fleet(p))
    assert [tr.track_id for tr in fleet.tracks] == ["a", "b"]    # order of first appearance
    assert fleet.time_form == "iso" and fleet.has_track_id and fleet.rows == 5
    a = fleet.tracks[0]
    assert a.t_text == ["2019-03-11T08:33:20+00:00", "2019-03-11T08:33:24+00:00",
                        "2019-03-11T08:33:24+00:00"]
    assert a.lines.tolist() == [6, 3, 4] and a.row_fix.tolist() == [0, 1, 1]
    np.testing.assert_allclose(np.degrees(a.gnss.lat), [60.0, 60.2], rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.degrees(a.gnss.lon), [27.0, 26.8], rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.diff(a.gnss.t), [4.0])
    assert any("'trip_id' as track_id" in n and "'latitude' as lat_deg" in n for n in notes)
    assert any("1 repeated time stamps merged" in n for n in notes)
    assert any("out of time order in 1 tracks" in n for n in notes)
    assert all("\n" not in n for n in notes)


def test_repeated_stamps_that_disagree_keep_the_fix_nearest_its_neighbours(tmp_path):
    """A good fix and a multipath one 120 m off in the same second: their mean would lie 60 m
    off both; the reader keeps the one on the line of the fixes around it (issue 21)."""
    rows = ["track_id,t,lat_deg,lon_deg,h_m"]
    for k in range(5):                                  # 10 m/s north
        rows.append(f"c,{k},{60.0 + k * 10 / 111_195:.8f},25.0,{k}")
    rows.insert(3, f"c,2,{60.0 + 20 / 111_195:.8f},{25.0 + 120 / 55_600:.8f},9")  # multipath
    rows.insert(3, f"c,2,{60.0 + 20 / 111_195:.8f},25.0,7")   # ... and a second good one
    p = _write(tmp_path / "f.csv", "\n".join(rows) + "\n")
    fleet, notes = _notes(lambda: read_fleet(p))
    c = fleet.tracks[0]
    assert len(c.gnss) == 5 and c.row_fix.tolist() == [0, 1, 2, 2, 2, 3, 4]
    # two of three agree: the median is theirs, the fix nearest the neighbours is kept
    assert np.degrees(c.gnss.lon[2]) == pytest.approx(25.0, abs=1e-9)
    assert c.gnss.h[2] in (2.0, 7.0)
    assert any("disagreed by more than 20 m" in n for n in notes)


def test_bad_rows_and_short_tracks_are_named_and_the_others_kept(tmp_path):
    p = _write(tmp_path / "f.csv", "track_id,t,lat_deg,lon_deg\n"
               "x,0,60.1,26.9\nx,5,abc,26.9\nx,10,60.1,26.91\n"
               "y,0,60.2,26.9\n"
               "z,0,60.3,26.9\nz,5,95.0,26.9\nz,7,60.3,26.95\nz,8,0,0\n")
    fleet, notes = _notes(lambda: read_fleet(p))
    by = {tr.track_id: tr for tr in fleet.tracks}
    assert len(by["x"].gnss) == 2 and by["x"].error is None
    assert by["y"].gnss is None and "line 5" in by["y"].error and "'y'" in by["y"].error
    assert len(by["z"].gnss) == 2
    bad = [n for n in notes if "skipped" in n]
    assert any("line 3" in n and "track 'x'" in n and "'abc' is not a number" in n for n in bad)
    assert any("line 7" in n and "track 'z'" in n and "latitude" in n and "2 rows skipped" in n
               for n in bad)


def test_missing_column_is_one_error_with_the_schema(tmp_path):
    p = _write(tmp_path / "f.csv", "t,lat_deg,lng_x\n0,60,26\n")
    with pytest.raises(InputError, match="missing column 'lon_deg'.*schema"):
        read_fleet(p)


def test_folder_of_files_is_a_fleet_named_by_file(tmp_path):
    for k in range(3):
        _write(tmp_path / f"veh{k}.csv", "t,lat_deg,lon_deg\n0,60.1,26.9\n5,60.1,26.91\n")
    fleet = read_fleet(tmp_path)
    assert [tr.track_id for tr in fleet.tracks] == ["veh0", "veh1", "veh2"]
    assert fleet.time_form == "seconds" and not fleet.has_track_id


@pytest.mark.filterwarnings("ignore:.*columns read as the schema's:selfnav.errors.SelfnavWarning")  # expected here
@pytest.mark.filterwarnings("ignore:.*rows out of time order:selfnav.errors.SelfnavWarning")  # expected here
def test_parquet_with_timestamp_column(tmp_path):
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    base = dt.datetime(2019, 3, 11, 8, 33, 24, tzinfo=dt.timezone.utc)
    tab = pa.table({"vehicle_id": ["v1", "v1", "v2", "v2", "v1"],
                    "time": [base + dt.timedelta(seconds=s) for s in (0, 10, 0, 3, 5)],
                    "lat": [60.1, 60.11, 60.2, 60.21, 60.105],
                    "lon": [26.9, 26.9, 26.8, 26.8, 26.9]})
    pq.write_table(tab, tmp_path / "f.parquet")
    fleet = read_fleet(tmp_path / "f.parquet")
    assert [tr.track_id for tr in fleet.tracks] == ["v1", "v2"] and fleet.time_form == "iso"
    v1 = fleet.tracks[0]
    np.testing.assert_allclose(v1.gnss.t - v1.gnss.t[0], [0.0, 5.0, 10.0])
    assert v1.lines.tolist() == [1, 5, 2]


def test_native_gnss_csv_takes_iso_times_repeats_and_unsorted_rows(tmp_path):
    p = _write(tmp_path / "g.csv", "t,lat_deg,lon_deg,h_m\n"
               "2019-03-11T08:00:02Z,60.0,26.0,10\n"
               "2019-03-11T08:00:00Z,60.1,26.1,10\n"
               "2019-03-11T08:00:01Z,60.05,26.05,10\n"
               "2019-03-11T08:00:01Z,60.05001,26.05,30\n")
    g, notes = _notes(lambda: read_gnss_csv(p))
    np.testing.assert_allclose(g.t - g.t[0], [0.0, 1.0, 2.0])
    np.testing.assert_allclose(np.degrees(g.lat), [60.1, 60.050005, 60.0])
    np.testing.assert_allclose(g.h, [10.0, 20.0, 10.0])
    assert len(notes) == 2 and any("1 repeated" in n for n in notes)
    bad = _write(tmp_path / "b.csv", "t,lat_deg,lon_deg,h_m\n0,60,26,1\n1,x,26,1\n")
    with pytest.raises(InputError, match=r"line 3, column 'lat_deg': 'x' is not a number"):
        read_gnss_csv(bad)
    two = _write(tmp_path / "two.csv", "track_id,t,lat_deg,lon_deg,h_m\na,0,60,26,1\n"
                 "a,1,60,26,1\nb,0,60,26,1\nb,1,60,26,1\n")
    with pytest.raises(InputError, match="2 tracks"):
        read_gnss_csv(two)


@pytest.mark.filterwarnings("ignore:.*columns read as the schema's:selfnav.errors.SelfnavWarning")  # expected here
def test_common_spellings_and_a_row_id_column(tmp_path):
    p = _write(tmp_path / "grab.csv", "id,trj_id,pingtimestamp,rawlat,rawlng\n"
               "1,7,1552293204,60.1,26.9\n2,7,1552293209,60.1,26.91\n"
               "3,8,1552293204,60.2,26.9\n4,8,1552293214,60.2,26.91\n")
    fleet, notes = _notes(lambda: read_fleet(p))
    assert [tr.track_id for tr in fleet.tracks] == ["7", "8"]
    assert any("'trj_id' as track_id" in n and "'rawlat' as lat_deg" in n for n in notes)
    rows = _write(tmp_path / "rows.csv", "ID,Time Stamp,Latitude,Longitude\n"
                  "1,0,60.1,26.9\n2,5,60.1,26.91\n3,9,60.1,26.92\n")
    fleet = read_fleet(rows)                    # unique ids number the rows: one track
    assert len(fleet.tracks) == 1 and len(fleet.tracks[0].gnss) == 3
    veh = _write(tmp_path / "veh.csv", "id,timestamp,lat,lon\n"
                 "a,0,60.1,26.9\na,5,60.1,26.91\nb,0,60.2,26.9\nb,5,60.2,26.91\n")
    assert [tr.track_id for tr in read_fleet(veh).tracks] == ["a", "b"]   # ids that repeat


def test_slash_dates_and_separate_date_and_time_columns(tmp_path):
    t, form, bad = parse_times(["2019/03/11 08:33:24", "2019/03/11 08:33:30"])
    assert form == "iso" and len(bad) == 0 and t[1] - t[0] == 6.0
    p = _write(tmp_path / "dt.csv", "vehicle,date,time,lat,lon\n"
               "v,2019-03-11,23:59:58,60.1,26.9\nv,2019-03-12,00:00:03,60.1,26.91\n")
    fleet, notes = _notes(lambda: read_fleet(p))
    tr = fleet.tracks[0]
    assert tr.t_text == ["2019-03-11 23:59:58", "2019-03-12 00:00:03"]
    assert np.diff(tr.gnss.t).tolist() == [5.0] and any("'date'" in n for n in notes)


def test_windows_and_old_mac_line_ends_and_a_stray_carriage_return(tmp_path):
    """CRLF and CR files read like LF ones; a lone ``\\r`` is a line end, not a crash (found
    by the CLI property test: ``csv.Error`` escaped as a traceback)."""
    rows = ["t,lat_deg,lon_deg,h_m", "0,60.48,26.95,20", "1,60.480001,26.95,20",
            "2,60.480002,26.95,20"]
    lf = tmp_path / "lf.csv"
    lf.write_bytes("\n".join(rows).encode())
    ref = read_gnss_csv(lf)
    for end in ("\r\n", "\r"):
        p = tmp_path / "other.csv"
        p.write_bytes(end.join(rows).encode())
        got = read_gnss_csv(p)
        np.testing.assert_array_equal(got.lat, ref.lat)
        np.testing.assert_array_equal(got.t, ref.t)
    p = tmp_path / "stray.csv"
    p.write_bytes(b"\nt,lat_deg,lon_deg,h_m\n\r0\n0,60.48,26.95,20\n1,60.480001,26.95,20\n"
                  b"2,60.480002,26.95,20\n")
    with pytest.raises(InputError, match="stray.csv"):
        read_gnss_csv(p)
