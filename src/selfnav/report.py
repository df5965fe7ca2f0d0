"""Plots and a self-contained HTML page for an evaluation (``selfnav evaluate --report DIR``).

Figures are drawn with matplotlib's Agg backend (no display needed), written as PNG and embedded
in ``report.html`` as base64 data so that the page is one file that can be mailed or archived.
The four files are written as one set (:func:`selfnav.io.output.atomic_folder`): an interrupt
leaves the old report or the new one.
"""
from __future__ import annotations

import base64
import html
import json
from pathlib import Path

import numpy as np

from selfnav.io.output import atomic_folder, atomic_write_bytes, figure_png

#: The files of a report (an older report's files are replaced as a set).
REPORT_FILES = ("errors.png", "track.png", "metrics.json", "report.html")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> bytes:
    try:
        return figure_png(fig, 110, bbox_inches="tight")
    finally:
        _pyplot().close(fig)


def error_figure(ev) -> bytes:
    """Error against time: horizontal, East/North/Up, along/cross-track. PNG bytes."""
    plt = _pyplot()
    has_road = ev.road_along is not None
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    t = ev.t - ev.t[0]
    hor = ev.horizontal
    ax = axes[0]
    ax.plot(t, hor, lw=1, color="k", label="horizontal")
    ax.axhline(ev.metrics["horizontal_rms_m"], color="C3", ls="--", lw=1,
               label=f"RMS {ev.metrics['horizontal_rms_m']:.3g} m")
    ax.axhline(ev.metrics["horizontal_p95_m"], color="C1", ls=":", lw=1,
               label=f"95 % {ev.metrics['horizontal_p95_m']:.3g} m")
    ax.set_ylabel("horizontal error, m")
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[1]
    for k, name in enumerate(("East", "North", "Up")):
        ax.plot(t, ev.error_enu[:, k], lw=1, label=name)
    ax.set_ylabel("error, m")
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[2]
    ax.plot(t, ev.along, lw=1, label="along-track (truth heading)")
    ax.plot(t, ev.cross, lw=1, label="cross-track (truth heading)")
    if has_road:
        ax.plot(t, ev.road_along, lw=1, ls="--", label="along-track (road)")
        ax.plot(t, ev.road_cross, lw=1, ls="--", label="cross-track (road)")
    ax.set_ylabel("error, m")
    ax.set_xlabel(f"time since {ev.t[0]:.3f} s, s")
    ax.legend(loc="upper right", fontsize=8)
    for a in axes:
        a.grid(alpha=0.3)
    fig.suptitle("Solution minus truth")
    return _png(fig)


