"""A simulated car on real OpenStreetMap roads (selfnav.sim.car): stays on the centre line,
respects one-ways and its acceleration limits, stops, and gives a consistent trajectory."""
import numpy as np

from selfnav import attitude as att
import pytest

from selfnav.errors import InputError
from selfnav.roads.graph import project_to_polyline
from selfnav.sim.car import CarTrajectory, car_route, car_trajectory, smooth_path
from selfnav.types import Trajectory

A_MAX, LAT_MAX, V_MAX = 2.0, 2.5, 20.0


@pytest.fixture(scope="module")
def drive(helsinki):
    return car_route(helsinki, duration=300.0, dt=0.01, seed=4, max_speed=V_MAX, a_max=A_MAX,
                     lat_acc_max=LAT_MAX)


def test_returns_a_labelled_trajectory(drive, karhula):
    traj, route = drive
    assert isinstance(traj, Trajectory) and isinstance(traj, CarTrajectory)
    assert traj.route is route
    assert traj.source.startswith("simulated car on helsinki_centre")
    assert len(traj) == 30001 and np.allclose(np.diff(traj.t), 0.01)
    t2 = car_trajectory(karhula, duration=20.0, dt=0.1, seed=1)
    assert isinstance(t2, Trajectory) and len(t2) == 201


def test_route_respects_one_way_streets(helsinki, drive):
    _, route = drive
    directed = set(zip(helsinki.seg_u.tolist(), helsinki.seg_v.tolist()))
    steps = list(zip(route.nodes[:-1].tolist(), route.nodes[1:].tolist()))
    assert all(s in directed for s in steps)
    oneway = helsinki.seg_twin < 0
    assert oneway.mean() > 0.1          # the Helsinki grid has plenty of one-way streets
    # driving a one-way street backwards is refused
    i = int(np.flatnonzero(oneway)[0])
    with pytest.raises(InputError, match="one-way"):
        car_route(helsinki, route=[helsinki.seg_v[i], helsinki.seg_u[i]], duration=10.0)


@pytest.fixture(scope="module")
def exact_drive(helsinki):
    """No simplification of the OSM line: the straights are the OSM segments themselves."""
    return car_route(helsinki, duration=300.0, dt=0.01, seed=4, max_speed=V_MAX, a_max=A_MAX,
                     lat_acc_max=LAT_MAX, simplify_tol=0.0)


@pytest.mark.parametrize("which, tol", [("drive", 0.5), ("exact_drive", 0.0)])
def test_car_stays_on_the_centre_line(helsinki, request, which, tol):
    traj, route = request.getfixturevalue(which)
    x, y = helsinki.to_local(traj.lat, traj.lon)
    xy = np.column_stack([x, y])
    _, cross, _ = project_to_polyline(xy, route.centerline, near_s=route.s, window=30.0)
    assert np.max(np.abs(cross)) < 0.01                   # on the driven (smoothed) centre line
    # against the OSM centre line: exact on the straights, corners cut by at most R(sec(θ/2)-1)
    path = route.path
    e = path.element(route.s)
    _, c_osm, _ = project_to_polyline(xy, route.polyline)
    straight = path.kappa[e] == 0
    assert np.max(np.abs(c_osm[straight])) < tol + 1e-3     # OSM vertices within tol dropped
    theta = np.abs(path.kappa * path.length)
    with np.errstate(divide="ignore", invalid="ignore"):
        cut = np.where(path.kappa != 0, (1 / np.cos(theta / 2) - 1) / np.abs(path.kappa), 0.0)
    assert np.all(np.abs(c_osm) <= cut[e] + tol + 1e-3)
    driven = path.s0 <= route.s[-1]
    assert np.all(np.abs(path.kappa[driven]) <= 1 / 2.0)     # min_radius 2 m
    assert np.max(cut[driven]) <= 12.0 * (1 / np.cos(np.radians(75)) - 1)  # turns <= 150°


def test_heading_follows_the_road(helsinki, exact_drive):
    traj, route = exact_drive
    _, pitch, heading = att.euler_from_dcm_nb(traj.C_nb)
    x, y = helsinki.to_local(traj.lat, traj.lon)
    grid_heading = heading - helsinki.true_heading_offset(x, y)
    e = route.path.element(route.s)
    on_line = route.path.kappa[e] == 0
    d = (grid_heading - route.path.psi0[e] + np.pi) % (2 * np.pi) - np.pi
    assert np.max(np.abs(d[on_line])) < 1e-7     # 6e-6 deg: lat/lon round trip
    # and that direction is the OSM segment's: each line element lies on a route segment
    segs = dict(zip(zip(helsinki.seg_u.tolist(), helsinki.seg_v.tolist()),
                    helsinki.seg_heading))
    road = np.array([segs[s] for s in zip(route.nodes[:-1].tolist(), route.nodes[1:].tolist())])
    driven_lines = (route.path.kappa == 0) & (route.path.s0 <= route.s[-1])
    dd = (route.path.psi0[driven_lines][:, None] - road[None, :] + np.pi) % (
        2 * np.pi) - np.pi
    assert np.max(np.min(np.abs(dd), axis=1)) < 1e-9
    assert np.all(pitch == 0.0)


