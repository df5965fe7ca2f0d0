"""selfnav evaluate: metrics against analytic cases and pyproj's geodesic, report files, CLI."""
import base64
import json
import re

import numpy as np
import pytest
from pyproj import Geod

from selfnav import attitude as att
from selfnav.cli import main
from selfnav.earth import ecef_to_geodetic, geodetic_to_ecef
from selfnav.errors import SelfnavError
from selfnav.earth import enu_rotation
from selfnav.evaluation import error_metrics, evaluate
from selfnav.report import write_report
from selfnav.types import Trajectory
from selfnav.io.trajectory import write_truth

LAT0, LON0, H0 = np.radians(59.9343), np.radians(30.3351), 20.0


def _from_enu(enu, lat0=LAT0, lon0=LON0, h0=H0):
    """Geodetic (rad, rad, m) of local ENU points (m) about (lat0, lon0, h0)."""
    x0 = geodetic_to_ecef(lat0, lon0, h0)
    C = enu_rotation(lat0, lon0)
    return ecef_to_geodetic(x0 + np.asarray(enu) @ C)


def _traj(t, enu, heading=None, velocity=None, with_att=True):
    lat, lon, h = _from_enu(enu)
    n = len(t)
    v = np.full((n, 3), np.nan) if velocity is None else velocity
    if with_att and heading is not None:
        C = att.dcm_nb_from_euler(np.zeros(n), np.zeros(n), heading)
    else:
        C = np.full((n, 3, 3), np.nan)
    return Trajectory(np.asarray(t, float), lat, lon, h, v, C, source="simulated test track")


def _straight(heading_deg=30.0, speed=10.0, T=100.0, dt=1.0):
    t = np.arange(0.0, T + dt / 2, dt)
    psi = np.radians(heading_deg)
    u = np.array([np.sin(psi), np.cos(psi), 0.0])
    enu = speed * t[:, None] * u
    return t, enu, u, psi


def _offset_solution(truth_t, enu, offset_enu):
    """Solution whose error is exactly ``offset_enu`` in the ENU frame of each truth point."""
    lat, lon, h = _from_enu(enu)
    out = []
    for k in range(len(truth_t)):
        x = geodetic_to_ecef(lat[k], lon[k], h[k]) + np.asarray(offset_enu[k]) @ enu_rotation(
            lat[k], lon[k])
        out.append(ecef_to_geodetic(x))
    out = np.array(out)
    n = len(truth_t)
    return Trajectory(truth_t.copy(), out[:, 0], out[:, 1], out[:, 2], np.full((n, 3), np.nan),
                      np.full((n, 3, 3), np.nan), source="simulated solution")


def test_constant_offset_analytic():
    t, enu, u, psi = _straight(heading_deg=30.0)
    truth = _traj(t, enu, heading=np.full(len(t), psi))
    off = np.tile([3.0, 4.0, -2.0], (len(t), 1))
    ev = evaluate(truth, _offset_solution(t, enu, off))
    m = ev.metrics
    for k in ("horizontal_rms_m", "horizontal_p95_m", "horizontal_max_m", "horizontal_mean_m"):
        assert m[k] == pytest.approx(5.0, abs=1e-6)
    assert m["vertical_rms_m"] == pytest.approx(2.0, abs=1e-6)
    # along = e·u, cross = e·(u turned right) with u = (sin 30°, cos 30°)
    along = 3 * np.sin(psi) + 4 * np.cos(psi)
    cross = 3 * np.cos(psi) - 4 * np.sin(psi)
    assert m["along_track_rms_m"] == pytest.approx(abs(along), abs=1e-6)
    assert m["cross_track_mean_m"] == pytest.approx(cross, abs=1e-6)
    assert m["samples"] == len(t) and m["duration_s"] == pytest.approx(100.0)


