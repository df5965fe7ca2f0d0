"""Map matching of many tracks: in this process or over a Dask cluster (issue 14).

:func:`match_tracks` matches each track on its own with one :class:`~selfnav.roads.hmm.HmmMatcher`
per process: the map is read once per process (per Dask worker), and the matcher's route store
(:class:`~selfnav.roads.routes.RouteCache`) is shared by every track that process matches, so a
fleet on one map pays for a route distance once. Tracks go out in chunks of about
``chunk_fixes`` fixes (one Dask task each), a few chunks per worker in flight at a time; results
come back **in track order** as soon as they can (a generator: write them as they come, memory
does not grow with the number of tracks). A track that fails (too few fixes, outside the map, an
error in matching) comes back with ``error`` set; the others are not affected.

Few fixes in all (below ``auto_min_fixes``), ``workers=0``, or no Dask installed with the
default: everything runs in this process, without the cost of starting a cluster. The cluster
helpers are :mod:`selfnav.cluster`'s (the same as ``selfnav montecarlo``).
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from selfnav.errors import SelfnavError
from selfnav.roads.graph import RoadGraph, read_match_roads
from selfnav.roads.hmm import MATCHED_GATE, MATCHED_P, HmmMatcher, MatchResult
from selfnav.roads.routes import driven_route
from selfnav.types import GnssData

#: a track none of whose fixes lies within this distance of the map's bounding box is refused
MAP_MARGIN_M = 1000.0


@dataclass(frozen=True)
class MatchParams:
    """The matcher's settings (see :class:`~selfnav.roads.hmm.HmmMatcher`). ``sigma_m=None``:
    each track's σ is estimated from its own fixes (:meth:`HmmMatcher.estimate_sigmas`) unless
    they carry ``sigma_m``. ``error_corr=None``: the shared share of the GNSS error is
    estimated once from all the tracks of a call (:meth:`HmmMatcher.estimate_error_corr`)."""

    sigma_m: float | None = None
    radius_m: float | None = None
    beta_m: float | None = None
    error_corr: float | None = None

    def matcher(self, graph: RoadGraph) -> HmmMatcher:
        return HmmMatcher(graph, sigma=self.sigma_m or 10.0, radius=self.radius_m,
                          beta=self.beta_m, error_corr=self.error_corr or 0.0)


@dataclass
class TrackMatch:
    """The match of one track.

    Attributes
    ----------
    track_id : str
    result : MatchResult or None
        One road position per fix (None if the track failed).
    error : str or None
        Why the track could not be matched.
    route : list of (lat (M,), lon (M,) rad, way ids (S,)) or None
        The driven route (with ``route=True``), one piece per unbroken run of the chain.
    seconds : float
        Matching time of this track (route included).
    outside : int
        Fixes more than :data:`MAP_MARGIN_M` outside the map.
    route_length_m : float
        Length of the driven route, m (with ``route=True``).
    """

    track_id: str
    result: MatchResult | None = None
    error: str | None = None
    route: list | None = None
    seconds: float = 0.0
    outside: int = 0
    route_length_m: float = 0.0


# one matcher per process and (map, settings): the map is read once per Dask worker
_MATCHERS: dict = {}


def process_matcher(roads, params: MatchParams) -> HmmMatcher:
    """This process's matcher for a map (path or :class:`RoadGraph`) and settings."""
    graph = roads if isinstance(roads, RoadGraph) else None
    key = (str(Path(roads).resolve()) if graph is None else id(graph), params)
    m = _MATCHERS.get(key)
    if m is None or (graph is not None and m.graph is not graph):
        graph = roads if isinstance(roads, RoadGraph) else read_match_roads(roads)
        if len(_MATCHERS) > 4:
            _MATCHERS.clear()
        m = _MATCHERS[key] = params.matcher(graph)
    return m


def inside_map(g: RoadGraph, lat, lon, margin=MAP_MARGIN_M):
    """Which fixes (rad) lie within ``margin`` of the map's bounding box."""
    x, y = g.to_local(lat, lon)
    xmin, ymin, xmax, ymax = g.bounds()
    return (x > xmin - margin) & (x < xmax + margin) & (y > ymin - margin) & (y < ymax + margin)


