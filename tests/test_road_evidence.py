"""The map's word between two tracks (selfnav.roads.evidence, issue 19): a car's track lies on the
roads, the same track moved by an offset does not; two tracks that put the car in the same place
get no word; the word is bounded. On the packaged Kotka Karhula map, a simulated drive."""
import numpy as np
import pytest

from selfnav.earth import enu_offset
from selfnav.roads.aid import EkfRoadAid
from selfnav.roads.evidence import on_roads_llr, shifts, thin_track
from selfnav.sim.car import car_trajectory


@pytest.fixture(scope="module")
def drive(karhula):
    tr = car_trajectory(karhula, duration=40.0, dt=1.0, seed=4)
    x, y = karhula.to_local(tr.lat, tr.lon)
    return karhula, tr, np.column_stack([x, y])


def test_a_track_on_the_roads_is_preferred_to_it_moved(drive):
    g, _, xy = drive
    keep = thin_track(xy)
    assert 3 <= len(keep) <= 12
    gaps = np.hypot(*np.diff(xy[keep], axis=0).T)
    assert np.all(gaps >= 25.0 - 1e-9)
    on = on_roads_llr(g, xy[keep], 10.0)
    assert 3.0 < on <= np.log(1 + len(shifts())) + 1e-9       # at most ln(1 + copies)
    moved = [on_roads_llr(g, xy[keep] + d, 10.0) for d in ([150.0, -90.0], [130.0, 110.0])]
    assert max(moved) < -10.0
    # with white 10 m noise on the fixes the track is still on the roads
    rng = np.random.default_rng(1)
    assert on_roads_llr(g, xy[keep] + rng.normal(0, 10.0, (len(keep), 2)), 10.0) > 1.0


def test_shifts_cover_the_annulus_in_every_direction():
    s = shifts(24, 40.0, 300.0)
    r = np.hypot(*s.T)
    assert r.min() >= 40.0 and r.max() <= 300.0
    az = np.degrees(np.arctan2(s[:, 0], s[:, 1])) % 360
    assert np.all(np.histogram(az, bins=4, range=(0, 360))[0] >= 4)


def test_track_evidence_scores_each_track_on_the_roads(drive):
    g, tr, xy = drive
    aid = EkfRoadAid(g)
    lat0, lon0 = tr.lat[0], tr.lon[0]
    p = np.array([enu_offset(lat0, lon0, 0.0, la, lo, 0.0)[:2] for la, lo in zip(tr.lat, tr.lon)])
    off = np.array([130.0, 110.0])
    e_fix, e_ins = aid.track_evidence((lat0, lon0), p, p + off, 10.0, 5.0)
    assert 3.0 < e_fix <= np.log(1 + len(shifts())) + 1e-9 and e_ins < -10.0
    e_fix, e_ins = aid.track_evidence((lat0, lon0), p + off, p, 10.0, 5.0)
    assert e_fix < -10.0 and 3.0 < e_ins <= np.log(1 + len(shifts())) + 1e-9
    # within their σ of each other the two put the car in the same place: no word
    assert aid.track_evidence((lat0, lon0), p, p + [6.0, -4.0], 10.0, 5.0) is None
    # a dead reckoning as wide as its offset: the map cannot place it
    assert aid.track_evidence((lat0, lon0), p, p + off, 10.0, 300.0) is None
    # a σ wider than the street spacing: the track fits anywhere, no evidence either way
    assert abs(on_roads_llr(g, xy[thin_track(xy)] + off, 400.0)) < 0.5