def test_random_errors_against_pyproj_geodesic():
    rng = np.random.default_rng(1)
    t, enu, u, psi = _straight(heading_deg=-75.0, T=300.0)
    truth = _traj(t, enu, heading=np.full(len(t), psi))
    off = rng.normal(size=(len(t), 3)) * [2.0, 3.0, 1.5]
    off[:, 2] = 0.0  # same height: the geodesic distance is then the horizontal error
    sol = _offset_solution(t, enu, off)
    ev = evaluate(truth, sol)
    g = Geod(ellps="WGS84")
    _, _, dist = g.inv(np.degrees(truth.lon), np.degrees(truth.lat), np.degrees(sol.lon),
                       np.degrees(sol.lat))
    # the geodesic is measured on the ellipsoid, our error at h = 20 m: scale (R + h)/R
    dist = dist * (1.0 + H0 / 6.37e6)
    assert np.max(np.abs(ev.horizontal - dist) / dist) < 1e-6
    assert ev.metrics["horizontal_rms_m"] == pytest.approx(np.sqrt(np.mean(dist**2)), rel=1e-6)
    assert ev.metrics["horizontal_p95_m"] == pytest.approx(np.percentile(dist, 95), rel=1e-6)
    assert ev.metrics["horizontal_max_m"] == pytest.approx(dist.max(), rel=1e-6)
    # along/cross is a rotation of (E, N): the squares add up
    assert np.allclose(ev.along**2 + ev.cross**2, ev.horizontal**2)


@pytest.mark.filterwarnings("ignore:.*covers .* of the truth's time span:selfnav.errors.SelfnavWarning")  # expected here
def test_time_lag_is_along_track_and_interpolation_is_exact():
    speed, lag = 12.0, 0.25
    t, enu, u, psi = _straight(heading_deg=135.0, speed=speed, T=60.0, dt=1.0)
    # truth without attitude: heading from the velocity columns
    truth = _traj(t, enu, velocity=np.tile(speed * u, (len(t), 1)), with_att=False)
    ts = np.arange(0.3, 59.0, 0.1)  # solution epochs between truth samples
    sol = _traj(ts, speed * (ts - lag)[:, None] * u)  # lags behind by 0.25 s
    ev = evaluate(truth, sol)
    assert np.allclose(ev.along, -speed * lag, atol=1e-4)
    # the track is straight in the start point's ENU frame; 700 m away the local North has
    # turned by the meridian convergence Δλ sin φ ≈ 1.4e-4 rad: 3 m × 1.4e-4 = 0.4 mm
    assert np.allclose(ev.cross, 0.0, atol=1e-3)
    assert ev.metrics["horizontal_rms_m"] == pytest.approx(speed * lag, abs=1e-4)
    # no velocity, no attitude: heading from the position differences
    truth2 = _traj(t, enu, with_att=False)
    ev2 = evaluate(truth2, sol)
    assert np.allclose(ev2.along, -speed * lag, atol=1e-4)


def test_curved_track_cross_track_sign():
    # anticlockwise circle of radius 200 m; solution 1.5 m further out = to the right
    w = 0.05
    t = np.arange(0.0, 120.0, 0.5)
    ang = w * t
    enu = np.column_stack([200 * np.cos(ang), 200 * np.sin(ang), 0 * t])
    vel = np.column_stack([-200 * w * np.sin(ang), 200 * w * np.cos(ang), 0 * t])
    truth = _traj(t, enu, velocity=vel, with_att=False)
    sol = _traj(t, enu * (201.5 / 200.0))
    ev = evaluate(truth, sol)
    assert np.allclose(ev.cross, 1.5, atol=2e-3)
    assert np.allclose(ev.along, 0.0, atol=2e-3)


def test_road_relative_along_cross():
    t, enu, u, psi = _straight(heading_deg=30.0)
    # the truth heading is wrong by 10° (a poor attitude reference) ...
    truth = _traj(t, enu, heading=np.full(len(t), psi + np.radians(10.0)))
    right = np.array([u[1], -u[0], 0.0])
    sol = _offset_solution(t, enu, np.tile(2.0 * right, (len(t), 1)))
    # ... but the road follows the track: road-relative cross-track is exactly the offset
    road_enu = np.array([-100 * u, 1200 * u])
    rl, rlo, _ = _from_enu(road_enu)
    ev = evaluate(truth, sol, roads=[np.column_stack([rl[::-1], rlo[::-1]])])  # drawn backwards
    assert np.allclose(ev.road_cross, 2.0, atol=1e-3)
    assert np.allclose(ev.road_along, 0.0, atol=1e-3)
    assert np.allclose(ev.cross, 2.0 * np.cos(np.radians(10.0)), atol=1e-3)
    assert ev.metrics["road_cross_track_rms_m"] == pytest.approx(2.0, abs=1e-3)


