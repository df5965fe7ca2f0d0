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


def unjoin_map(src, dst, *, share=0.5, offset_m=(0.5, 3.0), seed=0):
    """A copy of an OpenStreetMap file whose ways do not always share nodes where they touch, as
    maps often are: at a share ``share`` of the nodes where one drivable way *ends* on another
    way, the ending way gets a node of its own, moved ``offset_m`` m (uniform, random direction)
    from the shared one. Ways that cross are left joined. Writes ``dst`` (``.osm`` XML: highway
    ways and their nodes only) and returns the number of ends unjoined.

    This is simulated map damage for tests and benchmarks (the real map is unchanged);
    OpenStreetMap data © OpenStreetMap contributors, ODbL.
    """
    import osmium

    from selfnav.roads.graph import DRIVABLE

    rng = np.random.default_rng(seed)
    loc, ways = {}, []
    fp = osmium.FileProcessor(str(src)).with_locations().with_filter(
        osmium.filter.KeyFilter("highway"))
    for o in fp:
        if not o.is_way():
            continue
        refs = [(nd.ref, nd.location.lon, nd.location.lat) for nd in o.nodes
                if nd.location.valid()]
        if len(refs) < 2:
            continue
        for r, lo, la in refs:
            loc[r] = (lo, la)
        ways.append((o.id, [r for r, _, _ in refs], dict(o.tags)))
    use = {}
    for wid, refs, tags in ways:
        if tags.get("highway") in DRIVABLE:
            for r in set(refs):
                use[r] = use.get(r, 0) + 1
    next_id = max(loc) + 1
    n_unjoined = 0
    out_ways = []
    for wid, refs, tags in ways:
        refs = list(refs)
        if tags.get("highway") in DRIVABLE and refs[0] != refs[-1]:
            for k in (0, len(refs) - 1):
                r = refs[k]
                if use.get(r, 0) >= 2 and rng.random() < share:
                    lo, la = loc[r]
                    d = rng.uniform(*offset_m)
                    a = rng.uniform(0, 2 * np.pi)
                    dlat = d * np.cos(a) / 111_320.0
                    dlon = d * np.sin(a) / (111_320.0 * np.cos(np.radians(la)))
                    loc[next_id] = (lo + dlon, la + dlat)
                    use[r] -= 1
                    refs[k] = next_id
                    next_id += 1
                    n_unjoined += 1
        out_ways.append((wid, refs, tags))
    import os

    if os.path.exists(dst):
        os.remove(dst)
    w = osmium.SimpleWriter(str(dst))
    try:
        needed = sorted({r for _, refs, _ in out_ways for r in refs})
        for r in needed:
            w.add_node(osmium.osm.mutable.Node(id=r, location=osmium.osm.Location(*loc[r]),
                                               version=1))
        for wid, refs, tags in out_ways:
            w.add_way(osmium.osm.mutable.Way(id=wid, nodes=refs, tags=tags, version=1))
    finally:
        w.close()
    return n_unjoined


def gnss_errors(t, sigma, rng, *, white_share=0.5, tau=60.0, outlier_p=0.0,
                outlier_m=(30.0, 150.0)):
    """Horizontal GNSS errors at times ``t`` (s), m, (N, 2): per axis σ ``sigma``, split into white
    noise and a Gauss–Markov part (correlation time ``tau``) by variance, plus multipath
    outliers (probability ``outlier_p`` per fix, ``outlier_m`` m in a random direction)."""
    n = len(t)
    e = rng.normal(0.0, sigma * np.sqrt(white_share), (n, 2))
    s_c = sigma * np.sqrt(1.0 - white_share)
    gm = np.zeros((n, 2))
    if n:
        gm[0] = rng.normal(0.0, s_c, 2)
    for k in range(1, n):
        a = np.exp(-max(t[k] - t[k - 1], 0.0) / tau)
        gm[k] = a * gm[k - 1] + np.sqrt(1 - a * a) * s_c * rng.normal(size=2)
    e += gm
    out = rng.random(n) < outlier_p
    if out.any():
        d = rng.uniform(*outlier_m, out.sum())
        a = rng.uniform(0, 2 * np.pi, out.sum())
        e[out] += np.column_stack([d * np.sin(a), d * np.cos(a)])
    return e, out