def swapped_columns(g: RoadGraph, gnss_list, sample=20_000) -> bool:
    """True when latitude and longitude look swapped: no fix lies on the map as given, and most
    do with the two exchanged."""
    lat = np.concatenate([gd.lat for gd in gnss_list if gd is not None] or [np.zeros(0)])
    lon = np.concatenate([gd.lon for gd in gnss_list if gd is not None] or [np.zeros(0)])
    if not len(lat):
        return False
    k = np.linspace(0, len(lat) - 1, min(sample, len(lat))).astype(int)
    lat, lon = lat[k], lon[k]
    if inside_map(g, lat, lon).any() or np.any(np.abs(lon) > np.pi / 2):
        return False
    return bool(np.mean(inside_map(g, lon, lat)) > 0.5)


def _failed(track_id, gnss, g, xy=None):
    """Why a track cannot be matched, or None; and its local positions (``xy``: already
    converted)."""
    if gnss is None or len(gnss.t) < 2:
        return f"track '{track_id}': fewer than two fixes", None, 0
    x, y = g.to_local(gnss.lat, gnss.lon) if xy is None else xy.T
    xmin, ymin, xmax, ymax = g.bounds()
    m = MAP_MARGIN_M
    inside = (x > xmin - m) & (x < xmax + m) & (y > ymin - m) & (y < ymax + m)
    if not inside.any():
        return (f"track '{track_id}': none of the {len(x)} fixes lies within "
                f"{MAP_MARGIN_M / 1e3:.0f} km of the map {g.name}: another area, or a "
                "datum/degree mix-up?"), None, len(x)
    return None, np.column_stack([x, y]), int((~inside).sum())


def _prepare(matcher: HmmMatcher, items, auto_sigma: bool):
    """The tracks of ``items`` that can be matched: ``(out, ok, xys, sig, track_sigma,
    outside)`` -- ``out`` with the failed tracks filled in, the indices of the others, their
    local positions, their per-fix σ (or None) and σ."""
    g = matcher.graph
    out = [None] * len(items)
    ok, xys, outside = [], [], {}
    # every track's fixes to local metres in one projection call (one per track costs more)
    use = [gd is not None and len(gd.t) >= 2 for _, gd in items]
    if any(use):
        x, y = g.to_local(np.concatenate([gd.lat for (_, gd), u in zip(items, use) if u]),
                          np.concatenate([gd.lon for (_, gd), u in zip(items, use) if u]))
        sizes = [len(gd.t) for (_, gd), u in zip(items, use) if u]
        parts = iter(np.split(np.column_stack([x, y]), np.cumsum(sizes)[:-1]))
    for k, (tid, gd) in enumerate(items):
        err, xy, n_out = _failed(tid, gd, g, next(parts) if use[k] else None)
        if err:
            out[k] = TrackMatch(tid, error=err, outside=n_out)
        else:
            ok.append(k)
            xys.append(xy)
            outside[k] = n_out
    sig = [items[k][1].sigma_m for k in ok]
    track_sigma = None
    if ok and auto_sigma:
        est = matcher.estimate_sigmas([xy for xy, s in zip(xys, sig) if s is None]) \
            if any(s is None for s in sig) else []
        it = iter(est)
        track_sigma = [next(it) if s is None else float(np.nanmedian(s)) if
                       np.isfinite(s).any() else matcher.sigma for s in sig]
    return out, ok, xys, sig, track_sigma, outside


def fleet_error_corr(matcher: HmmMatcher, items, *, auto_sigma: bool = True) -> float:
    """The shared share of the GNSS error of the tracks ``items`` (``(track_id, GnssData)``),
    estimated once over all of them (:meth:`HmmMatcher.estimate_error_corr`; each track's σ
    estimated from its fixes with ``auto_sigma``, else the matcher's)."""
    use = [gd for _, gd in items if gd is not None and len(gd.t) >= 2]
    if not use:
        return 0.0
    x, y = matcher.graph.to_local(np.concatenate([gd.lat for gd in use]),
                                  np.concatenate([gd.lon for gd in use]))
    xy = np.split(np.column_stack([x, y]), np.cumsum([len(gd.t) for gd in use])[:-1])
    return matcher.estimate_error_corr([(gd.t, p, gd.sigma_m) for gd, p in zip(use, xy)],
                                       None if auto_sigma else [matcher.sigma] * len(use))