@pytest.mark.filterwarnings("ignore:.*lie outside the truth's time span:selfnav.errors.SelfnavWarning")  # expected here
@pytest.mark.filterwarnings("ignore:.*covers .* of the truth's time span:selfnav.errors.SelfnavWarning")  # expected here
def test_partial_and_no_overlap():
    t, enu, u, psi = _straight()
    truth = _traj(t, enu, heading=np.full(len(t), psi))
    late = _traj(t + 50.0, enu)
    ev = evaluate(truth, late)
    assert ev.metrics["samples"] == 51 and "outside" in ev.warnings[0]
    with pytest.raises(SelfnavError, match="time spans do not overlap"):
        evaluate(truth, _traj(t + 500.0, enu))


def test_error_metrics_percentile():
    e = np.zeros((100, 3))
    e[:, 0] = np.arange(1, 101)
    m = error_metrics(e)
    assert m["horizontal_p95_m"] == pytest.approx(np.percentile(np.arange(1, 101), 95))
    assert m["horizontal_max_m"] == 100.0


@pytest.fixture()
def files(tmp_path):
    t, enu, u, psi = _straight()
    truth = _traj(t, enu, heading=np.full(len(t), psi), velocity=np.tile(10 * u, (len(t), 1)))
    sol = _offset_solution(t, enu, np.tile([1.0, 0.0, 0.5], (len(t), 1)))
    sol.velocity_n = truth.velocity_n
    sol.C_nb = truth.C_nb
    write_truth(tmp_path / "truth.csv", truth)
    write_truth(tmp_path / "sol.csv", sol)
    far = Trajectory(t + 1e4, truth.lat, truth.lon, truth.h, truth.velocity_n, truth.C_nb,
                     source="simulated")
    write_truth(tmp_path / "far.csv", far)
    return tmp_path


def test_cli_json_and_report(files, capsys):
    rc = main(["evaluate", "--truth", str(files / "truth.csv"), "--solution",
               str(files / "sol.csv"), "--json", "--report", str(files / "rep")])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["horizontal_rms_m"] == pytest.approx(1.0, abs=1e-5)  # CSV rounding: 1e-10 deg
    assert out["vertical_rms_m"] == pytest.approx(0.5, abs=1e-5)
    for k in ("horizontal_p95_m", "horizontal_max_m", "along_track_rms_m", "cross_track_rms_m"):
        assert k in out
    html = (files / "rep" / "report.html").read_text()
    imgs = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(imgs) == 2 and all(base64.b64decode(i)[:8] == b"\x89PNG\r\n\x1a\n" for i in imgs)
    assert (files / "rep" / "errors.png").read_bytes()[:4] == b"\x89PNG"
    assert json.loads((files / "rep" / "metrics.json").read_text())["samples"] == 101
    assert not list((files / "rep").glob(".*tmp"))  # atomic: no temporary left