def simulate_real_fleet(graph, n_tracks, *, seed=0, fixes=(2, 20), period=(5.0, 15.0),
                        sigma=(1.0, 4.0), outlier_p=0.02, park_p=0.3, park=(20.0, 90.0),
                        dup_prob=0.05, full_share=0.3, t0="2019-03-11T06:00:00+00:00"):
    """Floating-car tracks with the properties of a real fleet (simulated data): short tracks
    (``fixes`` per track, uniform), ``period`` s sampling with irregular intervals stamped to the
    second, repeated stamps (``dup_prob``), stationary runs (with probability ``park_p`` the car
    stands ``park`` s, at the start or the end of the track), GNSS errors of
    :func:`gnss_errors` (σ per track in ``sigma``, half white, half correlated over 60 s,
    multipath outliers ``outlier_p``).

    ``graph`` is the *true* road graph, every drivable way kept (the truth the tracks are
    scored against): a share ``full_share`` of the tracks drive to or from a part of it
    outside the strongly connected core (a one-way exit the extract cuts, a parking aisle), the
    others drive in the core.

    Returns
    -------
    list of FleetTrackSim (``polyline``: the centre line driven, truth)
    """
    from scipy.sparse.csgraph import connected_components, dijkstra

    rng = np.random.default_rng(seed)
    start = dt.datetime.fromisoformat(t0)
    _, lab = connected_components(graph.csr, directed=True, connection="strong")
    core = lab == np.argmax(np.bincount(lab))
    core_nodes = np.flatnonzero(core)
    outside = np.flatnonzero(~core)
    out = []
    while len(out) < n_tracks:
        nfix = int(rng.integers(fixes[0], fixes[1] + 1))
        per = rng.uniform(*period)
        sig = rng.uniform(*sigma)
        hold = rng.uniform(*park) if rng.random() < park_p else 0.0
        hold_at_end = rng.random() < 0.5
        drive_s = nfix * per + 30.0
        # a route: core to core, or to / from a node outside the core
        for _ in range(50):
            a = int(rng.choice(core_nodes))
            if len(outside) and rng.random() < full_share:
                b = int(rng.choice(outside))
                if rng.random() < 0.5:
                    a, b = b, a
            else:
                b = int(rng.choice(core_nodes))
            _, pred = dijkstra(graph.csr, indices=a, return_predecessors=True)
            if a == b or pred[b] < 0:
                continue
            path = [b]
            while path[-1] != a:
                path.append(int(pred[path[-1]]))
            path = path[::-1]
            length = float(np.hypot(*np.diff(graph.xy[path], axis=0).T).sum())
            if length > 60.0:
                break
        _, route = car_route(graph, route=path, duration=max(drive_s * 4, 600.0), dt=1.0,
                             seed=int(rng.integers(2**31)), stops=False)
        n_s = len(route.xy)
        # the track: nfix fixes at irregular intervals, over part of the drive
        steps = per * rng.uniform(0.6, 1.4, max(nfix - 1, 0))
        ts = np.round(np.concatenate([[0.0], np.cumsum(steps)]))
        span = ts[-1] - min(hold, ts[-1])
        drive_len = n_s - 1
        a0 = int(rng.uniform(0, max(drive_len - span, 0) + 1)) if not hold_at_end else \
            max(int(drive_len - span), 0)
        if hold and not hold_at_end:      # standing at the start, then driving
            idx = a0 + np.clip(ts - hold, 0, None)
        elif hold:                        # driving, then standing at the end
            idx = a0 + np.minimum(ts, span)
        else:
            idx = a0 + ts
        idx = np.clip(idx, 0, drive_len).astype(int)
        e, _ = gnss_errors(ts, sig, rng, outlier_p=outlier_p)
        xy = route.xy[idx] + e
        dup = rng.random(len(idx)) < dup_prob
        if dup.any():                     # a second position in the same second
            e2, _ = gnss_errors(ts[dup], sig, rng, outlier_p=outlier_p)
            ts = np.concatenate([ts, ts[dup]])
            xy = np.concatenate([xy, route.xy[idx[dup]] + e2])
            idx = np.concatenate([idx, idx[dup]])
            o = np.argsort(ts, kind="stable")
            ts, xy, idx = ts[o], xy[o], idx[o]
        t_start = start + dt.timedelta(seconds=float(rng.uniform(0, 10 * 3600)))
        iso = [(t_start + dt.timedelta(seconds=float(s))).isoformat(timespec="seconds")
               for s in ts]
        out.append(FleetTrackSim(f"car{len(out):04d}", ts, xy, route.polyline, sig, per, iso,
                                 route.xy[idx]))
    return out


def score_fleet(graph, tracks, results, *, tol=5.0):
    """Per track and per fix: is the matched position within ``tol`` m of the true route?

    ``results``: for each track a :class:`~selfnav.roads.hmm.MatchResult`-like object with
    ``lat, lon`` (rad) per distinct time stamp, or an (N, 2) array of local positions of
    ``graph`` one per row of the track. Returns ``(per_track_share (T,), ok (all rows,) bool,
    track_index (all rows,))``."""
    from selfnav.roads.graph import project_to_polyline

    shares, oks, which = [], [], []
    for k, (tr, res) in enumerate(zip(tracks, results)):
        if isinstance(res, np.ndarray):
            xy = res
        else:
            _, inv = np.unique(tr.t, return_inverse=True)
            x, y = graph.to_local(res.lat, res.lon)
            xy = np.column_stack([x, y])[inv]
        _, c, _ = project_to_polyline(xy, tr.polyline)
        ok = np.abs(c) < tol
        shares.append(ok.mean())
        oks.append(ok)
        which.append(np.full(len(ok), k))
    return np.asarray(shares), np.concatenate(oks), np.concatenate(which)
