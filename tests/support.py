"""Helpers several test modules share (not a test module): simulated drives and their errors."""
import dataclasses

import numpy as np

from selfnav import attitude as att
from selfnav.cli import main
from selfnav.earth import radii
from selfnav.sensors import GnssModel, imu_grade
from selfnav.sim.car import car_route, car_trajectory
from selfnav.sim.inverse import imu_from_trajectory
from selfnav.types import ImuData


def simulated_drive(graph, seed, duration=600.0, outliers=(), grade="industrial", sigma=3.0):
    """Simulated car (labelled simulated): exact IMU corrupted by a grade model without
    scale-factor/misalignment terms (the 15-state filter does not model them), 1 Hz GNSS."""
    tr = car_trajectory(graph, duration=duration, dt=0.1, seed=seed, hold_start=10 if seed % 2 else 0)
    imu, truth = imu_from_trajectory(tr, 0.01, return_truth=True)
    rng = np.random.default_rng(seed)
    m = imu_grade(grade)
    m = dataclasses.replace(m, gyro=dataclasses.replace(m.gyro, scale_factor=0.0, misalignment=0.0,
                                                        quantum=0.0),
                            accel=dataclasses.replace(m.accel, scale_factor=0.0, misalignment=0.0))
    w, f = m.apply(imu.t, imu.omega_ib_b, imu.f_ib_b, rng)
    fx = GnssModel(rate_hz=1, sigma_h=sigma, sigma_v=5, outliers=list(outliers)).simulate(truth, rng)
    g = fx.as_gnss()
    return ImuData(imu.t, w, f, source="simulated car"), g, truth


def errors(res, truth):
    tt = res.trajectory
    k = np.clip(np.searchsorted(truth.t, tt.t), 0, len(truth.t) - 1)
    ok = np.abs(truth.t[k] - tt.t) < 1e-6
    k = k[ok]
    rm, rn = radii(truth.lat[k])
    de = (tt.lon[ok] - truth.lon[k]) * rn * np.cos(truth.lat[k])
    dn = (tt.lat[ok] - truth.lat[k]) * rm
    dv = tt.velocity_n[ok] - truth.velocity_n[k]
    psi = -att.dcm_to_rotvec(np.swapaxes(tt.C_nb[ok], 1, 2) @ truth.C_nb[k])
    return tt.t[ok], np.column_stack([de, dn]), dv, psi, ok


def window_metrics(res, truth, win):
    """Horizontal error: RMS and max inside the outlier window, RMS outside it (from 60 s after
    the in-motion alignment transient)."""
    t, dp, *_ = errors(res, truth)
    e = np.hypot(dp[:, 0], dp[:, 1])
    w = (t >= win.start) & (t < win.end)
    rest = ~w & (t > t[0] + 60.0)
    return np.sqrt(np.mean(e[w] ** 2)), e[w].max(), np.sqrt(np.mean(e[rest] ** 2))


def route_drive(g, windows, seed=3, duration=300.0):
    """A simulated car route on graph ``g`` with 1 Hz, 10 m GNSS and outlier ``windows``: the
    route, the fixes in map coordinates, the truth index of each fix, the truth heading, the
    fixes."""
    traj, route = car_route(g, duration=duration, dt=0.1, seed=seed)
    fx = GnssModel(1.0, 10.0, 15.0, outliers=windows).simulate(traj, 1)
    x, y = g.to_local(fx.lat, fx.lon)
    idx = np.minimum(np.searchsorted(traj.t, fx.t), len(traj.t) - 1)
    hdg = np.arctan2(traj.velocity_n[:, 0], traj.velocity_n[:, 1])
    return route, np.column_stack([x, y]), idx, hdg, fx


def run_cli(argv, capsys):
    """Run ``selfnav argv...`` in-process; returns ``(exit code, stdout, stderr)``.

    The first-run compile line is dropped from stderr: whether it shows depends on which test
    met a kernel first in a fresh clone (tests/test_first_run_and_pages.py checks it)."""
    from selfnav.cli.progress import COMPILE_LINE

    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    err = "".join(ln for ln in out.err.splitlines(keepends=True) if ln.rstrip("\n") != COMPILE_LINE)
    return code, out.out, err
