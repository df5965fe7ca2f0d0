"""The International Geomagnetic Reference Field (IGRF-14), shipped with the package.

The Gauss coefficients ``g_n^m, h_n^m`` (degree 13; 1900-2025 and the predicted secular
variation to 2030) are read from ``data/IGRF14.shc`` (source and terms in
``data/IGRF14_SOURCE.txt``) and interpolated linearly in time. The field is the gradient of

    V = a Σ_n (a/r)^(n+1) Σ_m (g_n^m cos mλ + h_n^m sin mλ) P_n^m(cos θ)

with Schmidt semi-normalised associated Legendre functions ``P_n^m``, geocentric radius ``r``,
colatitude ``θ`` and longitude ``λ``, ``a = 6371.2 km``; the geocentric components are rotated
to the geodetic (WGS-84) local frame. This is the computation of the IAGA reference code; the
tests compare it with the independent package ``ppigrf`` (0.01° in declination).
"""
from __future__ import annotations

import datetime as _dt
from functools import lru_cache
from importlib import resources

import numpy as np

from selfnav.earth import WGS84
from selfnav.errors import SelfnavError

#: Reference radius of the IGRF, m.
R_REF = 6371200.0
#: The date the field is evaluated at when none is given (a fixed date: reproducible results).
DEFAULT_DATE = _dt.datetime(2025, 1, 1)


@lru_cache(maxsize=1)
def coefficients():
    """``(epochs (T,), g (T, N+1, N+1), h (T, N+1, N+1))`` in nT from ``IGRF14.shc``."""
    text = (resources.files("selfnav") / "data" / "IGRF14.shc").read_text(encoding="ascii")
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    nmax = int(lines[0].split()[1])
    epochs = np.array([float(x) for x in lines[1].split()])
    g = np.zeros((len(epochs), nmax + 1, nmax + 1))
    h = np.zeros_like(g)
    for ln in lines[2:]:
        parts = ln.split()
        n, m = int(parts[0]), int(parts[1])
        vals = np.array([float(x) for x in parts[2:]])
        if m >= 0:
            g[:, n, m] = vals
        else:
            h[:, n, -m] = vals
    return epochs, g, h


def decimal_year(date) -> float:
    """A ``datetime``/``date`` or a decimal year as a decimal year."""
    if date is None:
        date = DEFAULT_DATE
    if isinstance(date, (int, float, np.floating)):
        return float(date)
    if not isinstance(date, _dt.datetime):
        date = _dt.datetime(date.year, date.month, date.day)
    start = _dt.datetime(date.year, 1, 1, tzinfo=date.tzinfo)
    end = _dt.datetime(date.year + 1, 1, 1, tzinfo=date.tzinfo)
    return date.year + (date - start).total_seconds() / (end - start).total_seconds()


def coefficients_at(date=None):
    """Gauss coefficients ``(g, h)`` (nT) at ``date``, interpolated between the model epochs."""
    epochs, g, h = coefficients()
    y = decimal_year(date)
    if not epochs[0] <= y <= epochs[-1]:
        raise SelfnavError(f"IGRF-14 covers {epochs[0]:.0f}-{epochs[-1]:.0f}; {y:.2f} is outside")
    k = int(np.clip(np.searchsorted(epochs, y, side="right") - 1, 0, len(epochs) - 2))
    w = (y - epochs[k]) / (epochs[k + 1] - epochs[k])
    return (1 - w) * g[k] + w * g[k + 1], (1 - w) * h[k] + w * h[k + 1]