def match_batch(matcher: HmmMatcher, items, *, auto_sigma: bool = True,
                route: bool = False, auto_corr: bool = False) -> list:
    """Match a list of ``(track_id, GnssData)`` in one pass of the matcher
    (:meth:`HmmMatcher.match_many`); a failing track does not affect the others.

    ``auto_sigma``: each track's σ (where its fixes give none) is estimated from its fixes.
    ``auto_corr``: the shared share of the GNSS error is estimated from these tracks (else
    the matcher's)."""
    t0 = time.perf_counter()
    g = matcher.graph
    out, ok, xys, sig, track_sigma, outside = _prepare(matcher, items, auto_sigma)
    if ok:
        if auto_corr:
            matcher = matcher.with_error_corr(matcher.estimate_error_corr(
                [(items[k][1].t, xy, s) for k, xy, s in zip(ok, xys, sig)], track_sigma))
        try:
            results = matcher.match_many([(items[k][1].t, xy, s) for k, xy, s in
                                          zip(ok, xys, sig)], track_sigma)
        except (SelfnavError, ValueError, FloatingPointError, IndexError) as e:
            if len(ok) == 1:
                tid = items[ok[0]][0]
                out[ok[0]] = TrackMatch(tid, error=f"track '{tid}': {type(e).__name__}: {e}")
                return out
            # one bad track should not take the others with it: one by one
            for k in ok:
                out[k] = match_batch(matcher, [items[k]], auto_sigma=auto_sigma,
                                     route=route)[0]
            return out
        per_fix = (time.perf_counter() - t0) / max(sum(len(x) for x in xys), 1)
        for k, xy, res in zip(ok, xys, results):
            tid = items[k][0]
            pieces, length = None, 0.0
            if route:
                t1 = time.perf_counter()
                pieces = []
                bt = matcher.with_sigma(res.sigma).backtrack
                for pxy, segs in driven_route(g, res.seg, res.along, res.xy, res.restart,
                                              backtrack=bt):
                    lat, lon = g.to_geodetic(pxy[:, 0], pxy[:, 1])
                    pieces.append((lat, lon, g.seg_way[segs]))
                    length += float(np.hypot(*np.diff(pxy, axis=0).T).sum())
                res.seconds += time.perf_counter() - t1
            out[k] = TrackMatch(tid, res, None, pieces, per_fix * len(xy), outside[k], length)
    return out


def match_track(matcher: HmmMatcher, track_id: str, gnss: GnssData, *, auto_sigma=True,
                route: bool = False, auto_corr: bool = True) -> TrackMatch:
    """Match one track; failures come back as ``error`` (one line naming the track).
    ``auto_corr``: the shared share of the GNSS error is estimated from the track itself."""
    return match_batch(matcher, [(track_id, gnss)], auto_sigma=auto_sigma, route=route,
                       auto_corr=auto_corr)[0]


def match_chunk(roads, params: MatchParams, items, route: bool = False) -> list:
    """Match a list of ``(track_id, GnssData)`` with this process's matcher (one Dask task)."""
    m = process_matcher(roads, params)
    return match_batch(m, items, auto_sigma=params.sigma_m is None, route=route,
                       auto_corr=params.error_corr is None)


def chunk_tracks(items, chunk_fixes: int):
    """Consecutive tracks grouped into chunks of about ``chunk_fixes`` fixes."""
    chunk, size = [], 0
    for tid, gd in items:
        chunk.append((tid, gd))
        size += 0 if gd is None else len(gd.t)
        if size >= chunk_fixes:
            yield chunk
            chunk, size = [], 0
    if chunk:
        yield chunk


@dataclass
class FleetRun:
    """How :func:`match_tracks` ran (filled in while it runs)."""

    mode: str = "in-process"
    workers: int = 0
    startup_s: float = 0.0
    match_s: float = 0.0
    extra: dict = field(default_factory=dict)


