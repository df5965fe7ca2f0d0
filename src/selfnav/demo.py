"""``selfnav demo``: the main jobs on data that ship with the package, with a small report.

Real data: PSINS ``lasergyro.imu`` (ring-laser-gyro IMU at rest on a vehicle with some
disturbance, Xi'an, site 34.246048° N; BSD 2-clause, © Gongmin Yan, PSINS toolbox).
"""
from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import numpy as np

from selfnav.cli.common import jsonable
from selfnav.io.csvio import atomic_write_bytes

SITE_LAT_DEG = 34.246048


def packaged(name: str) -> Path:
    """Path of a data file shipped inside the package."""
    return Path(str(resources.files("selfnav") / "data" / name))


def window_estimates(imu, window_s: float = 300.0):
    """Latitude in consecutive windows, plain (still) and tilt-compensated (disturbed)."""
    from selfnav.latitude import estimate_latitude

    n = int(round(window_s / imu.dt))
    out = []
    for k in range(0, len(imu) - n + 1, n):
        part = imu.select(slice(k, k + n))
        a = estimate_latitude(part, rest="still")
        b = estimate_latitude(part, rest="disturbed")
        out.append((part.t[0] + window_s / 2, np.degrees(a.latitude), np.degrees(b.latitude),
                    np.degrees(b.sigma)))
    return np.array(out)


def run_demo(out_dir: Path) -> dict:
    """Run the latitude method on the shipped static record; write JSON, a plot and HTML."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from selfnav.io import read_imu
    from selfnav.latitude import estimate_latitude

    imu = read_imu(packaged("lasergyro.imu.gz"), "psins")
    res = {m: estimate_latitude(imu, rest=m).to_dict() for m in ("auto", "still")}
    res["seed"] = estimate_latitude(imu, method="seed").to_dict()
    win = window_estimates(imu)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = {
        "data": "PSINS lasergyro.imu (real RLG IMU at rest, Xi'an), shipped with selfnav",
        "site_latitude_deg": SITE_LAT_DEG,
        "optimal": res["auto"], "plain_single_window": res["still"], "seed_formula": res["seed"],
        "error_deg": res["auto"]["latitude_deg"] - SITE_LAT_DEG,
    }
    atomic_write_bytes(out_dir / "latitude.json", json.dumps(jsonable(summary), indent=2).encode())
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(win[:, 0] / 60, win[:, 1], "o-", label="plain mean (still)")
    ax.errorbar(win[:, 0] / 60, win[:, 2], win[:, 3], fmt="s-", capsize=3,
                label="tilt-compensated (disturbed rest)")
    ax.axhline(SITE_LAT_DEG, color="k", lw=1, label="site 34.246048° N")
    ax.set_xlabel("window centre, min")
    ax.set_ylabel("latitude, deg")
    ax.set_title("Latitude from a resting RLG IMU, 5-min windows (real data)")
    ax.legend()
    fig.tight_layout()
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(out_dir / "latitude_windows.png", buf.getvalue())
    a = res["auto"]
    html = f"""<!doctype html><html><head><meta charset="utf-8"><title>selfnav demo</title></head>
<body style="font-family:sans-serif;max-width:50em">
<h1>selfnav demo — latitude from an IMU at rest</h1>
<p>Real data: PSINS <code>lasergyro.imu</code>, ring-laser-gyro IMU static on a vehicle with some
disturbance, Xi'an (site {SITE_LAT_DEG}° N), 30.8 min at 100 Hz.</p>
<table border=1 cellpadding=4>
<tr><th>estimate</th><th>latitude, deg</th><th>σ, deg</th><th>error, deg</th></tr>
<tr><td>selfnav (optimal, tilt-compensated)</td><td>{a['latitude_deg']:.4f}</td><td>{a['sigma_deg']:.4f}</td><td>{a['latitude_deg'] - SITE_LAT_DEG:+.4f}</td></tr>
<tr><td>plain single window (angle of mean vectors)</td><td>{res['still']['latitude_deg']:.4f}</td><td>{res['still']['sigma_deg']:.4f}</td><td>{res['still']['latitude_deg'] - SITE_LAT_DEG:+.4f}</td></tr>
<tr><td>seed formula (1.4)</td><td>{res['seed']['latitude_deg']:.4f}</td><td>{res['seed']['sigma_deg']:.4f}</td><td>{res['seed']['latitude_deg'] - SITE_LAT_DEG:+.4f}</td></tr>
</table>
<p>Heading {a['heading_deg']:.3f}°, pitch {a['pitch_deg']:.4f}°, roll {a['roll_deg']:.4f}°.</p>
<img src="latitude_windows.png" alt="window estimates">
<p>Notes: {'; '.join(a['warnings'])}</p>
</body></html>"""
    atomic_write_bytes(out_dir / "index.html", html.encode())
    return summary
