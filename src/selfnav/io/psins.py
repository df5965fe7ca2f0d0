"""Reader of the PSINS compact SIMU text format (``.imu``), as in PSINS ``lasergyro.imu``.

Layout (see ``shared/data/psins_lasergyro_static/README.md``): ``%`` comment lines, then

1. ``pitch0 roll0 yaw0 [deg]  VE0 VN0 VU0 [m/s]`` (coarse, "maybe inaccurate");
2. ``lat0 [deg]  lon0 [deg]  h0 [m]  t0 [s]  interval [ms]  g [m/s^2]``;
3. scale factors ``gf_x gf_y gf_z`` (arcsec per count) and ``af_x af_y af_z`` (ug*s per count,
   ug = 1e-6 g with the g of line 2);
4. rows of six integers: gyro angle increments x, y, z then accelerometer velocity increments
   x, y, z, in counts per interval. Axes are X-right, Y-forward, Z-up (RFU, as selfnav's body).

Rates are the increments divided by the interval; sample k (k = 1, 2, ...) is stamped at the end
of its interval, ``t0 + k * interval``.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.io.csvio import open_text
from selfnav.io.imu import check_imu_units
from selfnav.types import ImuData

ARCSEC = np.pi / 180.0 / 3600.0


def read_psins_imu(path) -> ImuData:
    """Read a PSINS compact SIMU ``.imu`` file (optionally gzip-compressed)."""
    path = Path(path)
    text = open_text(path)
    lines = text.splitlines()
    body = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("%")]
    if len(body) < 4:
        raise InputError(path, "PSINS file needs three header lines and data rows: is it the "
                         "compact SIMU format? (try --format csv)")

    def header(k, n, what):
        ln, s = body[k]
        try:
            vals = [float(x) for x in s.split()]
        except ValueError:
            raise InputError(path, f"PSINS header line {k + 1} ({what}) is not numeric", row=ln) from None
        if len(vals) < n:
            raise InputError(path, f"PSINS header line {k + 1} ({what}) has {len(vals)} values, "
                             f"expected {n}", row=ln)
        return vals

    att_vel = header(0, 6, "attitude and velocity")
    site = header(1, 6, "lat, lon, h, t0, interval ms, g")
    scale = header(2, 6, "scale factors")
    lat0, lon0, h0, t0, dt_ms, g0 = site[:6]
    if not (0.0 < dt_ms < 1e4):
        raise InputError(path, f"sampling interval {dt_ms} ms is not plausible", row=body[1][0])
    if not (9.7 < g0 < 9.9):
        raise InputError(path, f"nominal g {g0} in header line 2 is not in m/s^2", row=body[1][0])
    dt = dt_ms * 1e-3
    data_text = "\n".join(s for _, s in body[3:])
    try:
        arr = np.loadtxt(io.StringIO(data_text), ndmin=2, dtype=float)
    except ValueError:
        arr = None
    if arr is None or arr.ndim != 2 or arr.shape[1] < 6:
        for ln, s in body[3:]:
            parts = s.split()
            if len(parts) < 6:
                raise InputError(path, f"data row has {len(parts)} values, expected 6", row=ln)
            for x in parts[:6]:
                try:
                    float(x)
                except ValueError:
                    raise InputError(path, f"value '{x[:20]}' is not a number", row=ln) from None
        raise InputError(path, "data rows cannot be parsed")
    arr = arr[:, :6]
    bad = ~np.isfinite(arr)
    if bad.any():
        k = int(np.argmax(bad.any(axis=1)))
        raise InputError(path, "NaN or infinite value in a data row", row=body[3 + k][0])
    gf = np.asarray(scale[:3]) * ARCSEC
    af = np.asarray(scale[3:6]) * 1e-6 * g0
    omega = arr[:, :3] * gf / dt
    f = arr[:, 3:6] * af / dt
    n = len(arr)
    t = t0 + dt * np.arange(1, n + 1)
    imu = ImuData(t, omega, f, source=str(path), meta={
        "format": "psins", "lat0_deg": lat0, "lon0_deg": lon0, "h0_m": h0, "g_header": g0,
        "dt": dt, "pitch0_deg": att_vel[0], "roll0_deg": att_vel[1], "yaw0_deg": att_vel[2],
    })
    check_imu_units(imu, path)
    return imu