def match_tracks(items: Iterable, roads, params: MatchParams = MatchParams(), *,
                 workers: int | None = None, scheduler: str | None = None, client=None,
                 route: bool = False, progress: Callable[[int], None] | None = None,
                 chunk_fixes: int = 20_000, auto_min_fixes: int = 200_000,
                 run: FleetRun | None = None, graph: RoadGraph | None = None
                 ) -> Iterator[TrackMatch]:
    """Match tracks one by one, in this process or on Dask; yield results in track order.

    Parameters
    ----------
    items : iterable of (track_id, GnssData or None)
    roads : path or RoadGraph
        The map (a path lets each Dask worker read it itself).
    params : MatchParams
    workers : int, optional
        Local Dask workers (processes); 0 runs in this process. Default: in this process for
        fewer than ``auto_min_fixes`` fixes in all, else one worker per core.
    scheduler : str, optional
        Address of an existing Dask scheduler (then ``workers`` is ignored).
    client : dask.distributed.Client, optional
        Use this client (the caller owns it).
    route : bool
        Also compute each track's driven route.
    progress : callable, optional
        Called with the number of tracks just finished.
    chunk_fixes : int
        Fixes per Dask task (about).
    run : FleetRun, optional
        Filled with the mode, workers and times.
    graph : RoadGraph, optional
        ``roads`` already read (used when matching in this process).

    Yields
    ------
    TrackMatch
    """
    items = list(items)
    run = run if run is not None else FleetRun()
    if workers is not None and workers < 0:
        raise SelfnavError(f"--workers must be 0 (in this process) or more (got {workers})")
    total = sum(0 if gd is None else len(gd.t) for _, gd in items)
    if params.error_corr is None and items:
        # the shared share of the GNSS error, once for the whole fleet: every chunk, in this
        # process or on Dask, matches with the same model
        m = process_matcher(graph if graph is not None else roads, params)
        params = replace(params, error_corr=fleet_error_corr(m, items,
                                                              auto_sigma=params.sigma_m is None))
        run.extra["error_corr"] = params.error_corr
    if client is None and scheduler is None and (
            workers == 0 or (workers is None and (total < auto_min_fixes or len(items) < 2))):
        yield from _in_process(items, graph if graph is not None else roads, params, route,
                               progress, run)
        return
    if isinstance(roads, RoadGraph):
        raise SelfnavError("matching on Dask needs the map as a file path (each worker reads "
                           "it), not a RoadGraph")
    yield from _on_dask(items, str(Path(roads).resolve()), params, route, progress, run,
                        workers if workers is not None else (os.cpu_count() or 1), scheduler,
                        client, chunk_fixes)


def _in_process(items, roads, params, route, progress, run, batch_fixes=4096):
    t0 = time.perf_counter()
    m = process_matcher(roads, params)
    run.mode, run.workers = "in-process", 0
    run.startup_s = time.perf_counter() - t0
    t1 = time.perf_counter()
    for chunk in chunk_tracks(items, batch_fixes):
        for r in match_batch(m, chunk, auto_sigma=params.sigma_m is None, route=route,
                             auto_corr=params.error_corr is None):
            if progress:
                progress(1)
            yield r
    run.match_s = time.perf_counter() - t1