def test_cli_errors_are_one_line(files, capsys):
    rc = main(["evaluate", "--truth", str(files / "truth.csv"), "--solution",
               str(files / "far.csv")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.count("\n") == 0
    assert err.startswith("selfnav: error: time spans do not overlap")
    rc = main(["evaluate", "--truth", str(files / "nope.csv"), "--solution",
               str(files / "sol.csv")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "no such file" in err and err.count("\n") == 0


def test_report_with_road_background(tmp_path):
    t, enu, u, psi = _straight()
    truth = _traj(t, enu, heading=np.full(len(t), psi))
    sol = _offset_solution(t, enu, np.tile([0.5, -0.5, 0.0], (len(t), 1)))
    rl, rlo, _ = _from_enu(np.array([-50 * u, 1100 * u, 1100 * u + [300, 0, 0]]))
    roads = [np.column_stack([rl, rlo])]
    ev = evaluate(truth, sol, roads=roads)
    files = write_report(ev, tmp_path / "r", roads=roads)
    assert "road_cross_track_rms_m" in json.loads(open(files["metrics.json"]).read())
    assert "OpenStreetMap" in open(files["report.html"]).read()


def test_cli_map_real_osm_extract(tmp_path, capsys):
    """End to end on the packaged real OpenStreetMap extract (Kotka): a simulated drive along
    its longest way, a solution 2 m to the right of the road; --map gives road cross-track 2 m."""
    from selfnav.evaluation import local_xy
    from selfnav.roads.graph import packaged_map, road_polylines

    path = packaged_map("kotka_karhula")
    polys = road_polylines(path)
    lengths = [np.linalg.norm(np.diff(local_xy(r[:, 0], r[:, 1], r[0, 0], r[0, 1]), axis=0),
                              axis=1).sum() for r in polys]
    road = polys[int(np.argmax(lengths))]
    lat0, lon0 = road[0]
    xy = local_xy(road[:, 0], road[:, 1], lat0, lon0)
    seg = np.diff(xy, axis=0)
    s_cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(seg, axis=1))])
    s = np.arange(0.5, s_cum[-1] - 1.0, 20.0) + 0.37  # 20 m/s, never exactly on a vertex
    k = np.searchsorted(s_cum, s) - 1
    u = seg[k] / np.linalg.norm(seg[k], axis=1)[:, None]
    p = xy[k] + (s - s_cum[k])[:, None] * u
    right = np.column_stack([u[:, 1], -u[:, 0]])
    n = len(s)
    t = np.arange(n, dtype=float)
    hdg = np.arctan2(u[:, 0], u[:, 1])
    enu_t = np.column_stack([p, np.zeros(n)])
    enu_s = np.column_stack([p + 2.0 * right, np.zeros(n)])
    C = att.dcm_nb_from_euler(np.zeros(n), np.zeros(n), hdg)
    v = np.column_stack([20 * u, np.zeros(n)])
    for name, enu in (("truth.csv", enu_t), ("sol.csv", enu_s)):
        la, lo, h = _from_enu(enu, lat0, lon0, 0.0)
        write_truth(tmp_path / name, Trajectory(t, la, lo, h, v, C, source="simulated drive"))
    rc = main(["evaluate", "--truth", str(tmp_path / "truth.csv"), "--solution",
               str(tmp_path / "sol.csv"), "--map", str(path), "--json", "--report",
               str(tmp_path / "rep")])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["samples"] == n > 50
    assert out["road_cross_track_mean_m"] == pytest.approx(2.0, abs=0.01)
    assert out["road_cross_track_max_m"] == pytest.approx(2.0, abs=0.01)
    assert abs(out["road_along_track_mean_m"]) < 0.01
    assert out["horizontal_rms_m"] == pytest.approx(2.0, abs=0.01)
    assert (tmp_path / "rep" / "track.png").stat().st_size > 10_000


def test_cli_map_hook(files, capsys, monkeypatch):
    """--map goes through selfnav.roads.graph.road_polylines(path) -> [(M, 2) lat/lon rad]."""
    import sys
    import types

    from selfnav.io.trajectory import read_truth

    tr = read_truth(files / "truth.csv")
    fake = types.ModuleType("selfnav.roads.graph")
    fake.road_polylines = lambda path: [np.column_stack([tr.lat, tr.lon])]
    monkeypatch.setitem(sys.modules, "selfnav.roads.graph", fake)
    args = ["evaluate", "--truth", str(files / "truth.csv"), "--solution", str(files / "sol.csv"),
            "--json", "--map", str(files / "roads.osm")]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    # solution is 1 m East of a track heading 30°: cross-track (right +) = cos 30°
    assert out["road_cross_track_mean_m"] == pytest.approx(np.cos(np.radians(30)), abs=1e-4)
    monkeypatch.setitem(sys.modules, "selfnav.roads.graph", None)  # module absent
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert "selfnav.roads.graph" in err and "\n" not in err


def test_a_solution_in_radians_is_named_so_by_evaluate(tmp_path):
    """A truth or solution file whose lat_deg/lon_deg hold radians reads as a track near
    0° N 0° E, thousands of km from the other file: evaluate's reader says what the values look
    like (as navigate's and match's GNSS readers do); degrees read without the warning."""
    import warnings

    from selfnav.errors import SelfnavWarning
    from selfnav.io.trajectory import read_truth

    t = np.arange(30.0)
    lat, lon = LAT0 + 1e-6 * t, LON0 + 1e-6 * t
    for values, expect in (((lat, lon), 1), ((np.degrees(lat), np.degrees(lon)), 0)):
        p = tmp_path / f"sol{expect}.csv"
        p.write_text("t,lat_deg,lon_deg,h_m\n" + "".join(
            f"{a},{b:.10f},{c:.10f},20\n" for a, b, c in zip(t, *values)))
        with warnings.catch_warnings(record=True) as got:
            warnings.simplefilter("always")
            tr = read_truth(p)
        hits = [w for w in got if issubclass(w.category, SelfnavWarning)
                and "look like radians" in str(w.message)]
        assert len(hits) == expect
        assert str(p) in str(hits[0].message) if hits else True
        assert len(tr.t) == 30