def track_figure(ev, roads=None) -> bytes:
    """Truth and solution tracks in local East/North metres, over the road map when given."""
    from selfnav.evaluation import local_xy

    plt = _pyplot()
    lat0, lon0 = ev.truth_lat[0], ev.truth_lon[0]
    txy = local_xy(ev.truth_lat, ev.truth_lon, lat0, lon0)
    sxy = local_xy(ev.sol_lat, ev.sol_lon, lat0, lon0)
    fig, ax = plt.subplots(figsize=(7, 7))
    if roads:
        lo, hi = np.minimum(txy.min(0), sxy.min(0)), np.maximum(txy.max(0), sxy.max(0))
        pad = 0.1 * max(float(np.max(hi - lo)), 50.0)
        drawn = 0
        for r in roads:
            xy = local_xy(r[:, 0], r[:, 1], lat0, lon0)
            if np.any((xy >= lo - pad).all(1) & (xy <= hi + pad).all(1)):
                ax.plot(xy[:, 0], xy[:, 1], color="0.75", lw=2, zorder=0,
                        label="roads (map)" if drawn == 0 else None)
                drawn += 1
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.plot(txy[:, 0], txy[:, 1], color="k", lw=1.5, label="truth")
    ax.plot(sxy[:, 0], sxy[:, 1], color="C3", lw=1, label="solution")
    mark_ends(ax, txy[:, 0], txy[:, 1])
    ax.plot(0.0, 0.0, "k+", ms=12, mew=1.5,
            label=f"origin {np.degrees(lat0):.6f}°, {np.degrees(lon0):.6f}°")
    # fixed limits (the map's) keep the box's shape; otherwise the data limits adjust
    ax.set_aspect("equal", adjustable="box" if roads else "datalim")
    ax.set_xlabel("East of the origin, m")
    ax.set_ylabel("North of the origin, m")
    ax.set_title(f"Track (compared epochs); origin {np.degrees(lat0):.6f}°, "
                 f"{np.degrees(lon0):.6f}° (WGS-84)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return _png(fig)


def mark_ends(ax, x, y, what: str = "truth") -> None:
    """Start (green circle) and end (red square) marks of a track, with legend entries."""
    ax.plot(x[0], y[0], "o", color="tab:green", ms=8, mec="k", zorder=5,
            label=f"start ({what})")
    ax.plot(x[-1], y[-1], "s", color="tab:red", ms=8, mec="k", zorder=5, label=f"end ({what})")


#: metric names in words and their units (the report's table; the JSON keeps the keys)
METRIC_WORDS = {
    "truth": ("Truth file", ""), "solution": ("Solution file", ""),
    "horizontal_rms_m": ("Horizontal error, RMS", "m"),
    "horizontal_p95_m": ("Horizontal error, 95th percentile", "m"),
    "horizontal_max_m": ("Horizontal error, maximum", "m"),
    "horizontal_mean_m": ("Horizontal error, mean", "m"),
    "vertical_rms_m": ("Vertical error, RMS", "m"),
    "vertical_max_m": ("Vertical error, largest magnitude", "m"),
    "east_mean_m": ("East error, mean (bias)", "m"),
    "north_mean_m": ("North error, mean (bias)", "m"),
    "up_mean_m": ("Up error, mean (bias)", "m"),
    "velocity_horizontal_rms_m_s": ("Horizontal velocity error, RMS", "m/s"),
    "velocity_vertical_rms_m_s": ("Vertical velocity error, RMS", "m/s"),
    "samples": ("Epochs compared", ""),
    "duration_s": ("Time from first to last epoch compared", "s"),
    "solution_samples": ("Epochs in the solution", ""),
    "t_start_s": ("First epoch compared", "s"), "t_end_s": ("Last epoch compared", "s"),
    "coverage": ("Coverage of the truth's time span", "%"),
    "covered_s": ("Time covered by the solution", "s"),
    "truth_start_s": ("Truth starts", "s"), "truth_end_s": ("Truth ends", "s"),
    "truth_span_s": ("Truth's time span (less its holes)", "s"),
    "solution_gaps": ("Holes in the solution", ""),
    "longest_uncovered_s": ("Longest time without the solution", "s"),
    "solution_compared": ("Share of the solution's epochs compared", "%"),
    "truth_holes": ("Holes in the truth (not interpolated)", ""),
    "truth_hole_max_s": ("Longest hole in the truth", "s"),
}
_TRACK = {"along_track": "Along-track error (truth heading)",
          "cross_track": "Cross-track error (truth heading)",
          "road_along_track": "Along-track error (road)",
          "road_cross_track": "Cross-track error (road)"}
for _k, _words in _TRACK.items():
    METRIC_WORDS[f"{_k}_rms_m"] = (f"{_words}, RMS", "m")
    METRIC_WORDS[f"{_k}_mean_m"] = (f"{_words}, mean", "m")
    METRIC_WORDS[f"{_k}_max_m"] = (f"{_words}, largest magnitude", "m")
for _k in ("roll", "pitch", "heading"):
    METRIC_WORDS[f"{_k}_rms_deg"] = (f"{_k.capitalize()} error, RMS", "deg")
    METRIC_WORDS[f"{_k}_mean_deg"] = (f"{_k.capitalize()} error, mean", "deg")
_UNITS = (("_m_s", "m/s"), ("_deg", "deg"), ("_m", "m"), ("_s", "s"))


def metric_words(key: str):
    """``(name in words, unit)`` of a metric key: ``"horizontal_rms_m"`` →
    ``("Horizontal error, RMS", "m")``; an unknown key is spelled out from its own parts."""
    if key in METRIC_WORDS:
        return METRIC_WORDS[key]
    for suffix, unit in _UNITS:
        if key.endswith(suffix):
            return key[: -len(suffix)].replace("_", " ").capitalize(), unit
    return key.replace("_", " ").capitalize(), ""


def _table(metrics: dict) -> str:
    """The metric table: names in words, the value, its unit (the JSON key as a tooltip)."""
    rows = ["<tr><th>metric</th><td class=u>value</td><td class=u>unit</td></tr>"]
    for k, v in metrics.items():
        name, unit = metric_words(str(k))
        if unit == "%" and isinstance(v, (int, float)):
            v = 100.0 * v
        if isinstance(v, float):
            v = f"{v:.4g}" if np.isfinite(v) else "—"
        rows.append(f'<tr><th title="{html.escape(str(k))}">{html.escape(name)}</th>'
                    f"<td>{html.escape(str(v))}</td><td class=u>{html.escape(unit)}</td></tr>")
    return "<table>\n" + "\n".join(rows) + "\n</table>"


def html_page(title: str, metrics: dict, figures: dict, notes=()) -> str:
    """A self-contained HTML page: the metric table and the PNG figures as base64 images."""
    imgs = "\n".join(
        f'<figure><img alt="{html.escape(name)}" src="data:image/png;base64,'
        f'{base64.b64encode(png).decode("ascii")}"><figcaption>{html.escape(name)}</figcaption>'
        "</figure>" for name, png in figures.items())
    note = "".join(f"<li>{html.escape(str(n))}</li>" for n in notes)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}}
table{{border-collapse:collapse}}th,td{{border:1px solid #ccc;padding:3px 8px;text-align:left}}
td{{font-family:monospace;text-align:right}}td.u{{font-family:sans-serif;text-align:left}}
img{{max-width:100%}}</style></head>
<body><h1>{html.escape(title)}</h1>
<h2>Metrics</h2>
{_table(metrics)}
{f'<h2>Notes</h2><ul>{note}</ul>' if note else ''}
<h2>Figures</h2>
{imgs}
<p><small>Generated by selfnav. Map data © OpenStreetMap contributors (ODbL) where a map is
shown.</small></p>
</body></html>
"""


def write_report(ev, out_dir, *, roads=None, title: str = "selfnav evaluation",
                 sources: dict | None = None) -> dict:
    """Write ``errors.png``, ``track.png``, ``metrics.json`` and ``report.html`` into out_dir.

    Returns ``{name: path}`` of the files written.
    """
    out = Path(out_dir)
    figs = {"errors.png": error_figure(ev), "track.png": track_figure(ev, roads)}
    metrics = dict(ev.metrics)
    if sources:
        metrics = {**{k: str(v) for k, v in sources.items()}, **metrics}
    clean = {k: (None if isinstance(v, float) and not np.isfinite(v) else v)
             for k, v in metrics.items()}
    page = html_page(title, metrics, {"Error against time": figs["errors.png"],
                                      "Track": figs["track.png"]}, ev.warnings)
    data = {**figs, "metrics.json": json.dumps(clean, indent=2, default=float).encode(),
            "report.html": page.encode("utf-8")}
    with atomic_folder(out, owned=REPORT_FILES) as tmp:
        for name, content in data.items():
            atomic_write_bytes(tmp / name, content)
    return {name: str(out / name) for name in data}
