"""Units and conversions: one spelling for every constant (SI and radians inside, DESIGN §2).

Degrees appear only at the edges (files, CLI, reports); every other module converts with these
names, never with literals: ``x_deg_per_h * DEG_PER_H`` is rad/s.
"""
from __future__ import annotations

import numpy as np

#: one degree, rad
DEG = np.pi / 180.0
#: one arc-second, rad
ARCSEC = DEG / 3600.0
#: one degree per hour, rad/s
DEG_PER_H = DEG / 3600.0
#: one degree per second, rad/s
DEG_PER_S = DEG
#: angle random walk: one °/√h, rad/√s
DEG_PER_SQRT_H = DEG / 60.0
#: velocity random walk: one (m/s)/√h, (m/s)/√s
MPS_PER_SQRT_H = 1.0 / 60.0
#: standard gravity (the unit "g"), m/s²
G0 = 9.80665
#: one micro-g, m/s²
UG = 1e-6 * G0
#: one milli-g, m/s²
MG = 1e-3 * G0
#: one part per million
PPM = 1e-6


def wrap_pi(a):
    """Angle(s) wrapped to [−π, π), rad."""
    return np.mod(np.asarray(a) + np.pi, 2.0 * np.pi) - np.pi


def wrap_2pi(a):
    """Angle(s) wrapped to [0, 2π), rad."""
    return np.mod(a, 2.0 * np.pi)
