"""A simulated car driving a route on a real OpenStreetMap road graph (issue 3, DESIGN §7).

The path is the road centre line (nearly collinear OSM vertices within ``simplify_tol`` dropped,
junctions kept) with each corner replaced by a circular arc tangent to both legs (line-arc-line,
curvature piecewise constant, heading continuous), so that position, heading and yaw rate are
exact analytic functions of the arc length ``s``. The arc radius is the nominal
``corner_radius`` unless a leg is too short, in which case it shrinks so that the arc uses at
most half of each adjacent leg; the car therefore follows the OSM centre line on the straight
parts (to ``simplify_tol``) and cuts a corner of turn angle θ by at most ``R (1/cos(θ/2) - 1)``.

The speed profile along ``s`` respects, at every point:

* the road's speed (``maxspeed`` or the class default of :mod:`selfnav.roads.graph`) and ``max_speed``;
* the lateral acceleration limit ``v² |κ| <= lat_acc_max`` (slowing for corners);
* ``|dv/dt| <= a_max`` (accelerating and braking), by a forward and a backward pass;
* stops (``v = 0``, dwell 1–8 s) at randomly chosen junctions, at the start and at the end.

Between grid points the acceleration is constant, so ``s(t)`` is piecewise quadratic and is
sampled exactly at the IMU rate. Pitch is 0 (OpenStreetMap carries no elevation); roll follows
the lateral acceleration through a first-order lag (body roll, optional).

This is simulated data: the returned trajectory's ``source`` says so.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from selfnav import attitude as att
from selfnav.errors import InputError
from selfnav.types import Trajectory


@dataclass
class CarPath:
    """Line-arc-line path: element ``i`` starts at arc length ``s0[i]`` at point ``p0[i]`` with
    heading ``psi0[i]`` (clockwise from grid North) and has constant curvature ``kappa[i]``
    (1/m, positive turning right/clockwise), length ``length[i]``; ``speed[i]`` its road speed."""

    s0: np.ndarray
    p0: np.ndarray
    psi0: np.ndarray
    kappa: np.ndarray
    length: np.ndarray
    speed: np.ndarray
    vertex_s: np.ndarray | None = None   # arc length where each polyline vertex's corner starts

    @property
    def total_length(self) -> float:
        return float(self.s0[-1] + self.length[-1])

    def element(self, s):
        return np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, len(self.s0) - 1)

    def evaluate(self, s):
        """Position ``(N, 2)``, heading ``(N,)`` and curvature ``(N,)`` at arc lengths ``s``."""
        s = np.asarray(s, float)
        e = self.element(s)
        u = s - self.s0[e]
        k = self.kappa[e]
        psi0 = self.psi0[e]
        half = 0.5 * k * u
        chord = u * np.sinc(half / np.pi)   # 2 sin(κu/2)/κ, exact also for κ = 0
        ang = psi0 + half
        p = self.p0[e] + np.stack([chord * np.sin(ang), chord * np.cos(ang)], axis=-1)
        return p, psi0 + k * u, k

    def sample(self, max_step=0.5, max_angle=0.02):
        """Dense vertices of the path (lines by their ends, arcs every ``max_step`` m or
        ``max_angle`` rad): ``(s, xy)``."""
        ss = []
        for s0, L, k in zip(self.s0, self.length, self.kappa):
            if k == 0.0:
                ss.append(np.array([s0]))
            else:
                n = int(np.ceil(max(L / max_step, abs(k) * L / max_angle))) + 1
                ss.append(s0 + np.linspace(0.0, L, n)[:-1])
        ss.append(np.array([self.total_length]))
        s = np.concatenate(ss)
        return s, self.evaluate(s)[0]


@dataclass
class CarRoute:
    """What the car drove, for evaluation (along/cross-track) and tests.

    Attributes
    ----------
    graph : RoadGraph
    nodes : (K,) int
        Route node indices in ``graph`` (consecutive nodes are directed segments).
    polyline : (K, 2) m
        The OSM centre line of the route, local metres.
    path : CarPath
        The smoothed path actually driven (corner arcs).
    centerline : (M, 2) m
        Dense samples of ``path`` (for :func:`selfnav.roads.graph.project_to_polyline`).
    centerline_s : (M,) m
    s, speed, accel, curvature : (N,) per trajectory sample
        Arc length (m), speed (m/s), along-track acceleration (m/s²), curvature (1/m).
    xy : (N, 2) m
        Local position of each trajectory sample.
    stops : (J,) m
        Arc lengths of the stops.
    """

    graph: object
    nodes: np.ndarray
    polyline: np.ndarray
    path: CarPath
    centerline: np.ndarray
    centerline_s: np.ndarray
    s: np.ndarray
    speed: np.ndarray
    accel: np.ndarray
    curvature: np.ndarray
    xy: np.ndarray
    stops: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def lateral_accel(self):
        """``v² κ`` (m/s², positive to the right)."""
        return self.speed ** 2 * self.curvature


@dataclass
class CarTrajectory(Trajectory):
    """A :class:`Trajectory` that also carries the :class:`CarRoute` it was driven on."""

    route: CarRoute | None = None


# ------------------------------------------------------------------ route
def random_route(graph, length_m, rng, *, start=None, max_turn=np.radians(150.0),
                 min_radius=2.0, corner_radius=12.0, simplify_tol=0.5):
    """A random route of at least ``length_m`` on a strongly connected graph: shortest paths to
    random junctions chained end to end, avoiding U-turns where two paths meet and legs whose
    rounded corners would be tighter than ``min_radius`` (a U-turn through a short connector
    between two carriageways, say)."""
    from scipy.sparse.csgraph import dijkstra

    csr = graph.csr
    und_deg = np.bincount(np.concatenate([graph.seg_u, graph.seg_v]), minlength=graph.n_nodes)
    # a node with twin segments counts each road twice; dead ends have one road
    twin_pairs = graph.seg_twin >= 0
    roads = und_deg - np.bincount(graph.seg_u[twin_pairs], minlength=graph.n_nodes)
    junction = is_junction(graph)
    targets = np.flatnonzero(roads >= 3)
    if len(targets) < 2:
        targets = np.flatnonzero(roads >= 2)
    node = int(rng.choice(targets) if start is None else start)
    legs = []           # list of node paths, chained
    total = 0.0
    xy = graph.xy
    budget = 100 + int(length_m / 20.0)
    banned = set()
    while total < length_m:
        prev = legs[-1][-2] if legs else None
        _, pred = dijkstra(csr, indices=node, return_predecessors=True)
        found = None
        for tgt in rng.permutation(targets)[:200]:
            tgt = int(tgt)
            if tgt == node or pred[tgt] < 0:
                continue
            path = [tgt]
            while path[-1] != node:
                path.append(int(pred[path[-1]]))
            path = path[::-1]
            if (path[-2], path[-1]) in banned:
                continue
            if prev is not None:
                d0 = xy[node] - xy[prev]
                d1 = xy[path[1]] - xy[node]
                c = np.dot(d0, d1) / (np.linalg.norm(d0) * np.linalg.norm(d1) + 1e-12)
                if path[1] == prev or np.arccos(np.clip(c, -1, 1)) > max_turn:
                    continue
            nodes = ([prev] if prev is not None else []) + path
            if _min_corner_radius(xy[nodes], simplify_tol, corner_radius,
                                  junction[nodes]) < min_radius:
                continue
            found = path
            break
        budget -= 1
        if budget < 0:
            raise InputError(graph.name, "cannot find a route without U-turns on this map")
        if found is None:
            if not legs:
                node = int(rng.choice(targets))
                continue
            bad = legs.pop()          # no way on without a U-turn: drop the last leg
            banned.add((bad[-2], bad[-1]))
            total -= _poly_length(xy[bad])
            node = bad[0]
            continue
        legs.append(found)
        total += _poly_length(xy[found])
        node = found[-1]
    route = [legs[0][0]] + [n for leg in legs for n in leg[1:]]
    return np.asarray(route, np.int64)


def is_junction(graph):
    """Nodes where three or more roads meet (five or more directed segment ends)."""
    return np.bincount(np.concatenate([graph.seg_u, graph.seg_v]), minlength=graph.n_nodes) >= 5


def _corner_radii(poly, corner_radius):
    """Turn angle and arc radius at each interior vertex (see :func:`smooth_path`)."""
    d = np.diff(poly, axis=0)
    L = np.hypot(d[:, 0], d[:, 1])
    psi = np.arctan2(d[:, 0], d[:, 1])
    theta = (psi[1:] - psi[:-1] + np.pi) % (2 * np.pi) - np.pi
    with np.errstate(divide="ignore", invalid="ignore"):
        r_fit = 0.5 * np.minimum(L[:-1], L[1:]) / np.tan(np.abs(theta) / 2)
    return theta, np.where(np.abs(theta) > 1e-9, np.minimum(corner_radius, r_fit), np.inf)


def _min_corner_radius(pts, simplify_tol, corner_radius, keep=None):
    pts = pts[_simplify(pts, simplify_tol, keep)]
    if len(pts) < 3:
        return np.inf
    return float(np.min(_corner_radii(pts, corner_radius)[1]))


def _poly_length(p):
    d = np.diff(p, axis=0)
    return float(np.hypot(d[:, 0], d[:, 1]).sum())


def _edge_segments(graph, nodes):
    """Segment index of each consecutive node pair; error if the route breaks a one-way."""
    lookup = {(u, v): i for i, (u, v) in enumerate(zip(graph.seg_u.tolist(), graph.seg_v.tolist()))}
    out = []
    for a, b in zip(nodes[:-1].tolist(), nodes[1:].tolist()):
        i = lookup.get((a, b))
        if i is None:
            raise InputError(graph.name, f"route step {a} -> {b} is not a drivable directed road "
                             "segment (missing, or against a one-way)")
        out.append(i)
    return np.asarray(out, np.int64)


def smooth_path(poly, speeds, corner_radius=12.0) -> CarPath:
    """Replace each vertex of a polyline by a tangent circular arc (line-arc-line).

    Parameters
    ----------
    poly : (K, 2) vertices (consecutive duplicates not allowed)
    speeds : (K-1,) road speed of each leg, m/s
    corner_radius : float
        Nominal arc radius, m; smaller where a leg is shorter than twice the tangent length.
    """
    d = np.diff(poly, axis=0)
    L = np.hypot(d[:, 0], d[:, 1])
    psi = np.arctan2(d[:, 0], d[:, 1])
    theta, R = _corner_radii(poly, corner_radius)       # turn and radius at interior vertices
    T = np.where(np.isfinite(R), R * np.tan(np.abs(theta) / 2), 0.0)
    t_in = np.concatenate([[0.0], T])      # tangent length used at the start of each leg
    t_out = np.concatenate([T, [0.0]])     # ... and at its end
    s0, p0, psi0, kap, length, spd = [], [], [], [], [], []
    vs = np.zeros(len(poly))
    s = 0.0
    for i in range(len(L)):
        u = d[i] / L[i]
        lin = L[i] - t_in[i] - t_out[i]
        if lin > 1e-9:
            s0.append(s), p0.append(poly[i] + u * t_in[i]), psi0.append(psi[i])
            kap.append(0.0), length.append(lin), spd.append(speeds[i])
            s += lin
        vs[i + 1] = s
        if i < len(theta) and np.isfinite(R[i]):
            arc = R[i] * abs(theta[i])
            s0.append(s), p0.append(poly[i + 1] - u * T[i]), psi0.append(psi[i])
            kap.append(np.sign(theta[i]) / R[i]), length.append(arc)
            spd.append(min(speeds[i], speeds[i + 1]))
            s += arc
    return CarPath(np.array(s0), np.array(p0), np.array(psi0), np.array(kap), np.array(length),
                   np.array(spd), vs)


# ------------------------------------------------------------ speed profile
def speed_profile(path: CarPath, *, max_speed, a_max, lat_acc_max, stop_s=(), ds=0.5):
    """Speed at grid points of ``s`` under road, corner, acceleration and stop limits.

    Returns ``(s_grid, v_grid)``; the grid holds every element boundary and every stop, the
    speed is 0 at the start, at the end and at the stops.
    """
    total = path.total_length
    s = np.unique(np.concatenate([np.arange(0.0, total, ds), path.s0, [total],
                                  np.asarray(stop_s, float)]))
    s = s[(s >= 0) & (s <= total)]
    mid = 0.5 * (s[1:] + s[:-1])
    e = path.element(mid)
    with np.errstate(divide="ignore"):
        v_cell = np.minimum(np.minimum(path.speed[e], max_speed),
                            np.sqrt(lat_acc_max / np.abs(path.kappa[e])))
    vmax = np.empty(len(s))
    vmax[0], vmax[-1] = 0.0, 0.0
    vmax[1:-1] = np.minimum(v_cell[1:], v_cell[:-1])
    vmax[np.isin(s, np.asarray(stop_s, float))] = 0.0
    v = _limit_accel(s, vmax, a_max)
    return s, v


def _limit_accel(s, vmax, a_max):
    v = vmax.copy()
    dsq = 2.0 * a_max * np.diff(s)
    for i in range(len(v) - 1):          # forward: accelerate no faster than a_max
        lim = np.sqrt(v[i] ** 2 + dsq[i])
        if v[i + 1] > lim:
            v[i + 1] = lim
    for i in range(len(v) - 2, -1, -1):  # backward: brake no harder than a_max
        lim = np.sqrt(v[i + 1] ** 2 + dsq[i])
        if v[i] > lim:
            v[i] = lim
    return v


def sample_motion(s, v, dwell, t):
    """Exact arc length, speed and acceleration at times ``t`` (constant acceleration per cell).

    ``dwell[i]`` seconds are spent standing at grid point ``i`` before leaving it.
    """
    ds = np.diff(s)
    vsum = v[1:] + v[:-1]
    dt = 2.0 * ds / np.where(vsum > 0, vsum, np.inf)
    a = np.where(dt > 0, (v[1:] - v[:-1]) / np.where(dt > 0, dt, 1.0), 0.0)
    depart = np.concatenate([[0.0], np.cumsum(dwell[:-1] + dt)]) + dwell   # leave point i
    arrive = depart - dwell
    t = np.asarray(t, float)
    i = np.clip(np.searchsorted(arrive, t, side="right") - 1, 0, len(s) - 1)
    tau = np.maximum(t - depart[i], 0.0)         # 0 while dwelling
    moving = (t >= depart[i]) & (i < len(s) - 1)
    ic = np.minimum(i, len(s) - 2)
    tau = np.where(moving, np.minimum(tau, dt[ic]), 0.0)
    acc = np.where(moving, a[ic], 0.0)
    vel = np.where(moving, v[ic] + a[ic] * tau, np.where(i == len(s) - 1, v[-1], 0.0))
    pos = np.where(moving, s[ic] + v[ic] * tau + 0.5 * a[ic] * tau ** 2, s[i])
    return pos, vel, acc, float(arrive[-1])


# ------------------------------------------------------------------ public
def car_route(graph, *, duration=600.0, dt=0.01, seed=None, route=None, max_speed=25.0,
              a_max=2.0, lat_acc_max=2.5, stops=True, corner_radius=12.0, stop_prob=0.25,
              dwell=(1.0, 8.0), hold_start=0.0, roll_gain=0.004, roll_tau=0.5, h0=0.0,
              simplify_tol=0.5, min_radius=2.0):
    """Simulate a car on ``graph``; return ``(CarTrajectory, CarRoute)``.

    Parameters
    ----------
    graph : selfnav.roads.graph.RoadGraph
        Preferably strongly connected (the default of :func:`selfnav.roads.graph.read_roads`).
    duration, dt : float
        Length and sample interval of the trajectory, s (the car may not have finished its
        route; it starts at rest).
    seed : int, optional
        Random route, stops and dwell times.
    route : sequence of int, optional
        Node indices to drive (each consecutive pair a directed segment of ``graph``); the
        trajectory ends when the route ends (at rest) or at ``duration``.
    max_speed, a_max, lat_acc_max : float
        m/s, m/s² (accelerating and braking), m/s² (in corners).
    stops : bool
        Random stops at junctions (probability ``stop_prob``, ``dwell`` seconds uniform).
    corner_radius, min_radius : float
        Nominal corner arc radius, m; a random route avoids legs that would need a corner
        tighter than ``min_radius`` (given routes are driven as they are).
    simplify_tol : float
        OSM vertices closer than this (m) to the line through their neighbours are dropped
        before the corners are rounded (Douglas-Peucker), so that a node splitting a straight
        street just before a junction does not force a tiny corner radius; the path then
        departs from the OSM centre line by at most this much on the straights.
    hold_start : float
        Seconds at rest before driving off.
    roll_gain, roll_tau : float
        Body roll per unit lateral acceleration (rad per m/s², outward) and its lag, s.
    h0 : float
        Ellipsoidal height of the (flat) road, m.
    """
    rng = np.random.default_rng(seed)
    if route is None:
        nodes = random_route(graph, duration * max_speed + 200.0, rng, min_radius=min_radius,
                             corner_radius=corner_radius, simplify_tol=simplify_tol)
    else:
        nodes = np.asarray(route, np.int64)
        if len(nodes) < 2:
            raise InputError(graph.name, "a route needs at least two nodes")
    segs = _edge_segments(graph, nodes)
    poly = graph.xy[nodes]
    junction = is_junction(graph)
    kept = _simplify(poly, simplify_tol, junction[nodes])   # drop nearly collinear vertices
    leg_speed = np.minimum.reduceat(graph.seg_speed[segs], kept[:-1])
    path = smooth_path(poly[kept], leg_speed, corner_radius)
    stop_s = np.zeros(0)
    if stops:   # before junctions (3+ roads meet), turning or not
        inner = kept[1:-1]
        pick = junction[nodes[inner]] & (rng.random(len(inner)) < stop_prob)
        stop_s = np.clip(path.vertex_s[1:-1][pick] - 3.0, 0.5, path.total_length - 0.5)
    s_grid, v_grid = speed_profile(path, max_speed=max_speed, a_max=a_max,
                                   lat_acc_max=lat_acc_max, stop_s=stop_s)
    dw = np.zeros(len(s_grid))
    dw[0] = hold_start
    if len(stop_s):
        dw[np.searchsorted(s_grid, stop_s)] = rng.uniform(*dwell, size=len(stop_s))
    n = int(np.floor(duration / dt + 1e-9)) + 1
    t = np.arange(n) * dt
    s, v, a, t_end = sample_motion(s_grid, v_grid, dw, t)
    if route is not None and t_end < t[-1]:
        keep = t < t_end + dt            # the last sample is at rest on the last node
        t, s, v, a = t[keep], s[keep], v[keep], a[keep]
    xy, psi, kappa = path.evaluate(s)
    lat, lon = graph.to_geodetic(xy[:, 0], xy[:, 1])
    heading = (psi + graph.true_heading_offset(xy[:, 0], xy[:, 1])) % (2 * np.pi)
    vel = np.column_stack([v * np.sin(heading), v * np.cos(heading), np.zeros_like(v)])
    roll = _lag(-roll_gain * v ** 2 * kappa, dt, roll_tau) if roll_gain else np.zeros_like(v)
    C_nb = att.dcm_nb_from_euler(roll, np.zeros_like(v), heading)
    c_s, c_xy = path.sample()
    # keep the part of the route that was driven (the random route is made long enough)
    j = min(len(kept) - 1, int(np.searchsorted(path.vertex_s, s[-1], side="right")))
    n_vert = int(kept[j]) + 1
    n_c = min(len(c_s), int(np.searchsorted(c_s, s[-1], side="right")) + 1)
    car = CarRoute(graph, nodes[:n_vert], poly[:n_vert], path, c_xy[:n_c], c_s[:n_c], s, v, a,
                   kappa, xy, stop_s[stop_s <= s[-1]])
    traj = CarTrajectory(t, lat, lon, np.full_like(t, h0), vel, C_nb,
                         source=f"simulated car on {graph.name}", route=car)
    return traj, car


def car_trajectory(graph, *, duration=600.0, dt=0.01, seed=None, route=None, max_speed=25.0,
                   a_max=2.0, lat_acc_max=2.5, stops=True, **kw) -> CarTrajectory:
    """Simulate a car driving on ``graph``; a :class:`Trajectory` with ``.route`` attached.

    See :func:`car_route` for the parameters; ``traj.route`` is the :class:`CarRoute` (OSM
    polyline, smoothed centre line, per-sample arc length, speed, acceleration, curvature).
    """
    traj, _ = car_route(graph, duration=duration, dt=dt, seed=seed, route=route,
                        max_speed=max_speed, a_max=a_max, lat_acc_max=lat_acc_max, stops=stops,
                        **kw)
    return traj


def _simplify(poly, tol, keep=None):
    """Indices of the vertices Douglas-Peucker (shapely) keeps; vertices where ``keep`` is
    True (junctions), the first and the last are always kept."""
    import shapely

    n = len(poly)
    if tol <= 0 or n < 3:
        return np.arange(n)
    cuts = np.flatnonzero(keep) if keep is not None else np.zeros(0, np.int64)
    cuts = np.unique(np.concatenate([[0, n - 1], cuts]))
    out = [np.zeros(1, np.int64)]
    for a, b in zip(cuts[:-1], cuts[1:]):
        if b - a < 2:
            out.append(np.array([b]))
            continue
        piece = poly[a:b + 1]
        simple = shapely.get_coordinates(shapely.simplify(shapely.linestrings(piece), tol,
                                                          preserve_topology=False))
        idx = np.empty(len(simple), np.int64)
        i = 0
        for k, c in enumerate(simple):      # the kept vertices are a subsequence of the piece
            while not (piece[i, 0] == c[0] and piece[i, 1] == c[1]):
                i += 1
            idx[k] = i
            i += 1
        idx[-1] = len(piece) - 1
        out.append(a + idx[1:])
    return np.concatenate(out)


def _lag(x, dt, tau):
    """First-order lag ``tau y' + y = x`` (exact discretisation for piecewise-constant input)."""
    from scipy.signal import lfilter

    if tau <= 0:
        return x
    alpha = np.exp(-dt / tau)
    return lfilter([1 - alpha], [1, -alpha], x, zi=[alpha * x[0]])[0]
