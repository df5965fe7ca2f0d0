"""Evaluation of a navigation solution against truth (DESIGN §6 ``selfnav evaluate``).

The truth is interpolated onto the solution's times (only the overlap counts, and never across
a hole in the truth longer than :data:`MAX_TRUTH_GAP` truth intervals: solution epochs inside
such a hole are left out, and ``solution_compared`` says which share of the solution was
compared). ``coverage`` is the share of the truth's time span (less its holes) that the
compared solution covers: a solution that starts late or has holes covers less, and under 99 %
a warning says so (:func:`truth_coverage`). Each solution
point's error is the ECEF difference rotated into the local ENU frame at the truth point, in
metres. Metrics:

* horizontal error ``sqrt(e_E² + e_N²)``: RMS, 95th percentile (linear interpolation between
  order statistics), maximum and mean;
* vertical error ``e_U``: RMS and maximum of its magnitude;
* along- and cross-track components relative to the **truth heading** (always): along is
  positive ahead of the truth, cross positive to the right of the direction of travel; the truth
  heading is the file's ``heading_deg`` when present, else the direction of its velocity
  (``ve, vn``), else of its position differences; epochs where it is unknown (standing still with
  no attitude) are left out of these two;
* the same two relative to a **road polyline** when one is given (the direction of the nearest
  road segment to the truth point, oriented along the truth heading).

Everything is WGS-84; convert other datums first (:mod:`selfnav.datum`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from selfnav import attitude as att
from selfnav.earth import WGS84, enu_rotation, geodetic_to_ecef, geodetic_to_enu
from selfnav.errors import SelfnavError, warn
from selfnav.summary import coverage, default_max_gap, span_text
from selfnav.types import Trajectory

#: Speed below which the direction of motion is not trusted as a heading, m/s.
MIN_SPEED = 0.2

#: The truth is not interpolated across a step longer than this many (median) truth intervals.
MAX_TRUTH_GAP = 3.0

#: A road map whose roads all lie farther than this from the truth is refused, m.
MAP_MARGIN_M = 1000.0

#: A solution covering less of the truth's time span than this gets a warning.
COVERAGE_WARNING = 0.99


def truth_coverage(truth: Trajectory, t, holes=()) -> dict:
    """Share of the truth's time span (less its holes) that the compared solution epochs ``t``
    cover (:func:`selfnav.summary.coverage`; a step between epochs counts when it is at most
    three median solution steps, and at least 1.5 median truth intervals)."""
    d = np.diff(truth.t)
    floor = 1.5 * float(np.median(d)) if d.size else 0.0
    return coverage(t, truth.t[0], truth.t[-1], max_gap=default_max_gap(t, floor), holes=holes)


def truth_gap_mask(truth_t, t, max_intervals: float = MAX_TRUTH_GAP):
    """True for times ``t`` that fall strictly inside a hole of the truth (a step longer than
    ``max_intervals`` median truth intervals), where interpolation would invent the truth.

    Returns ``(mask, holes)`` with ``holes`` the ``(start, end)`` times of every such step.
    """
    truth_t = np.asarray(truth_t, dtype=float)
    t = np.asarray(t, dtype=float)
    d = np.diff(truth_t)
    if d.size == 0:
        return np.zeros(len(t), bool), []
    big = d > max_intervals * np.median(d)
    holes = [(float(truth_t[k]), float(truth_t[k + 1])) for k in np.flatnonzero(big)]
    k = np.clip(np.searchsorted(truth_t, t, side="right") - 1, 0, len(d) - 1)
    mask = big[k] & (t > truth_t[k]) & (t < truth_t[k + 1])
    return mask, holes


def _interp_angle(t_new, t, a):
    """Interpolate angles (rad) through their unit vectors; NaN stays NaN."""
    c = np.interp(t_new, t, np.cos(a))
    s = np.interp(t_new, t, np.sin(a))
    out = np.arctan2(s, c)
    bad = np.interp(t_new, t, np.isnan(a).astype(float)) > 0
    out[bad | (np.hypot(c, s) < 1e-6)] = np.nan
    return out


def _fill_nearest(x):
    """Fill NaN with the nearest valid value before or after (ffill, then bfill)."""
    x = np.array(x, dtype=float)
    ok = np.isfinite(x)
    if not ok.any():
        return x
    idx = np.where(ok, np.arange(len(x)), -1)
    idx = np.maximum.accumulate(idx)
    first = int(np.argmax(ok))
    idx[:first] = first
    return x[idx]


def truth_heading(truth: Trajectory):
    """Heading of the truth at its own samples, rad clockwise from North (NaN where unknown).

    Attitude heading when the file has it; else the velocity direction; else the direction of
    position differences. Samples slower than :data:`MIN_SPEED` take the nearest moving sample's
    direction (a stop keeps the heading it arrived with).
    """
    if np.all(np.isfinite(truth.C_nb)):
        return att.euler_from_dcm_nb(truth.C_nb)[2]
    if np.all(np.isfinite(truth.velocity_n[:, :2])):
        ve, vn = truth.velocity_n[:, 0], truth.velocity_n[:, 1]
    else:
        if len(truth) < 2:
            return np.full(len(truth), np.nan)
        x = geodetic_to_ecef(truth.lat, truth.lon, truth.h, WGS84)
        E = enu_rotation(truth.lat, truth.lon)
        d = np.gradient(x, truth.t, axis=0)
        v = np.einsum("nij,nj->ni", E, d)
        ve, vn = v[:, 0], v[:, 1]
    hdg = np.where(np.hypot(ve, vn) >= MIN_SPEED, np.arctan2(ve, vn), np.nan)
    return _fill_nearest(hdg)


@dataclass
class Evaluation:
    """Errors of a solution at its own times (only the overlap with the truth).

    Attributes
    ----------
    t : (N,) s
    error_enu : (N, 3) m, solution minus truth in the truth point's ENU frame
    along, cross : (N,) m, relative to the truth heading (NaN where unknown)
    road_along, road_cross : (N,) m or None, relative to the road
    truth_lat, truth_lon, truth_h, sol_lat, sol_lon, sol_h : (N,) rad, rad, m
    heading : (N,) rad, truth heading used
    metrics : dict
    warnings : list of str
    """

    t: np.ndarray
    error_enu: np.ndarray
    along: np.ndarray
    cross: np.ndarray
    truth_lat: np.ndarray
    truth_lon: np.ndarray
    truth_h: np.ndarray
    sol_lat: np.ndarray
    sol_lon: np.ndarray
    sol_h: np.ndarray
    heading: np.ndarray
    road_along: np.ndarray | None = None
    road_cross: np.ndarray | None = None
    metrics: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)

    @property
    def horizontal(self) -> np.ndarray:
        return np.hypot(self.error_enu[:, 0], self.error_enu[:, 1])


def _rms(x):
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def error_metrics(error_enu, along=None, cross=None, road_along=None, road_cross=None) -> dict:
    """The metric dictionary of ``selfnav evaluate`` from error components (m)."""
    e = np.asarray(error_enu, dtype=float)
    hor = np.hypot(e[:, 0], e[:, 1])
    m = {
        "horizontal_rms_m": _rms(hor),
        "horizontal_p95_m": float(np.percentile(hor, 95)),
        "horizontal_max_m": float(np.max(hor)),
        "horizontal_mean_m": float(np.mean(hor)),
        "vertical_rms_m": _rms(e[:, 2]),
        "vertical_max_m": float(np.max(np.abs(e[:, 2]))),
        "east_mean_m": float(np.mean(e[:, 0])),
        "north_mean_m": float(np.mean(e[:, 1])),
        "up_mean_m": float(np.mean(e[:, 2])),
    }
    for name, x in (("along_track", along), ("cross_track", cross),
                    ("road_along_track", road_along), ("road_cross_track", road_cross)):
        if x is None:
            continue
        ok = np.isfinite(x)
        m[f"{name}_rms_m"] = _rms(x)
        m[f"{name}_mean_m"] = float(np.mean(x[ok])) if ok.any() else float("nan")
        m[f"{name}_max_m"] = float(np.max(np.abs(x[ok]))) if ok.any() else float("nan")
    return m


def local_xy(lat, lon, lat0, lon0):
    """East/North metres of points in the tangent plane at (lat0, lon0) (for road geometry)."""
    return geodetic_to_enu(lat, lon, 0.0, lat0, lon0, 0.0)[..., :2]


def road_direction(points_xy, roads_xy, chunk: int = 2_000_000):
    """Unit direction (E, N) of the nearest road segment to each point, and the distance.

    Parameters
    ----------
    points_xy : (N, 2) m
    roads_xy : list of (M_i, 2) m polylines
    """
    a = np.concatenate([r[:-1] for r in roads_xy if len(r) >= 2])
    b = np.concatenate([r[1:] for r in roads_xy if len(r) >= 2])
    d = b - a
    L2 = np.einsum("ij,ij->i", d, d)
    keep = L2 > 0
    a, d, L2 = a[keep], d[keep], L2[keep]
    if len(a) == 0:
        raise SelfnavError("the road geometry has no segment of non-zero length")
    n = len(points_xy)
    best = np.empty(n, dtype=int)
    dist = np.empty(n)
    step = max(1, chunk // len(a))
    for i in range(0, n, step):
        p = points_xy[i:i + step, None, :]
        s = np.clip(np.einsum("nsk,sk->ns", p - a, d) / L2, 0.0, 1.0)
        q = a + s[..., None] * d
        r2 = np.sum((p - q) ** 2, axis=-1)
        j = np.argmin(r2, axis=1)
        best[i:i + step] = j
        dist[i:i + step] = np.sqrt(r2[np.arange(len(j)), j])
    u = d[best] / np.sqrt(L2[best])[:, None]
    return u, dist


def along_cross(error_en, direction_en):
    """Along (ahead +) and cross (right +) components of horizontal errors, m."""
    u = np.asarray(direction_en, dtype=float)
    e = np.asarray(error_en, dtype=float)
    along = e[:, 0] * u[:, 0] + e[:, 1] * u[:, 1]
    cross = e[:, 0] * u[:, 1] - e[:, 1] * u[:, 0]
    return along, cross


def evaluate(truth: Trajectory, solution: Trajectory, *, roads=None,
             truth_name: str = "truth", solution_name: str = "solution",
             roads_name: str = "the map") -> Evaluation:
    """Errors of ``solution`` against ``truth`` (module docstring).

    Parameters
    ----------
    truth, solution : Trajectory
        WGS-84 geodetic, as :func:`selfnav.sim.trajectory.read_truth` returns them.
    roads : list of (M_i, 2) arrays, optional
        Road polylines as ``(lat, lon)`` in rad (WGS-84); enables road-relative along/cross.
        A map none of whose roads comes within :data:`MAP_MARGIN_M` of the truth is refused
        (:class:`SelfnavError`, named ``roads_name``): another place's map.
    """
    if len(truth) < 2:
        raise SelfnavError(f"{truth_name}: at least two samples are needed to interpolate")
    t0, t1 = truth.t[0], truth.t[-1]
    inside = (solution.t >= t0) & (solution.t <= t1)
    if not inside.any():
        raise SelfnavError(
            f"time spans do not overlap: {truth_name} covers {t0:.3f}..{t1:.3f} s, "
            f"{solution_name} {solution.t[0]:.3f}..{solution.t[-1]:.3f} s (same time base?)")
    warnings = []
    n_out = int((~inside).sum())
    if n_out:
        warnings.append(f"{n_out} of {len(solution)} solution epochs lie outside the truth's "
                        "time span and are not evaluated")
    in_hole, holes = truth_gap_mask(truth.t, solution.t)
    n_hole = int((in_hole & inside).sum())
    if n_hole:
        longest = max(holes, key=lambda h: h[1] - h[0])
        warnings.append(f"{n_hole} of {len(solution)} solution epochs fall in {len(holes)} "
                        f"hole(s) of the truth (the longest {longest[1] - longest[0]:.4g} s at "
                        f"t = {longest[0]:.3f} s) and are not evaluated: the truth is not "
                        "interpolated across them")
    inside &= ~in_hole
    if not inside.any():
        raise SelfnavError(f"{solution_name}: no epoch can be compared: all fall in holes of "
                           f"{truth_name}")
    t = solution.t[inside]
    tl = np.interp(t, truth.t, truth.lat)
    tlon = _interp_angle(t, truth.t, truth.lon)
    th = np.interp(t, truth.t, truth.h)
    sl, slon, sh = solution.lat[inside], solution.lon[inside], solution.h[inside]
    d = geodetic_to_ecef(sl, slon, sh, WGS84) - geodetic_to_ecef(tl, tlon, th, WGS84)
    e = np.einsum("nij,nj->ni", enu_rotation(tl, tlon), d)
    hdg = _interp_angle(t, truth.t, truth_heading(truth))
    along, cross = along_cross(e, np.column_stack([np.sin(hdg), np.cos(hdg)]))
    if np.isnan(hdg).all():
        warnings.append("the truth has no heading, velocity or motion: along/cross-track omitted")
    ra = rc = None
    if roads is not None:
        lat0, lon0 = tl[0], tlon[0]
        rxy = [local_xy(r[:, 0], r[:, 1], lat0, lon0) for r in roads]
        u, dist = road_direction(local_xy(tl, tlon, lat0, lon0), rxy)
        flip = u[:, 0] * np.sin(hdg) + u[:, 1] * np.cos(hdg) < 0
        u[flip] *= -1.0
        if not (dist <= MAP_MARGIN_M).any():
            raise SelfnavError(
                f"{roads_name}: no truth point lies within {MAP_MARGIN_M / 1000:g} km of its roads "
                f"(the nearest is {dist.min() / 1000:.1f} km away): the map of another place? "
                "Road-relative metrics need the map of the drive")
        ra, rc = along_cross(e, u)
        far = dist > 50.0
        if far.any():
            warnings.append(f"{int(far.sum())} of {len(far)} truth points "
                            f"({100 * far.mean():.1f} %) are more than 50 m from any road of "
                            f"{roads_name}: their road-relative along/cross-track is not "
                            "relative to the road driven")
    m = error_metrics(e, along, cross, ra, rc)
    m.update(motion_metrics(truth, solution, t, inside))
    cov = truth_coverage(truth, t, holes)
    m.update({"samples": int(len(t)), "duration_s": float(t[-1] - t[0]),
              "solution_samples": int(len(solution)), "t_start_s": float(t[0]),
              "t_end_s": float(t[-1]), "coverage": cov["coverage"],
              "covered_s": cov["covered_s"], "truth_start_s": float(t0),
              "truth_end_s": float(t1), "truth_span_s": cov["span_s"],
              "solution_gaps": cov["gaps"], "longest_uncovered_s": cov["longest_gap_s"],
              "solution_compared": float(len(t) / len(solution)),
              "truth_holes": len(holes),
              "truth_hole_max_s": float(max((b - a for a, b in holes), default=0.0))})
    if m["coverage"] < COVERAGE_WARNING:
        w = (f"{solution_name} covers {100 * m['coverage']:.1f} % of the truth's time span ("
             f"{span_text(float(t[0]), float(t[-1]), float(t0), float(t1), 'truth')}"
             f"{', with ' + str(cov['gaps']) + ' hole(s)' if cov['gaps'] else ''}): the metrics "
             "describe only the part covered")
        warnings.append(w)
    for w in warnings:
        warn(w)
    return Evaluation(t, e, along, cross, tl, tlon, th, sl, slon, sh, hdg, ra, rc, m, warnings)


def motion_metrics(truth: Trajectory, solution: Trajectory, t, inside) -> dict:
    """Velocity and attitude errors where both files have them (the keys are left out
    otherwise): horizontal/vertical velocity RMS (m/s), roll, pitch and heading RMS (deg);
    the heading error is wrapped to ±180°."""
    out = {}
    tv, sv = truth.velocity_n, solution.velocity_n[inside]
    if np.all(np.isfinite(tv)) and np.all(np.isfinite(sv)):
        dv = sv - np.column_stack([np.interp(t, truth.t, tv[:, k]) for k in range(3)])
        out["velocity_horizontal_rms_m_s"] = _rms(np.hypot(dv[:, 0], dv[:, 1]))
        out["velocity_vertical_rms_m_s"] = _rms(dv[:, 2])
    if np.all(np.isfinite(truth.C_nb)) and np.all(np.isfinite(solution.C_nb[inside])):
        rt, pt, ht = att.euler_from_dcm_nb(truth.C_nb)
        rs, ps, hs = att.euler_from_dcm_nb(solution.C_nb[inside])
        for name, a_t, a_s in (("roll", rt, rs), ("pitch", pt, ps), ("heading", ht, hs)):
            d = np.angle(np.exp(1j * (a_s - _interp_angle(t, truth.t, a_t))))
            out[f"{name}_rms_deg"] = _rms(np.degrees(d))
            out[f"{name}_mean_deg"] = float(np.degrees(np.nanmean(d)))
    return out


def load_road_polylines(path):
    """Road polylines ``[(M_i, 2) (lat, lon) rad]`` from a map file through :mod:`selfnav.roads.graph`.

    The hook for ``--map``: it needs ``selfnav.roads.graph.road_polylines(path)`` (same return
    contract). Raises :class:`SelfnavError` with one line when the roads module is absent.
    """
    import importlib

    try:
        roads = importlib.import_module("selfnav.roads.graph")
    except ImportError:
        raise SelfnavError("--map needs the selfnav.roads.graph module, which this installation "
                           "lacks") from None
    fn = getattr(roads, "road_polylines", None)
    if fn is None:
        raise SelfnavError("selfnav.roads.graph has no road_polylines(path): road-relative "
                           "along/cross-track is not available yet")
    return [np.asarray(r, dtype=float) for r in fn(path)]


def attitude_errors(t, C_nb, ref_t, ref_C_nb, *, t_from: float | None = None,
                    sigma_rph=None) -> dict:
    """Roll, pitch and heading differences of an attitude series against a reference.

    The reference is interpolated onto ``t`` by SLERP (:func:`selfnav.attitude.slerp_dcm`)
    inside its span; epochs before ``t_from``, outside the reference or NaN are left out. The
    heading difference is wrapped to ±180°.

    Returns
    -------
    dict
        ``epochs``, ``t_from``, and per angle ``{name}_rms_deg``, ``{name}_max_deg`` (of the
        absolute difference), ``{name}_mean_deg``; with ``sigma_rph`` (N, 3) rad also
        ``{name}_within_2sigma`` (fraction of epochs) and ``{name}_nees`` (mean of (d/σ)²).
    """
    t = np.asarray(t, dtype=float)
    C = np.asarray(C_nb, dtype=float)
    ref_t = np.asarray(ref_t, dtype=float)
    ok = np.all(np.isfinite(C.reshape(len(t), 9)), axis=1)
    ok &= (t >= ref_t[0]) & (t <= ref_t[-1])
    if t_from is not None:
        ok &= t >= t_from
    out = {"epochs": int(ok.sum()), "t_from": None if t_from is None else float(t_from)}
    if not ok.any():
        return out
    Cr = att.slerp_dcm(ref_t, np.asarray(ref_C_nb, dtype=float), t[ok])
    a = att.euler_from_dcm_nb(C[ok])
    b = att.euler_from_dcm_nb(Cr)
    for k, name in enumerate(("roll", "pitch", "heading")):
        d = np.degrees(np.angle(np.exp(1j * (a[k] - b[k]))))
        out[f"{name}_rms_deg"] = _rms(d)
        out[f"{name}_max_deg"] = float(np.max(np.abs(d)))
        out[f"{name}_mean_deg"] = float(np.mean(d))
        if sigma_rph is not None:
            s = np.degrees(np.asarray(sigma_rph, dtype=float)[ok, k])
            out[f"{name}_within_2sigma"] = float(np.mean(np.abs(d) <= 2 * s))
            out[f"{name}_nees"] = float(np.mean((d / s) ** 2))
    return out
