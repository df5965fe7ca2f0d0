"""Atmospheric delays of a pseudorange and the receiver–satellite geometry (vectorized).

* :func:`klobuchar` — the GPS broadcast ionosphere model, IS-GPS-200 §20.3.3.5.2.5 (Figure
  20-4), L1 delay scaled to other carriers by ``(f_L1/f)²``.
* :func:`saastamoinen` — zenith hydrostatic + wet delays of Saastamoinen (1972) from the
  standard atmosphere (1013.25 hPa, 15 °C, 70 % humidity at sea level, as RTKLIB's
  ``tropmodel``), mapped with the Black & Eisner (1984) ``1.001 / √(0.002001 + sin²E)``.
* :func:`azimuth_elevation` — line of sight in the local ENU frame.
"""
from __future__ import annotations

import numpy as np

from selfnav.earth import enu_rotation

C_LIGHT = 299_792_458.0
F_L1 = 1575.42e6


def azimuth_elevation(rx_ecef, sat_ecef, lat, lon):
    """Azimuth (clockwise from North) and elevation (rad) of satellites seen from ``rx_ecef``
    at geodetic ``lat, lon`` (rad). Shapes broadcast: rx (..., 3), sat (..., 3)."""
    d = np.asarray(sat_ecef, float) - np.asarray(rx_ecef, float)
    C = enu_rotation(np.asarray(lat, float), np.asarray(lon, float))
    enu = np.einsum("...ij,...j->...i", C, d)
    rho = np.linalg.norm(enu, axis=-1)
    el = np.arcsin(np.clip(enu[..., 2] / np.where(rho > 0, rho, 1.0), -1, 1))
    az = np.mod(np.arctan2(enu[..., 0], enu[..., 1]), 2 * np.pi)
    return az, el


def klobuchar(t_gps, lat, lon, az, el, alpha, beta, freq=F_L1):
    """Ionospheric group delay (m) on carrier ``freq`` from the broadcast Klobuchar model.

    Parameters
    ----------
    t_gps : GPS time, s (any origin that is a whole number of days from GPS midnight)
    lat, lon : receiver geodetic latitude / longitude, rad
    az, el : satellite azimuth / elevation, rad
    alpha, beta : (4,) broadcast coefficients (s, s/semicircle, ...; s, s/semicircle, ...)
    freq : Hz
    """
    lat_sc = np.asarray(lat) / np.pi
    lon_sc = np.asarray(lon) / np.pi
    el_sc = np.asarray(el) / np.pi
    psi = 0.0137 / (el_sc + 0.11) - 0.022
    phi_i = np.clip(lat_sc + psi * np.cos(az), -0.416, 0.416)
    lam_i = lon_sc + psi * np.sin(az) / np.cos(phi_i * np.pi)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * np.pi)
    t = np.mod(43200.0 * lam_i + np.asarray(t_gps, float), 86400.0)
    F = 1.0 + 16.0 * (0.53 - el_sc) ** 3
    amp = sum(a * phi_m**n for n, a in enumerate(alpha))
    per = sum(b * phi_m**n for n, b in enumerate(beta))
    amp = np.maximum(amp, 0.0)
    per = np.maximum(per, 72000.0)
    x = 2 * np.pi * (t - 50400.0) / per
    T = F * np.where(np.abs(x) < 1.57, 5e-9 + amp * (1 - x**2 / 2 + x**4 / 24), 5e-9)
    return C_LIGHT * T * (F_L1 / np.asarray(freq, float)) ** 2


def saastamoinen(lat, h, el, humidity: float = 0.7):
    """Tropospheric delay (m): Saastamoinen zenith delays from the standard atmosphere at
    ellipsoidal height ``h`` (m; 0 outside −100 m … 10 km), Black & Eisner mapping."""
    lat = np.asarray(lat, float)
    h = np.asarray(h, float)
    el = np.asarray(el, float)
    hgt = np.maximum(h, 0.0)
    pres = 1013.25 * (1.0 - 2.2557e-5 * hgt) ** 5.2568
    temp = 15.0 - 6.5e-3 * hgt + 273.16
    e = 6.108 * humidity * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    zhd = 0.0022768 * pres / (1.0 - 0.00266 * np.cos(2 * lat) - 0.00028 * hgt / 1e3)
    zwd = 0.002277 * (1255.0 / temp + 0.05) * e
    m = 1.001 / np.sqrt(0.002001 + np.sin(el) ** 2)
    out = (zhd + zwd) * m
    return np.where((h > -100.0) & (h < 1e4) & (el > 0), out, 0.0)


#: RTKLIB's default Klobuchar parameters (2004/1/1), used only when no file gives them
KLOBUCHAR_DEFAULT = (np.array([0.1118e-07, -0.7451e-08, -0.5961e-07, 0.1192e-06]),
                     np.array([0.1167e+06, -0.2294e+06, -0.1311e+06, 0.1049e+07]))


def klobuchar_bds(t_bdt, lat, lon, az, el, alpha, beta, freq=1561.098e6):
    """Ionospheric delay (m) from the BeiDou broadcast Klobuchar model (BDS-SIS-ICD-B1I v3.0
    §5.2.4.7: pierce point at 375 km, geographic coordinates, BDT), scaled from B1I to ``freq``
    by ``(f_B1I/f)²``."""
    R, hi = 6378.0, 375.0
    el = np.asarray(el, float)
    lat = np.asarray(lat, float)
    psi = np.pi / 2 - el - np.arcsin(R / (R + hi) * np.cos(el))
    phi_m = np.arcsin(np.clip(np.sin(lat) * np.cos(psi) + np.cos(lat) * np.sin(psi) * np.cos(az),
                              -1, 1))
    lam_m = np.asarray(lon) + np.arcsin(np.clip(np.sin(psi) * np.sin(az) / np.cos(phi_m), -1, 1))
    x = np.abs(phi_m / np.pi)
    a2 = np.maximum(sum(a * x**n for n, a in enumerate(alpha)), 0.0)
    a4 = np.clip(sum(b * x**n for n, b in enumerate(beta)), 72000.0, 172799.0)
    t = np.mod(np.asarray(t_bdt, float) + lam_m * 43200.0 / np.pi, 86400.0)
    iz = np.where(np.abs(t - 50400.0) < a4 / 4, 5e-9 + a2 * np.cos(2 * np.pi * (t - 50400.0) / a4),
                  5e-9)
    slant = iz / np.sqrt(1.0 - (R / (R + hi) * np.cos(el)) ** 2)
    return C_LIGHT * slant * (1561.098e6 / np.asarray(freq, float)) ** 2