def test_velocity_and_attitude_are_consistent(helsinki, drive):
    traj, route = drive
    x, y = helsinki.to_local(traj.lat, traj.lon)
    dt = np.diff(traj.t)
    v_fd = np.column_stack([np.diff(x), np.diff(y)]) / dt[:, None]
    off = helsinki.true_heading_offset(x, y)
    c, s = np.cos(off), np.sin(off)
    ve, vn = traj.velocity_n[:, 0], traj.velocity_n[:, 1]
    v_grid = np.column_stack([c * ve - s * vn, s * ve + c * vn])   # true -> grid axes
    v_mid = 0.5 * (v_grid[1:] + v_grid[:-1])
    assert np.max(np.abs(v_fd - v_mid)) < 0.02    # second-order error in corners only
    C = traj.C_nb
    np.testing.assert_allclose(C @ np.swapaxes(C, 1, 2), np.broadcast_to(np.eye(3), C.shape),
                               atol=1e-12)
    speed = np.hypot(ve, vn)
    moving = speed > 0.1
    fwd = C[moving, 1, :]            # second row of C_nb: the forward axis in ENU
    np.testing.assert_allclose(fwd[:, :2] * speed[moving, None],
                               traj.velocity_n[moving, :2], atol=1e-9)
    roll, _, _ = att.euler_from_dcm_nb(traj.C_nb)
    assert np.max(np.abs(roll)) < np.radians(1.0)        # small body roll in corners


def test_speed_profile_limits_and_stops(helsinki, drive):
    traj, route = drive
    v = route.speed
    assert v[0] == 0.0                                       # starts at rest
    dv = np.diff(v) / np.diff(traj.t)
    assert np.max(np.abs(dv)) <= A_MAX * (1 + 1e-9)
    assert np.max(np.abs(route.accel)) <= A_MAX * (1 + 1e-9)
    assert np.max(np.abs(route.lateral_accel)) <= LAT_MAX * (1 + 1e-9)
    assert np.max(v) <= V_MAX
    seg_speed = dict(zip(zip(helsinki.seg_u.tolist(), helsinki.seg_v.tolist()),
                         helsinki.seg_speed))
    road_max = max(seg_speed[s] for s in zip(route.nodes[:-1].tolist(), route.nodes[1:].tolist()))
    assert np.max(v) <= road_max + 1e-9
    # it does drive, slows for corners (some corner needs < the straight-road speed) and stops
    assert route.s[-1] > 500.0
    assert len(route.stops) >= 1
    for s_stop in route.stops:
        at = np.abs(route.s - s_stop) < 1e-9
        assert at.sum() >= 100          # >= 1 s standing still at 100 Hz
        assert np.all(v[at] == 0.0)
    tight = np.abs(route.curvature) > LAT_MAX / 8.0 ** 2
    assert tight.any() and np.max(v[tight]) < 8.0 + 1e-9


def test_given_route_ends_at_rest_on_the_last_node(karhula):
    g = karhula
    from scipy.sparse.csgraph import dijkstra

    _, pred = dijkstra(g.csr, indices=0, return_predecessors=True)
    far = int(np.argmax(np.where(np.isfinite(dijkstra(g.csr, indices=0)), dijkstra(g.csr,
                                                                                     indices=0), 0)))
    nodes = [far]
    while nodes[-1] != 0:
        nodes.append(int(pred[nodes[-1]]))
    nodes = nodes[::-1]
    traj, route = car_route(g, route=nodes, duration=3600.0, dt=0.05, stops=False)
    assert traj.t[-1] < 3600.0
    assert route.speed[-1] == pytest.approx(0.0, abs=1e-9)
    x, y = g.to_local(traj.lat[-1:], traj.lon[-1:])
    assert np.hypot(x[0] - g.xy[far, 0], y[0] - g.xy[far, 1]) < 1e-6
    assert route.path.total_length == pytest.approx(route.s[-1], abs=1e-6)


def test_corner_arc_geometry():
    # a right angle with long legs: arc of radius 12 tangent 12 m before and after the corner
    poly = np.array([[0.0, 0.0], [0.0, 100.0], [100.0, 100.0]])
    p = smooth_path(poly, np.array([10.0, 10.0]), corner_radius=12.0)
    assert p.total_length == pytest.approx(200 - 24 + 12 * np.pi / 2)
    xy, psi, k = p.evaluate(np.array([88.0, 88.0 + 3 * np.pi, 88.0 + 6 * np.pi]))
    np.testing.assert_allclose(xy[0], [0, 88], atol=1e-12)
    np.testing.assert_allclose(xy[2], [12, 100], atol=1e-12)
    centre = np.array([12.0, 88.0])
    assert np.hypot(*(xy[1] - centre)) == pytest.approx(12.0)
    np.testing.assert_allclose(psi, [0, np.pi / 4, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(k, [1 / 12, 1 / 12, 0.0])       # the arc, then the line
    np.testing.assert_allclose(xy[1], centre + 12 * np.array([-np.cos(np.pi / 4), np.sin(np.pi / 4)]))
