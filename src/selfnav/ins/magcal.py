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

A platform that turns less than half a circle — a boat changing course by 30°, a rover's or
a walker's first corners — leaves the circle's centre undetermined from the readings alone;
the gyros know how far it turned. With ``φ_k`` the raw gyros' heading at each reading
(integrated about the vertical, their bias in: a constant bias is a straight drift ``ε``), a
reading is::

    m_k = B_h (−sin(φ_k − ε τ_k − c), cos(φ_k − ε τ_k − c)) + b_h
        = [[−sin θ_k, cos θ_k], [cos θ_k, sin θ_k]] (B_h cos c, B_h sin c) + b_h,
    θ_k = φ_k − ε τ_k

(``c`` the unknown constant between the gyros' heading and the field's, ``τ`` time from the
stretch's middle): linear in ``(B_h cos c, B_h sin c, b_h)`` for a given ``ε``. ``ε`` is
searched about the navigator's bias estimate (±0.5 °/s: a consumer prior early in a drive is
that far off), then Gauss–Newton polishes all five. A turn of a few tens of degrees pins the
offset; the straight stretches pin the drift (the field does not turn there, whatever the
gyros say). The absolute heading still comes from the field alone. The residuals (noise, the
levelling's tilt error as it wanders) are correlated over seconds: the covariance is widened
by their lag-one correlation, ``(1 + ρ) / (1 − ρ)``. A fit is trusted as the circle's is
(σ, dip), with at least ``min_turn`` of turning once the drift is removed; the better of the
two trusted fits is used, and a trusted one is kept when the turns that pinned it leave the
window (the iron has not moved).

Measured: docs/platforms.md.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from selfnav import attitude as att
from selfnav.correlation import ar1_variance_factor, lag_one_correlation

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
    aided_window : readings kept for the fit through the turns (the gyro bias must stay
        nearly constant over them)
    min_turn : the turns must span at least this over those readings, rad

    Attributes
    ----------
    centre : (2,) or None, the horizontal offset
    radius : the fitted horizontal field
    dip : the fitted field's dip, rad (down positive)
    sigma : heading σ of a corrected reading, rad (inf until fitted)
    ready : bool, the fit is trusted
    source : ``"circle"`` or ``"turns"``, the fit in use (None before)
    t_ready : time of the first trusted fit (None before)
    fits : int, fits made
    """

    def __init__(self, inclination: float | None = None, *, step_s: float = 1.0,
                 window: int = 900, refit_s: float = 10.0, max_sigma: float = math.radians(4.0),
                 min_sweep_bins: int = 6, dip_tolerance: float = math.radians(4.0),
                 aided_window: int = 300, min_turn: float = math.radians(20.0)):
        self.inclination = inclination
        self.step_s, self.refit_s = float(step_s), float(refit_s)
        self.max_sigma, self.min_sweep_bins = float(max_sigma), int(min_sweep_bins)
        self.dip_tolerance = float(dip_tolerance)
        self._xy = deque(maxlen=int(window))
        self._z = deque(maxlen=int(window))
        # the recent readings with the raw gyros' heading (t, φ, m_x, m_y, m_up) for the fit
        # through the turns, and the navigator's latest gyro bias about the vertical
        self.aided_window = int(aided_window)
        self.min_turn = float(min_turn)
        self._seg = deque(maxlen=self.aided_window)
        self._bias_up = 0.0
        self.source = None                   # "circle" or "turns": the fit in use
        self.t_ready = None                  # when a fit was first trusted
        self._t_kept = -math.inf
        self._t_fit = -math.inf
        self.centre = None
        self.radius = float("nan")
        self.dip = float("nan")
        self.sigma = math.inf
        self.ready = False
        self.fits = 0

    def add(self, t: float, mag_b, roll: float, pitch: float, gyro_yaw: float | None = None,
            gyro_bias_up: float = 0.0) -> None:
        """Keep a reading (levelled with the navigator's tilt) and refit when it is time.
        ``gyro_yaw``: the raw gyros' heading change (clockwise, rad) integrated since any fixed
        time, their bias in; ``gyro_bias_up``: the navigator's estimate of that bias about the
        vertical (rad/s, counter-clockwise), where the fit through the turns starts from."""
        if t - self._t_kept < self.step_s - 1e-9:
            return
        self._t_kept = float(t)
        m = level_reading(mag_b, roll, pitch)
        self._xy.append(m[:2])
        self._z.append(-m[2])                # up-positive in the frame: the dip is down
        if gyro_yaw is not None:
            self._seg.append((float(t), float(gyro_yaw), m[0], m[1], -m[2]))
            self._bias_up = float(gyro_bias_up)
        if t - self._t_fit >= self.refit_s and len(self._xy) >= 20:
            self._t_fit = float(t)
            self._fit()

    def new_stretch(self) -> None:
        """The gyros' heading is broken (an IMU gap): the fit through the turns starts again
        (a trusted calibration is kept)."""
        self._seg.clear()

    def _fit(self):
        found = [f for f in (self._fit_circle(), self._fit_turns()) if f is not None]
        if not found:
            return
        self.fits += 1
        trusted = [f for f in found if f["ready"]]
        if trusted:
            best = min(trusted, key=lambda f: f["sigma"])
        elif self.ready:
            # the turns that pinned the centre have left the window; the iron has not moved
            return
        else:
            best = found[0]
        self.centre, self.radius, self.dip = best["centre"], best["radius"], best["dip"]
        self.sigma, self.ready = best["sigma"], best["ready"]
        self.source = best["source"] if best["ready"] else None
        if self.ready and self.t_ready is None:
            self.t_ready = self._t_kept

    def _candidate(self, source, centre, radius, dip, s_r, cov_centre, shape_ok=True):
        """A fit's result: its heading σ from the readings' scatter ``s_r`` and the centre's
        covariance ``cov_centre`` over the radius (the floor added), trusted when that σ is
        below ``max_sigma``, the dip agrees with IGRF's and ``shape_ok``."""
        s_centre = math.sqrt(max(float(np.max(np.linalg.eigvalsh(cov_centre))), 0.0))
        sigma = math.hypot(s_r, s_centre) / radius
        dip_ok = self.inclination is None or abs(dip - self.inclination) <= self.dip_tolerance
        return {"centre": centre, "radius": radius, "dip": dip, "source": source,
                "sigma": math.hypot(sigma, MAG_CAL_FLOOR),
                "ready": bool(sigma <= self.max_sigma and dip_ok and shape_ok)}

    def _fit_turns(self):
        """The fit through the turns (module docstring): ``(B_h cos e, B_h sin e, b_x, b_y)``
        and the gyros' heading drift ``ε`` (minus their bias about the vertical),
        ``m_k = Rot(φ_k − ε τ_k) (B_h cos e, B_h sin e) + b_h``: the linear solution at the
        best drift of a grid about the navigator's bias, then Gauss–Newton; None while the
        stretch is too short or has not turned ``min_turn``."""
        if len(self._seg) < 20:
            return None
        a = np.asarray(self._seg)
        phi = a[:, 1]
        tau = a[:, 0] - a[:, 0].mean()
        th = phi + self._bias_up * tau
        if float(th.max() - th.min()) < 0.5 * self.min_turn:
            return None
        n = len(phi)
        y = np.concatenate([a[:, 2], a[:, 3]])

        def model(x):
            th = phi - x[4] * tau
            s, c = np.sin(th), np.cos(th)
            J = np.zeros((2 * n, 5))
            J[:n, 0], J[:n, 1], J[:n, 2] = -s, c, 1.0
            J[n:, 0], J[n:, 1], J[n:, 3] = c, s, 1.0
            rot = J[:, :2] @ x[:2]
            d = np.concatenate([-c * x[0] - s * x[1], -s * x[0] + c * x[1]])
            J[:, 4] = -np.tile(tau, 2) * d
            return rot + np.concatenate([np.full(n, x[2]), np.full(n, x[3])]), J

        def linear(eps, keep):
            x = np.zeros(5)
            x[4] = eps
            _, J = model(x)
            x[:4] = np.linalg.lstsq(J[keep, :4], y[keep], rcond=None)[0]
            return x, float(np.sum((y - model(x)[0])[keep] ** 2))

        def solve(keep):
            # the navigator's bias may be far off early (a consumer prior): the drift is first
            # searched about it (±0.5 °/s), Gauss–Newton then polishes all five
            grid = -self._bias_up + np.radians(np.linspace(-0.5, 0.5, 41))
            x = min((linear(e, keep) for e in grid), key=lambda c: c[1])[0]
            for _ in range(6):
                f, J = model(x)
                step = np.linalg.lstsq(J[keep], (y - f)[keep], rcond=None)[0]
                x = x + step
                if abs(step[4]) * (tau.max() - tau.min()) < 1e-4:
                    break
            f, J = model(x)
            r = y - f
            return x, r, J, float(np.sqrt(np.sum(r[keep] ** 2) / max(int(keep.sum()) - 5, 1)))

        keep = np.ones(2 * n, bool)
        x, r, J, s_r = solve(keep)
        # a disturbance (steel, a passing car): readings beyond 4σ dropped, refitted once
        new = np.abs(r) <= 4.0 * s_r + 1e-12
        new = np.tile(new[:n] & new[n:], 2)
        if 40 <= new.sum() < keep.sum():
            keep = new
            x, r, J, s_r = solve(keep)
        B = math.hypot(x[0], x[1])
        if not (B > 0 and np.all(np.isfinite(x))):
            return None
        th = phi - x[4] * tau                   # the turns the field shows, drift removed
        if float(th.max() - th.min()) < self.min_turn:
            return None
        # residuals correlated from one reading to the next (the levelling's tilt error wanders):
        # the covariance widened by the effective number of independent readings
        rk = r.reshape(2, n)[:, keep[:n]]
        rho = lag_one_correlation(rk, 0.95) if rk.shape[1] > 3 else 0.0
        try:
            cov = s_r * s_r * np.linalg.inv(J[keep].T @ J[keep]) * ar1_variance_factor(rho)
        except np.linalg.LinAlgError:
            return None
        return self._candidate("turns", x[2:4].copy(), B,
                               math.atan2(float(np.median(a[:, 4])), B), s_r, cov[2:4, 2:4])

    def _fit_circle(self):
        xy = np.asarray(self._xy)
        z = float(np.median(self._z))
        b, R, r, J = fit_circle(xy)
        s_r = float(np.sqrt(np.sum(r * r) / max(len(r) - 3, 1)))
        keep = np.abs(r) <= 4.0 * s_r + 1e-12          # a disturbance (steel, a passing car)
        if keep.sum() < len(r) and keep.sum() >= 20:
            b, R, r, J = fit_circle(xy[keep], iterations=3)
            s_r = float(np.sqrt(np.sum(r * r) / max(len(r) - 3, 1)))
            xy = xy[keep]
        if not (R > 0 and np.all(np.isfinite(b))):
            return None
        try:
            cov = s_r * s_r * np.linalg.inv(J.T @ J)
        except np.linalg.LinAlgError:
            return None
        ang = np.arctan2(xy[:, 1] - b[1], xy[:, 0] - b[0])
        swept = len(np.unique(np.floor((ang + math.pi) / (math.pi / 6.0)).astype(int) % 12))
        return self._candidate("circle", b, R, math.atan2(z, R), s_r, cov[:2, :2],
                               swept >= self.min_sweep_bins)

    def heading(self, mag_b, roll: float, pitch: float, declination: float = 0.0):
        """``(heading, σ)`` of a reading corrected by the fitted offset (rad, clockwise from true
        North with ``declination``), or None while the fit is not trusted."""
        if not self.ready:
            return None
        m = level_reading(mag_b, roll, pitch)
        mx, my = m[0] - self.centre[0], m[1] - self.centre[1]
        return (math.atan2(-mx, my) + declination) % (2.0 * math.pi), self.sigma


__all__ = ["HardIronFit", "fit_circle", "level_reading", "MAG_CAL_FLOOR"]