def legendre_schmidt(theta, nmax: int):
    """Schmidt semi-normalised ``P_n^m(cos θ)`` and ``dP_n^m/dθ``, shapes ``(nmax+1, nmax+1, K)``."""
    theta = np.atleast_1d(np.asarray(theta, dtype=float))
    c, s = np.cos(theta), np.sin(theta)
    P = np.zeros((nmax + 1, nmax + 1, theta.size))
    dP = np.zeros_like(P)
    P[0, 0] = 1.0
    for n in range(1, nmax + 1):
        if n == 1:
            P[1, 1], dP[1, 1] = s, c
        else:
            k = np.sqrt((2 * n - 1) / (2 * n))
            P[n, n] = k * s * P[n - 1, n - 1]
            dP[n, n] = k * (c * P[n - 1, n - 1] + s * dP[n - 1, n - 1])
        for m in range(n):
            a = np.sqrt(n * n - m * m)
            b = np.sqrt((n - 1) ** 2 - m * m) if n - 1 >= m else 0.0
            p2 = P[n - 2, m] if n >= 2 else 0.0
            d2 = dP[n - 2, m] if n >= 2 else 0.0
            P[n, m] = ((2 * n - 1) * c * P[n - 1, m] - b * p2) / a
            dP[n, m] = ((2 * n - 1) * (c * dP[n - 1, m] - s * P[n - 1, m]) - b * d2) / a
    return P, dP


def igrf_enu(lat, lon, h=0.0, date=None):
    """IGRF-14 field in the local geodetic East-North-Up frame, nT, shape ``(..., 3)``.

    Parameters
    ----------
    lat, lon : geodetic latitude and longitude (WGS-84), rad (broadcast together with ``h``)
    h : height above the ellipsoid, m
    date : datetime, date or decimal year (default :data:`DEFAULT_DATE`)
    """
    lat, lon, h = np.broadcast_arrays(np.asarray(lat, float), np.asarray(lon, float),
                                      np.asarray(h, float))
    shape = lat.shape
    lat, lon, h = lat.ravel(), lon.ravel(), h.ravel()
    g, hh = coefficients_at(date)
    nmax = g.shape[0] - 1
    # geodetic -> geocentric (IAGA reference code): radius r, geocentric colatitude, and the
    # rotation (cd, sd) between the two local frames
    a2, b2 = WGS84.a ** 2, WGS84.b ** 2
    sl, cl = np.sin(lat), np.cos(lat)
    one, two = a2 * cl * cl, b2 * sl * sl
    rho = np.sqrt(one + two)
    r = np.sqrt(h * (h + 2.0 * rho) + (a2 * one + b2 * two) / (one + two))
    cd = (h + rho) / r
    sd = (a2 - b2) / rho * sl * cl / r
    cos_t = sl * cd - cl * sd          # cos(geocentric colatitude)
    sin_t = cl * cd + sl * sd
    theta = np.arctan2(sin_t, cos_t)
    P, dP = legendre_schmidt(theta, nmax)
    n = np.arange(nmax + 1)[:, None, None]
    m = np.arange(nmax + 1)[None, :, None]
    ratio = (R_REF / r)[None, None, :] ** (n + 2)
    cm, sm = np.cos(m * lon[None, None, :]), np.sin(m * lon[None, None, :])
    G, H = g[:, :, None], hh[:, :, None]
    gc = G * cm + H * sm
    br = np.sum((n + 1) * ratio * gc * P, axis=(0, 1))                 # up (outward)
    bt = -np.sum(ratio * gc * dP, axis=(0, 1))                          # along +θ (south)
    with np.errstate(divide="ignore", invalid="ignore"):
        bp = np.sum(ratio * m * (G * sm - H * cm) * P, axis=(0, 1)) / np.where(
            sin_t > 1e-12, sin_t, np.nan)                                # east
    x_gc, z_gc = -bt, -br               # north and down, geocentric frame
    north = x_gc * cd + z_gc * sd
    down = z_gc * cd - x_gc * sd
    return np.stack([bp, north, -down], axis=-1).reshape(shape + (3,))


__all__ = ["igrf_enu", "coefficients", "coefficients_at", "legendre_schmidt", "decimal_year",
           "R_REF", "DEFAULT_DATE"]
