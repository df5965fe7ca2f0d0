"""The magnetometer calibrated in motion (issue 20): the offset a platform's iron adds to its
readings, fitted from its own turns, so that the magnetometer can hold the heading after the
start.

Levelled with the navigator's roll and pitch (:func:`selfnav.sensors.magnetic_heading`'s
frame, ``m_l = R_z(−H) B_n + b_l``), a reading's horizontal part traces, as the heading turns,
a circle of radius ``|B_h|`` about a fixed offset ``b_h``: the hard iron, plus the soft iron's
share of the vertical field (2 % of a 50 µT vertical field is 1 µT, 4° at 60° N), both fixed in
the body while it stays near level. Uncorrected, that offset is a heading error that changes
with the heading (simulated boat: 7.4° at one heading; walker: ±6.7° as it turns) and no
white-noise σ covers it: through the turns of a drive it is written into the gyro bias.

:class:`HardIronFit` fits the circle from the past only — the algebraic fit (Kåsa) as the start
of Gauss–Newton on the geometric distance ``|m − b| − R`` — and gives a corrected heading with
a σ from the fit itself: the scatter of the readings about the circle (noise, soft iron, tilt
errors) over ``R``, and the centre's covariance, which is large until the turns have swept
enough of the circle. It is trusted only when that σ is small, the turns cover at least half
the circle, and the dip of the fitted field — the levelled readings' vertical part against the
circle's radius, a ratio free of the magnetometer's unit — agrees with IGRF's (a disturbed
place, or a wrong levelling, gives another).
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from selfnav import attitude as att

#: Least heading σ of a calibrated reading, rad (the soft iron's heading-dependent part, which a
#: circle does not model, and the declination model).
MAG_CAL_FLOOR = math.radians(1.0)


def level_reading(mag_b, roll: float, pitch: float) -> np.ndarray:
    """A magnetometer reading in the levelled body frame (``R_x(θ)ᵀ R_y(γ)ᵀ m_b``, the frame
    of :func:`selfnav.sensors.magnetic_heading`)."""
    Rt = (att.frame_rotation(1, roll) @ att.frame_rotation(0, pitch)).T
    return Rt @ np.asarray(mag_b, dtype=float)


def fit_circle(xy: np.ndarray, iterations: int = 5):
    """Centre ``(2,)``, radius and the residuals of a least-squares circle through ``xy`` (N, 2):
    Kåsa's algebraic fit ``x² + y² = 2 b·m + c``, then Gauss–Newton on ``|m − b| − R``.
    Returns ``(centre, radius, residuals, J)`` with ``J`` the Jacobian of the residuals in
    ``(b_x, b_y, R)`` at the solution."""
    A = np.column_stack([2.0 * xy, np.ones(len(xy))])
    sol = np.linalg.lstsq(A, np.sum(xy * xy, axis=1), rcond=None)[0]
    b = sol[:2]
    R = math.sqrt(max(sol[2] + b @ b, 0.0))
    for _ in range(iterations):
        d = xy - b
        rho = np.hypot(d[:, 0], d[:, 1])
        rho[rho == 0.0] = 1e-9
        r = rho - R
        J = np.column_stack([-d / rho[:, None], -np.ones(len(xy))])
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        b, R = b + step[:2], R + step[2]
        if np.max(np.abs(step)) < 1e-6 * max(R, 1.0):
            break
    d = xy - b
    rho = np.hypot(d[:, 0], d[:, 1])
    rho[rho == 0.0] = 1e-9
    J = np.column_stack([-d / rho[:, None], -np.ones(len(xy))])
    return b, R, rho - R, J


class HardIronFit:
    """A causal fit of the levelled magnetometer's horizontal offset (module docstring).

    Parameters
    ----------
    inclination : IGRF's dip where the platform is, rad, down positive (None: not checked)
    step_s : seconds between kept readings (consecutive readings are one heading)
    window : readings kept (the oldest dropped: a platform whose iron changes is refitted)
    refit_s : seconds between fits
    max_sigma : the fit is used while its heading σ (without the floor) is below this, rad
    min_sweep_bins : of twelve 30° sectors about the centre, how many the readings must fill
    dip_tolerance : the fitted dip within this of ``inclination``, rad (a hard iron's vertical
        part, not fitted, shifts it: 500 nT in 50 µT by 0.2° at 60° N)

    Attributes
    ----------
    centre : (2,) or None, the horizontal offset
    radius : the fitted horizontal field
    dip : the fitted field's dip, rad (down positive)
    sigma : heading σ of a corrected reading, rad (inf until fitted)
    ready : bool, the fit is trusted
    fits : int, fits made
    """

    def __init__(self, inclination: float | None = None, *, step_s: float = 1.0,
                 window: int = 900, refit_s: float = 10.0, max_sigma: float = math.radians(4.0),
                 min_sweep_bins: int = 6, dip_tolerance: float = math.radians(4.0)):
        self.inclination = inclination
        self.step_s, self.refit_s = float(step_s), float(refit_s)
        self.max_sigma, self.min_sweep_bins = float(max_sigma), int(min_sweep_bins)
        self.dip_tolerance = float(dip_tolerance)
        self._xy = deque(maxlen=int(window))
        self._z = deque(maxlen=int(window))
        self._t_kept = -math.inf
        self._t_fit = -math.inf
        self.centre = None
        self.radius = float("nan")
        self.dip = float("nan")
        self.sigma = math.inf
        self.ready = False
        self.fits = 0

    def add(self, t: float, mag_b, roll: float, pitch: float) -> None:
        """Keep a reading (levelled with the navigator's tilt) and refit when it is time."""
        if t - self._t_kept < self.step_s - 1e-9:
            return
        self._t_kept = float(t)
        m = level_reading(mag_b, roll, pitch)
        self._xy.append(m[:2])
        self._z.append(-m[2])                # up-positive in the frame: the dip is down
        if t - self._t_fit >= self.refit_s and len(self._xy) >= 20:
            self._t_fit = float(t)
            self._fit()

    def _fit(self):
        xy = np.asarray(self._xy)
        z = float(np.median(self._z))
        b, R, r, J = fit_circle(xy)
        s_r = float(np.sqrt(np.sum(r * r) / max(len(r) - 3, 1)))
        keep = np.abs(r) <= 4.0 * s_r + 1e-12          # a disturbance (steel, a passing car)
        if keep.sum() < len(r) and keep.sum() >= 20:
            b, R, r, J = fit_circle(xy[keep], iterations=3)
            s_r = float(np.sqrt(np.sum(r * r) / max(len(r) - 3, 1)))
            xy = xy[keep]
        self.fits += 1
        if not (R > 0 and np.all(np.isfinite(b))):
            self.ready, self.sigma = False, math.inf
            return
        try:
            cov = s_r * s_r * np.linalg.inv(J.T @ J)
        except np.linalg.LinAlgError:
            self.ready, self.sigma = False, math.inf
            return
        s_centre = math.sqrt(max(float(np.max(np.linalg.eigvalsh(cov[:2, :2]))), 0.0))
        sigma = math.hypot(s_r, s_centre) / R
        ang = np.arctan2(xy[:, 1] - b[1], xy[:, 0] - b[0])
        swept = len(np.unique(np.floor((ang + math.pi) / (math.pi / 6.0)).astype(int) % 12))
        self.dip = math.atan2(z, R)
        dip_ok = self.inclination is None or abs(self.dip - self.inclination) <= self.dip_tolerance
        self.centre, self.radius = b, R
        self.sigma = math.hypot(sigma, MAG_CAL_FLOOR)
        self.ready = bool(sigma <= self.max_sigma and swept >= self.min_sweep_bins and dip_ok)

    def heading(self, mag_b, roll: float, pitch: float, declination: float = 0.0):
        """``(heading, σ)`` of a reading corrected by the fitted offset (rad, clockwise from true
        North with ``declination``), or None while the fit is not trusted."""
        if not self.ready:
            return None
        m = level_reading(mag_b, roll, pitch)
        mx, my = m[0] - self.centre[0], m[1] - self.centre[1]
        return (math.atan2(-mx, my) + declination) % (2.0 * math.pi), self.sigma


__all__ = ["HardIronFit", "fit_circle", "level_reading", "MAG_CAL_FLOOR"]
