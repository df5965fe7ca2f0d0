"""A simulated fleet of floating cars, logged the way fleet loggers log (issue 14).

Each track is a piece of a drive of :func:`selfnav.sim.car.car_route` on a real
OpenStreetMap graph, stationary for a while at the start, sampled every ``period`` seconds (drawn
per track) with irregular intervals, time stamps rounded to the second (so two positions can fall in
the same second), white GNSS noise of σ drawn per track, and now and then a position logged twice
in the same second. Rows can be written shuffled within a track. This is simulated data; the
truth (the OSM centre line each car drove) comes with it.
"""
from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

import numpy as np

from selfnav.sim.car import car_route


@dataclass
class FleetTrackSim:
    """One simulated track: ``t`` (s, since ``t0``), fixes ``xy`` (local m, noisy), the route
    polyline (truth, local m), σ of the noise, and the ISO-8601 text of each time stamp."""

    track_id: str
    t: np.ndarray
    xy: np.ndarray
    polyline: np.ndarray
    sigma: float
    period: float
    iso: list
    true_xy: np.ndarray | None = None


def _vertex_of_samples(xy, poly, reach=40.0):
    """For each sample of a drive (in order, 1 s apart), the polyline segment it lies on: a
    monotone projection that looks no further along the polyline than the car can have driven
    (``reach`` m past the current segment), so a route that passes the same place twice is not
    confused."""
    a, b = poly[:-1], poly[1:]
    d = b - a
    seg_len = np.hypot(d[:, 0], d[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    L2 = np.maximum(seg_len ** 2, 1e-12)
    out = np.empty(len(xy), np.int64)
    k = 0
    for i, p in enumerate(xy):
        hi = max(k + 1, int(np.searchsorted(cum, cum[k + 1] + reach, side="right")))
        hi = min(hi, len(a))
        u = np.clip(((p - a[k:hi]) * d[k:hi]).sum(axis=1) / L2[k:hi], 0.0, 1.0)
        dist = np.hypot(*(a[k:hi] + u[:, None] * d[k:hi] - p).T)
        k = k + int(np.argmin(dist))
        out[i] = k
    return out


def simulate_fleet(graph, n_tracks, *, seed=0, period=(5.0, 30.0), sigma=(10.0, 30.0),
                   duration=(300.0, 1200.0), park=(0.0, 120.0), dup_prob=0.03,
                   drive_s=4 * 3600.0, t0="2019-03-11T06:00:00+00:00"):
    """``n_tracks`` floating-car tracks on ``graph``.

    Cars drive long random routes (``drive_s`` each) which are cut into tracks; each track
    starts with a stationary run (``park`` s at its first position) and has its own sampling
    and noise.

    Parameters
    ----------
    period, sigma, duration, park : (low, high)
        Per track, uniform: nominal sampling interval (s), GNSS σ per axis (m), driving time
        (s), time stationary at the start (s).
    dup_prob : float
        Probability that a fix is logged twice in the same second (a second position).
    t0 : str
        ISO-8601 start of the day; track starts are spread over the following ten hours.

    Returns
    -------
    list of FleetTrackSim
        ``polyline``: the OSM centre line the car drove during the track (truth).
    """
    rng = np.random.default_rng(seed)
    start = dt.datetime.fromisoformat(t0)
    out = []
    drive = None
    cursor = 0.0
    while len(out) < n_tracks:
        dur = rng.uniform(*duration)
        if drive is None or cursor + dur + 60.0 > drive[0].size - 1:
            _, route = car_route(graph, duration=drive_s, dt=1.0,
                                 seed=int(rng.integers(2**31)))
            seg_of = _vertex_of_samples(route.xy, route.polyline)
            drive = (route.s, route.xy, route.polyline, seg_of)
            cursor = 0.0
        _, dxy, poly, seg_of = drive
        a = int(cursor)
        b = int(cursor + dur)
        cursor += dur + rng.uniform(10.0, 120.0)
        per = rng.uniform(*period)
        sig = rng.uniform(*sigma)
        hold = rng.uniform(*park)
        # irregular intervals around the nominal period, stamped to the second; stationary
        # at the first position for ``hold`` seconds, then driving
        steps = per * rng.uniform(0.6, 1.4, int((dur + hold) / per * 1.6) + 2)
        ts = np.round(np.concatenate([[0.0], np.cumsum(steps)]))
        ts = ts[ts <= hold + (b - a)]
        idx = a + np.clip(ts - round(hold), 0, b - a).astype(int)
        xy = dxy[idx] + rng.normal(0.0, sig, (len(idx), 2))
        dup = rng.random(len(idx)) < dup_prob
        if dup.any():                     # a second position in the same second
            ts = np.concatenate([ts, ts[dup]])
            xy = np.concatenate([xy, dxy[idx[dup]] + rng.normal(0.0, sig, (int(dup.sum()), 2))])
            idx = np.concatenate([idx, idx[dup]])
            o = np.argsort(ts, kind="stable")
            ts, xy, idx = ts[o], xy[o], idx[o]
        t_start = start + dt.timedelta(seconds=float(rng.uniform(0, 10 * 3600)))
        iso = [(t_start + dt.timedelta(seconds=float(s))).isoformat(timespec="seconds")
               for s in ts]
        truth = poly[max(seg_of[a] - 1, 0):seg_of[b] + 3]
        out.append(FleetTrackSim(f"car{len(out):04d}", ts, xy, truth, sig, per, iso, dxy[idx]))
    return out


def fleet_rows(graph, tracks, *, rng=None, shuffle_prob=0.0):
    """The rows of a fleet CSV: ``(track_id, t_iso, lat_deg, lon_deg)`` lists, tracks one after
    another; with ``shuffle_prob`` some neighbouring rows of a track are swapped."""
    rng = rng or np.random.default_rng(0)
    ids, ts, lats, lons = [], [], [], []
    for tr in tracks:
        lat, lon = graph.to_geodetic(tr.xy[:, 0], tr.xy[:, 1])
        order = np.arange(len(tr.t))
        if shuffle_prob:
            for i in np.flatnonzero(rng.random(len(order) - 1) < shuffle_prob):
                order[i], order[i + 1] = order[i + 1], order[i]
        ids += [tr.track_id] * len(order)
        ts += [tr.iso[i] for i in order]
        lats += list(np.degrees(lat[order]))
        lons += list(np.degrees(lon[order]))
    return ids, ts, lats, lons
