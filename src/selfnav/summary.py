"""What a result covers, in numbers and in words: time spans, coverage, output rates.

Small pure functions shared by ``selfnav navigate`` (the solution's own span against the IMU
record: "from 37.2 s to 60.0 s of a 60.0 s IMU record") and ``selfnav evaluate`` (the share of
the truth's time span that the compared solution covers). Coverage is a share of *time*, not
of epochs: a solution that starts late or has holes covers less, whatever its epoch count.

A step between two consecutive epochs counts as covered when it is no longer than
``max_gap`` (:func:`default_max_gap`: three typical steps of the solution); a longer step is a
hole in the solution.
"""
from __future__ import annotations

import numpy as np

#: a step longer than this many median steps is a hole in a solution
GAP_FACTOR = 3.0


def default_max_gap(t, floor: float = 0.0) -> float:
    """The longest step between epochs ``t`` (s) that still counts as covered:
    :data:`GAP_FACTOR` median steps, at least ``floor`` (s)."""
    t = np.asarray(t, dtype=float)
    if len(t) < 2:
        return float(floor)
    return float(max(GAP_FACTOR * np.median(np.diff(t)), floor))


def covered_intervals(t, max_gap: float | None = None):
    """Time intervals ``[(start, end), ...]`` (s) that the epochs ``t`` cover: runs of epochs
    whose steps are at most ``max_gap`` (default :func:`default_max_gap`)."""
    t = np.asarray(t, dtype=float)
    if len(t) == 0:
        return []
    if len(t) == 1:
        return [(float(t[0]), float(t[0]))]
    gap = default_max_gap(t) if max_gap is None else float(max_gap)
    breaks = np.flatnonzero(np.diff(t) > gap)
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [len(t) - 1]])
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends)]


def _overlap(intervals, a: float, b: float) -> float:
    return float(sum(max(0.0, min(b, e) - max(a, s)) for s, e in intervals))


def coverage(t, start: float, end: float, *, max_gap: float | None = None, holes=()) -> dict:
    """How much of the span ``[start, end]`` (s) the epochs ``t`` cover.

    Parameters
    ----------
    t : (N,) s, increasing
    start, end : the reference span (the truth's, the IMU record's)
    max_gap : longest step that counts as covered (default :func:`default_max_gap` of ``t``)
    holes : ``[(a, b), ...]`` parts of the reference span that do not count (holes of the
        truth): removed from the span and from what is covered

    Returns
    -------
    dict
        ``coverage`` (share of the span covered, 0..1), ``covered_s``, ``span_s`` (the span
        less its holes), ``gaps`` (holes of the solution inside the span: count) and
        ``longest_gap_s`` (the longest stretch of the span without the solution, the start
        and end included).
    """
    t = np.asarray(t, dtype=float)
    start, end = float(start), float(end)
    holes = [(float(a), float(b)) for a, b in holes]
    span = max(end - start, 0.0) - _overlap(holes, start, end)
    ivs = covered_intervals(t[(t >= start) & (t <= end)], max_gap)
    covered = _overlap(ivs, start, end) - sum(_overlap(ivs, a, b) for a, b in holes)
    # the stretches of the span the solution leaves out: before, between and after its runs
    bounds = [start] + [x for iv in ivs for x in iv] + [end]
    missing = [(bounds[k], bounds[k + 1]) for k in range(0, len(bounds), 2)]
    missing = [b - a - _overlap(holes, a, b) for a, b in missing]
    return {"coverage": float(np.clip(covered / span, 0.0, 1.0)) if span > 0 else 0.0,
            "covered_s": float(max(covered, 0.0)), "span_s": float(span),
            "gaps": max(len(ivs) - 1, 0), "longest_gap_s": float(max(missing, default=0.0))}


def span_text(t_first: float, t_last: float, start: float, end: float, what: str) -> str:
    """``"from 37.2 s to 60.0 s of a 60.0 s IMU record"`` (``what``: "IMU record", "truth"),
    times relative to the record's start when it starts at a large time (GPS seconds)."""
    origin = start if abs(start) >= 1000.0 else 0.0
    rel = "" if origin == 0.0 else f" (since its start at {start:.3f} s)"
    return (f"from {t_first - origin:.1f} s to {t_last - origin:.1f} s of a "
            f"{end - start:.1f} s {what}{rel}")


def output_rate(t) -> dict:
    """Epoch rate of a result: ``median_hz``, and the shortest and longest steps (s)."""
    t = np.asarray(t, dtype=float)
    if len(t) < 2:
        return {"median_hz": float("nan"), "min_step_s": float("nan"), "max_step_s": float("nan")}
    d = np.diff(t)
    return {"median_hz": float(1.0 / np.median(d)), "min_step_s": float(d.min()),
            "max_step_s": float(d.max())}


def solution_span(t, record_t) -> dict:
    """The solution's span against its input record (the IMU's): the keys ``navigate --json``
    adds to its summary. ``t``: the solution's epochs; ``record_t``: the record's times."""
    t = np.asarray(t, dtype=float)
    r0, r1 = float(record_t[0]), float(record_t[-1])
    cov = coverage(t, r0, r1)
    return {"t_first_s": float(t[0]), "t_last_s": float(t[-1]),
            "solution_duration_s": float(t[-1] - t[0]), "imu_start_s": r0, "imu_end_s": r1,
            "imu_duration_s": r1 - r0, "coverage": cov["coverage"],
            "solution_gaps": cov["gaps"], "longest_gap_s": cov["longest_gap_s"],
            "output_rate": output_rate(t),
            "span": span_text(float(t[0]), float(t[-1]), r0, r1, "IMU record")}


__all__ = ["coverage", "covered_intervals", "default_max_gap", "span_text", "output_rate",
           "solution_span"]