def _on_dask(items, roads, params, route, progress, run, workers, scheduler, client,
             chunk_fixes):
    from selfnav.cluster import make_client

    t0 = time.perf_counter()
    own_client = own_cluster = None
    if client is None:
        client, own_cluster = make_client(workers, scheduler)
        own_client = client
    try:
        nw = len(client.scheduler_info().get("workers", {})) or max(workers, 1)
        run.mode = scheduler or ("local" if own_cluster is not None else "client")
        run.workers = nw
        run.startup_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        # chunks small enough that every worker gets several (load balance)
        size = max(1, min(chunk_fixes, sum(0 if g is None else len(g.t) for _, g in items)
                          // (4 * nw) + 1))
        chunks = list(chunk_tracks(items, size))
        in_flight = {}
        done: dict = {}
        nxt = 0
        limit = 4 * nw
        from dask.distributed import wait

        submitted = 0
        while nxt < len(chunks):
            while submitted < len(chunks) and len(in_flight) < limit:
                fut = client.submit(match_chunk, roads, params, chunks[submitted], route,
                                    pure=False)
                in_flight[fut] = submitted
                submitted += 1
            finished = wait(list(in_flight), return_when="FIRST_COMPLETED").done
            for fut in finished:
                k = in_flight.pop(fut)
                try:
                    done[k] = fut.result()
                except Exception as e:          # a lost worker, a pickling error: the chunk's
                    msg = str(e).splitlines()[0] if str(e) else type(e).__name__
                    done[k] = [TrackMatch(tid, error=f"track '{tid}': {type(e).__name__}: "
                                          f"{msg}") for tid, _ in chunks[k]]
                if progress:
                    progress(len(done[k]))
            while nxt in done:
                chunks[nxt] = None
                yield from done.pop(nxt)
                nxt += 1
        run.match_s = time.perf_counter() - t1
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()


def match_files(gnss, map_path, out, *, route_out=None, sigma_m: float | None = None,
                radius_m: float | None = None, beta_m: float | None = None,
                gnss_datum: str | None = None, out_datum: str | None = None,
                workers: int | None = None, scheduler: str | None = None,
                progress=None) -> dict:
    """``selfnav match``: read GNSS file(s) (one track or a fleet), match, write; returns the
    summary that ``--json`` prints (re-exported by :mod:`selfnav.api`; it lives here so that the
    command does not import the inertial stack).

    The output keeps each input row (in time order within its track, repeated stamps sharing
    their merged fix), the input's ``track_id`` and time text; columns ``t, lat_deg, lon_deg,
    h_m, cross_m, way_id, matched, match_p, piece``. ``route_out``: the driven routes as
    GeoJSON. A track that cannot be matched gets one warning line naming it and its file line
    and is left out; if no track can be matched the call fails and writes nothing.

    ``progress(done, total)`` is called as tracks finish.
    """
    import contextlib
    import warnings

    from selfnav.datum import convert, datum_key
    from selfnav.errors import SelfnavWarning
    from selfnav.io.fleet import FleetWriter, RouteWriter, fleet_files, read_fleet

    t_start = time.perf_counter()
    if sigma_m is not None and not sigma_m > 0:
        raise SelfnavError(f"--sigma-m must be positive, got {sigma_m}")
    paths = list(gnss) if isinstance(gnss, (list, tuple)) else [gnss]
    files = fleet_files(paths)
    out_key = datum_key(out_datum) if out_datum else "wgs84"
    fleet = read_fleet(files, datum=datum_key(gnss_datum) if gnss_datum else "wgs84")
    graph = read_match_roads(map_path)
    if swapped_columns(graph, [tr.gnss for tr in fleet.tracks]):
        warnings.warn(f"{names_of(files)}: latitude and longitude look swapped (no fix lies on "
                      "the map as given, most do exchanged): read exchanged", SelfnavWarning,
                      stacklevel=2)
        for tr in fleet.tracks:
            if tr.gnss is not None:
                tr.gnss.lat, tr.gnss.lon = tr.gnss.lon, tr.gnss.lat
    failures = [(tr.track_id, tr.error) for tr in fleet.tracks if tr.error]
    todo = [tr for tr in fleet.tracks if tr.error is None]
    run = FleetRun()
    done = [0]

    def tick(k):
        done[0] += k
        if progress:
            progress(done[0], len(todo))

    params = MatchParams(sigma_m, radius_m, beta_m)
    it = match_tracks([(tr.track_id, tr.gnss) for tr in todo], map_path, params, workers=workers,
                      scheduler=scheduler, route=route_out is not None, progress=tick, run=run,
                      graph=graph)
    datum_name = "WGS-84" if out_key == "wgs84" else out_datum
    names = names_of(files)
    comments = [f"selfnav match: GNSS {names} matched to roads of {Path(map_path).name} (HMM, "
                f"Newson & Krumm); datum {datum_name}",
                "cross_m: distance from the fix to its matched road position, m; way_id: "
                "OpenStreetMap way; matched: 1 where the match is plausible (match_p >= "
                f"{MATCHED_P:g}, the fix within {MATCHED_GATE:g} sigma of the road, not a lone "
                "fix between breaks); match_p: posterior probability of the matched road; "
                "piece: piece of the track between breaks of the chain (0, 1, ...)",
                "map data (c) OpenStreetMap contributors, ODbL",
                f"map: {graph.n_nodes} nodes, {graph.n_segments} directed segments (every "
                f"drivable way), {graph.snapped} dead ends of unjoined ways snapped within "
                f"{graph.snap_m:g} m"]
    n_fix = n_in = n_restart = matched_tracks = n_out = 0
    sigmas, quality = [], []
    sum_moved, max_moved, track_s = 0.0, 0.0, 0.0
    with contextlib.ExitStack() as stack:
        w = stack.enter_context(FleetWriter(out, track_id=fleet.has_track_id or len(files) > 1,
                                            comments=comments))
        rw = stack.enter_context(RouteWriter(
            route_out, comment="driven routes matched by selfnav; map data (c) OpenStreetMap "
            "contributors, ODbL")) if route_out is not None else None
        for tr, tm in zip(todo, it):
            if tm.error:
                failures.append((tr.track_id, f"{tr.source}, line {tr.first_line}: {tm.error}"))
                continue
            res = tm.result
            matched_tracks += 1
            n_fix += len(res.t)
            n_in += int(res.matched.sum())
            quality.append({"track_id": tr.track_id, **res.quality()})
            n_restart += int(res.restart.sum()) - 1
            sum_moved += float(res.moved.sum())
            max_moved = max(max_moved, float(res.moved.max()))
            n_out += int(tm.outside)
            track_s += tm.seconds
            sigmas.append(res.sigma)
            f = tr.row_fix
            lat, lon, h = res.lat[f], res.lon[f], tr.h_m
            if out_key != "wgs84":
                lat, lon, h = convert(lat, lon, np.nan_to_num(h), "wgs84", out_key)
            w.write(tr.track_id, tr.t_text, np.degrees(lat), np.degrees(lon), h, res.moved[f],
                    res.way[f], res.matched[f], res.match_p[f], res.piece[f])
            if rw is not None:
                rw.write(tr.track_id, tm.route or [],
                         {"fixes": len(res.t), "length_m": round(tm.route_length_m, 1),
                          "matched_share": round(float(res.matched.mean()), 4),
                          "breaks": res.breaks,
                          "median_cross_m": round(float(np.median(res.moved)), 2)})
        if not matched_tracks:
            first = failures[0][1] if failures else "no track in the input"
            if len(fleet.tracks) == 1:
                raise SelfnavError(first)
            raise SelfnavError(f"no track could be matched ({len(failures)} failed; the first: "
                               f"{first})")
    for k, (_, msg) in enumerate(failures):
        if k == 20:
            warnings.warn(f"{len(failures) - 20} more tracks left out", SelfnavWarning,
                          stacklevel=2)
            break
        warnings.warn(f"{msg}: track left out", SelfnavWarning, stacklevel=2)
    elapsed = time.perf_counter() - t_start
    probe = HmmMatcher(graph, sigma=sigma_m or float(np.median(sigmas)), radius=radius_m,
                       beta=beta_m)
    return {"gnss": [str(f) for f in files], "map": str(map_path), "out": str(out),
            "route_out": None if route_out is None else str(route_out),
            "tracks": len(fleet.tracks), "tracks_matched": matched_tracks,
            "tracks_failed": len(failures), "rows": w.rows, "fixes": n_fix,
            "matched_share": n_in / n_fix if n_fix else 0.0,
            "mean_correction_m": sum_moved / n_fix if n_fix else 0.0,
            "max_correction_m": max_moved, "restarts": n_restart, "breaks": n_restart,
            "outside_map": n_out, "map_snapped": graph.snapped, "snap_m": graph.snap_m,
            "tracks_below_90pct_matched": sum(q["matched_share"] < 0.9 for q in quality),
            "track_quality": quality,
            "time_form": fleet.time_form, "seconds": elapsed,
            "fixes_per_second": n_fix / elapsed if elapsed > 0 else None,
            "match_seconds": track_s,
            "matcher_fixes_per_second": n_fix / track_s if track_s > 0 else None,
            "mode": run.mode, "workers": run.workers, "startup_seconds": run.startup_s,
            "map_nodes": graph.n_nodes, "map_segments": graph.n_segments,
            "sigma_m": probe.sigma, "sigma_estimated": sigma_m is None,
            "error_corr": run.extra.get("error_corr", 0.0),
            "beta_m": probe.beta, "radius_m": probe.radius,
            "failed": [{"track_id": t, "error": e} for t, e in failures[:100]]}


def names_of(files) -> str:
    """The first file names of a list, for messages."""
    return ", ".join(Path(f).name for f in files[:3]) + (" ..." if len(files) > 3 else "")
