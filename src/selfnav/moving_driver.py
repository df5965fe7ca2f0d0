"""Moving-base latitude and longitude from an IMU record and an attitude record (seeds 002/003).

:func:`navigate_moving` is what ``selfnav moving`` runs. Around the method of
:mod:`selfnav.moving` it settles the two things a real record gets wrong:

* **The IMU row convention.** Rows are interval means ending at ``t`` (the package's one
  convention, :class:`selfnav.types.ImuData`) unless ``rates="instantaneous"``. The gyro record
  becomes rotation vectors between *knots* (the interval ends), :class:`GyroRecord`.
* **The attitude clock.** Attitude from another system (gyrocompass, AHRS, INS) never shares
  the IMU's clock to a millisecond, and on a rolling ship 1 ms is about 0.1° of latitude
  (:func:`timing_sensitivity`). The offset is estimated from the data
  (:func:`estimate_time_offset`), then the attitude is used at its own (corrected) times and the
  gyros are composed onto them — gyros are interpolated within one IMU step by a cubic spline
  of their running sum, the attitude is never interpolated.

The σ it reports adds, to the sensor model of :func:`selfnav.moving_budget.error_budget`, the
residual timing term (offset σ × sensitivity), the interpolation term and the gyro scale-factor
term of the actual motion.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numba
import numpy as np
from scipy.interpolate import CubicSpline

from selfnav.earth import nav_rate_n
from selfnav.errors import InputError
from selfnav.io.attitude_file import check_against_gyros, check_gaps, overlap
from selfnav.kernels import (
    cumulative_rotation,
    nav_increments,
    relative_rotations,
    rodrigues,
)
from selfnav.moving import (
    MovingBaseNavigator,
    MovingSolution,
    check_rates,
    coning_increments,
    gyro_increments,
    low_pass,
)
from selfnav.moving_budget import grade_errors
from selfnav.types import AttitudeData, ImuData

#: Attitude–gyro offsets searched, s (beyond, the offset is reported as not found)
MAX_OFFSET_S = 1.0


# ----------------------------------------------------------------------------- gyro record
class GyroRecord:
    """Gyro rotations between knots, composable onto any time grid inside the knots.

    Parameters
    ----------
    t : (N,) IMU times
    omega_ib_b : (N, 3) rate rows, rad/s
    rates : ``"interval-mean"`` (row ``k`` is the mean over ``[t_{k−1}, t_k]``; the first
        interval is taken as long as the second, so the knots are ``t_0 − Δt_0, t_0, …``) or
        ``"instantaneous"`` (knots ``t``; increments by :func:`selfnav.moving.gyro_increments`)
    """

    def __init__(self, t, omega_ib_b, rates="interval-mean"):
        t = np.asarray(t, float)
        w = np.asarray(omega_ib_b, float)
        if len(t) < 4:
            raise ValueError("at least 4 IMU samples are needed")
        self.rates_convention = check_rates(rates)
        if rates == "instantaneous":
            self.tau = t
            self.rv = gyro_increments(t, w)
        else:
            self.tau = np.r_[t[0] - (t[1] - t[0]), t]
            self.rv = coning_increments(w * np.diff(self.tau)[:, None])
        self.Q = cumulative_rotation(np.ascontiguousarray(self.rv))   # body orientation at knots
        self.S = np.vstack([np.zeros(3), np.cumsum(self.rv, axis=0)])  # summed rotation vectors
        self.spline = CubicSpline(self.tau, self.S, axis=0)
        self.step = float(np.median(np.diff(self.tau)))

    @property
    def span(self):
        return float(self.tau[0]), float(self.tau[-1])

    def inside(self, t, tol=1e-6):
        """Mask of times inside the knot span (``tol`` steps beyond the ends allowed)."""
        a, b = self.span
        e = tol * self.step
        return (t >= a - e) & (t <= b + e)

    def rotations(self, grid):
        """Body rotation vectors over ``[grid_j, grid_{j+1}]`` (M-1, 3): the orientation at each
        grid time is the product of the whole steps times the partial step from the spline."""
        grid = np.asarray(grid, float)
        k = np.clip(np.searchsorted(self.tau, grid, side="right") - 1, 0, len(self.rv) - 1)
        part = self.spline(grid) - self.S[k]
        return relative_rotations(self.Q, k, np.ascontiguousarray(part))

    def rates_at(self, grid):
        """Body rates at ``grid`` (M, 3), the derivative of the spline of the summed rotations."""
        return self.spline(np.asarray(grid, float), 1)

    def interpolation_error(self, grid):
        """Error estimate (rad, (M,)) of the partial-step rotation at each grid time.

        The spline's error inside a step is about ``|ω'''| h⁴ u²(1−u)²/24`` (u the fraction of
        the step); ``ω''' h³`` is the third difference of the step means. Zero on the knots.
        """
        grid = np.asarray(grid, float)
        a = self.rv / np.diff(self.tau)[:, None]
        d3 = np.zeros_like(a)
        if len(a) >= 4:
            d3[2:-1] = a[3:] - 3 * a[2:-1] + 3 * a[1:-2] - a[:-3]
            d3[:2], d3[-1] = d3[2], d3[-2]
        k = np.clip(np.searchsorted(self.tau, grid, side="right") - 1, 0, len(self.rv) - 1)
        h = np.diff(self.tau)[k]
        u = np.clip((grid - self.tau[k]) / h, 0.0, 1.0)
        return np.linalg.norm(d3[k], axis=1) * h * (u * (1 - u)) ** 2 / 24.0


# ----------------------------------------------------------------------------- time offset
@dataclass
class TimeOffset:
    """An attitude–gyro clock offset: the attitude's stamps minus the IMU clock, s (positive:
    the attitude is stamped late; the attitude stamped ``s`` is used at ``s − offset``)."""

    offset: float
    sigma: float
    estimated: bool
    observable: bool = True
    iterations: int = 0
    check: float | None = None      # with a fixed offset: the further offset the data suggest
    motion_rate: float = 0.0        # RMS of the high-passed body rate the estimate rests on, rad/s


def _high_pass(x, n):
    """``x`` minus its centred moving average over ``n`` samples (rows ``n//2`` from each end
    are invalid and returned as zero)."""
    c = np.cumsum(np.vstack([np.zeros((1,) + x.shape[1:]), x]), axis=0)
    h = n // 2
    out = np.zeros_like(x)
    if len(x) > n:
        out[h:len(x) - h] = x[h:len(x) - h] - (c[n:] - c[:-n])[:len(x) - 2 * h] / n
    return out


def _offset_step(gyro: GyroRecord, t_att, C_nb, offset, window_s):
    """One Gauss-Newton step: (correction, its σ, RMS high-passed rate).

    With the attitude used at ``t − offset`` but truly taken at ``t − offset_true``, it equals
    ``exp([ε]) C_b^n`` with ``ε = Δ (C_b^n ω_ib^b − ω_in^n)``, ``Δ = offset − offset_true``.
    The discrete form (b) summed over the record, ``Ψ_k = Σ ζ_j``, is then ``∫ω_n dt − Δ u_k``
    with ``u = C_b^n ω_ib^b``: after removing the slow part (``∫ω_n``, the Earth and transport
    rates) by a high-pass over ``window_s``, ``Ψ`` regressed on ``u`` gives ``−Δ``.
    """
    g = t_att - offset
    m = gyro.inside(g)
    if m.sum() < 10:
        return 0.0, np.inf, 0.0
    g = g[m]
    C_nb = C_nb[m]
    C_bn = np.swapaxes(C_nb, -1, -2)
    zeta = nav_increments(np.ascontiguousarray(C_nb), gyro.rotations(g))
    psi = np.vstack([np.zeros(3), np.cumsum(zeta, axis=0)])
    u = np.einsum("nij,nj->ni", C_bn, gyro.rates_at(g))
    n = max(5, round(window_s / float(np.median(np.diff(g)))) | 1)
    psi_h, u_h = _high_pass(psi, n), _high_pass(u, n)
    h = n // 2
    psi_h, u_h = psi_h[h:len(g) - h], u_h[h:len(g) - h]
    den = float(np.sum(u_h * u_h))
    if len(u_h) < 20 or den == 0.0:
        return 0.0, np.inf, 0.0
    b = float(np.sum(psi_h * u_h)) / den
    # σ by blocks (the residuals are correlated: filtered noise, gyro random walk)
    nb = 8
    edges = np.linspace(0, len(u_h), nb + 1).astype(int)
    bb = []
    for i in range(nb):
        s = slice(edges[i], edges[i + 1])
        d = float(np.sum(u_h[s] * u_h[s]))
        if d > 0:
            bb.append(float(np.sum(psi_h[s] * u_h[s])) / d)
    sig = float(np.std(bb, ddof=1) / np.sqrt(len(bb))) if len(bb) >= 3 else np.inf
    return b, sig, float(np.sqrt(den / len(u_h)))


def estimate_time_offset(gyro: GyroRecord, t_att, C_nb, *, offset0=0.0, max_offset=MAX_OFFSET_S,
                         window_s=10.0, iterations=8, tol=1e-7, min_rate=2e-3,
                         max_rate_hz=50.0) -> TimeOffset:
    """Attitude–gyro clock offset from the record: the attitude's rotation against the gyros'.

    Gauss-Newton on :func:`_offset_step` from ``offset0`` (each step re-composes the gyros onto
    the shifted attitude times, so the model is linear in the small remaining offset), stopped
    when the correction is below ``tol`` s. Without motion (high-passed body rate below
    ``min_rate`` rad/s) the offset is not observable — and does not matter: it stays
    ``offset0`` with σ ``max_offset``. An attitude faster than ``max_rate_hz`` is thinned to it
    for the estimate (the regression needs the motion's band, not every sample).
    """
    t_att = np.asarray(t_att, float)
    step = max(1, int(np.floor(1.0 / (max_rate_hz * float(np.median(np.diff(t_att)))) + 1e-9)))
    t_att, C_nb = t_att[::step], C_nb[::step]
    off, sig, rate = float(offset0), np.inf, 0.0
    it = 0
    for it in range(1, iterations + 1):
        b, sig, rate = _offset_step(gyro, t_att, C_nb, off, window_s)
        if not np.isfinite(sig) or rate < min_rate:
            return TimeOffset(float(offset0), float(max_offset), True, False, it, motion_rate=rate)
        off = float(np.clip(off + b, -max_offset, max_offset))
        if abs(b) < tol:
            break
    observable = abs(off) < max_offset
    return TimeOffset(off, float(sig) if observable else float(max_offset), True, observable, it,
                      motion_rate=rate)


# ----------------------------------------------------------------------------- sensitivity
def _running_rms(x, n):
    n = max(1, min(int(n), len(x)))
    c = np.cumsum(np.r_[0.0, x * x])
    h = n // 2
    i0 = np.clip(np.arange(len(x)) - h, 0, len(x) - n)
    return np.sqrt((c[i0 + n] - c[i0]) / n)


def timing_sensitivity(t, C_nb, body_rates, sol: MovingSolution, *, smooth=True):
    """Latitude and longitude error per second of attitude–gyro offset, (N-1,) each, rad/s.

    An offset Δ makes the attitude ``exp([Δ u]) C_b^n`` (``u = C_b^n ω_ib^b``), so form (b)
    reads ``ω_n − Δ u̇``; the observer and the smoothing stage low-pass it (twice, gain K), and
    (13), (14) with the lag compensation turn it into ``∂φ/∂Δ`` and ``∂λ/∂Δ``
    (:func:`selfnav.moving.rate_error_to_position`). ``t``, ``C_nb``, ``body_rates`` on the
    attitude grid; ``sol`` the solution on ``t[1:]``.
    """
    t = np.asarray(t, float)
    u = np.einsum("nji,nj->ni", np.asarray(C_nb, float), np.asarray(body_rates, float))
    d = -np.diff(u, axis=0) / np.diff(t)[:, None]
    # the filters start at the mean over the first 1/K, as the navigator's (its start transient)
    d0 = d[:max(1, int(np.searchsorted(sol.t, sol.t[0] + 1.0 / sol.gain)))].mean(axis=0)
    g = low_pass(sol.t, d, sol.gain, d0)
    if smooth:
        g = low_pass(sol.t, g, sol.gain, d0)
    c, s = np.cos(sol.lat), np.sin(sol.lat)
    A = sol.branch * np.maximum(np.hypot(sol.omega_n[:, 1], sol.omega_n[:, 2]), 1e-12)
    lead = (2.0 if smooth else 1.0) / sol.gain
    dlat = (c * g[:, 2] - s * g[:, 1]) / A - lead * g[:, 0]
    rate = sol.branch * (c * g[:, 1] + s * g[:, 2])
    dlon = np.r_[0.0, np.cumsum(0.5 * np.diff(sol.t) * (rate[1:] + rate[:-1]))]
    dlon = dlon + lead * (rate - rate[0])
    return dlat, dlon


# ----------------------------------------------------------------------------- attitude sources
@numba.njit(cache=True)
def _strapdown_attitude(C_bn0, dtheta, zeta):  # pragma: no cover - compiled
    n = dtheta.shape[0]
    out = np.empty((n + 1, 3, 3))
    C = C_bn0.copy()
    Z = np.empty((3, 3))
    B = np.empty((3, 3))
    out[0] = C
    for k in range(n):
        rodrigues(-zeta[k, 0], -zeta[k, 1], -zeta[k, 2], Z)
        rodrigues(dtheta[k, 0], dtheta[k, 1], dtheta[k, 2], B)
        C = Z @ C @ B
        out[k + 1] = C
    return out


def internal_attitude(t, dtheta_b, C_nb0, lat_assumed, velocity_n=None, h=0.0):
    """Attitude ``C_n^b`` (N, 3, 3) by strapdown integration of the same gyros (no external source).

    ``C_b^n(k+1) = exp(−[ζ_k]) C_b^n(k) exp([Δθ_k])`` with ``ζ_k = ω_in^n(φ_assumed, v) Δt``.
    **Circular**: the nav-frame rate this attitude embodies is the one computed from the assumed
    latitude, so form (b) on it returns ``φ_assumed`` exactly, whatever the true latitude (a test
    measures the slope dφ_out/dφ_assumed = 1). It is useful only to check the tool chain, or
    with a latitude from elsewhere to propagate the longitude.
    """
    t = np.asarray(t, float)
    n = len(t)
    lat = np.full(n, float(lat_assumed))
    v = np.zeros((n, 3)) if velocity_n is None else np.asarray(velocity_n, float)
    w = nav_rate_n(lat, v, h)
    zeta = 0.5 * (w[1:] + w[:-1]) * np.diff(t)[:, None]
    C_bn = _strapdown_attitude(np.ascontiguousarray(np.asarray(C_nb0, float).T),
                               np.ascontiguousarray(dtheta_b, float), np.ascontiguousarray(zeta))
    return np.swapaxes(C_bn, -1, -2)


# ----------------------------------------------------------------------------- driver
def _with_start_row(sol: MovingSolution, t0, lon0) -> MovingSolution:
    def first(x):
        x = np.asarray(x)
        return np.concatenate([x[:1], x]) if x.ndim and len(x) == len(sol.t) else x

    lon = np.r_[(lon0 + np.pi) % (2 * np.pi) - np.pi, sol.lon]
    return replace(sol, t=np.r_[t0, sol.t], lat=first(sol.lat), lon=lon,
                   omega_n=first(sol.omega_n), sigma_lat=first(sol.sigma_lat),
                   sigma_lon=np.r_[0.0, sol.sigma_lon], branch=first(sol.branch),
                   sigma_terms={k: first(v) for k, v in sol.sigma_terms.items()})


def _fmt_ms(x):
    return f"{1e3 * x:+.3f} ms"


def navigate_moving(imu: ImuData, attitude: AttitudeData, lat0, lon0, *, rates="interval-mean",
                    attitude_time_offset=None, grade="navigation", gain=None, bandwidth_hz=None,
                    method="observer", observer="stable", drift_b=None,
                    max_offset=MAX_OFFSET_S) -> MovingSolution:
    """Latitude and longitude of a moving object from an IMU and an attitude record.

    Parameters
    ----------
    imu : ImuData
        Gyro rows (``f_ib_b`` is not used).
    attitude : AttitudeData
        ``C_nb`` at its own times (any rate; checked against the gyros for units and jumps).
    lat0, lon0 : rad
        ``lat0`` only picks the branch of (13); ``lon0`` starts (14) at the first solved time.
    rates : {"interval-mean", "instantaneous"}
        Convention of the IMU rows (:data:`selfnav.moving.RATE_CONVENTIONS`).
    attitude_time_offset : float, optional
        The attitude's stamps minus the IMU clock, s. Default: estimated from the data
        (:func:`estimate_time_offset`). When given, it is used as is; one regression step still
        measures what further offset the data suggest, for the σ and a warning.
    grade : a grade of :data:`selfnav.sensors.GRADES` for the sensor part of the σ
    gain, bandwidth_hz, method, observer, drift_b : as :class:`MovingBaseNavigator`

    Returns
    -------
    MovingSolution
        On the IMU times inside the solved span. ``info`` holds ``attitude_time_offset_s``,
        its σ, whether it was estimated, the rate convention and the timing sensitivity;
        ``sigma_terms`` the latitude σ per source.
    """
    check_rates(rates)
    sensor = grade_errors(grade)
    src_att = attitude.source or "attitude"
    check_gaps(imu.t, imu.source or "IMU", what="IMU")
    overlap(attitude.t, imu.t, src_att, imu.source or "")
    gyro = GyroRecord(imu.t, imu.omega_ib_b, rates)
    check_against_gyros(attitude, gyro.tau, gyro.rv, src_att, imu_path=imu.source or "IMU")
    nav = MovingBaseNavigator(lat0, lon0, gain=gain, bandwidth_hz=bandwidth_hz, method=method,
                              observer=observer, drift_b=drift_b, sensor=sensor)
    warnings = []
    t_att = np.asarray(attitude.t, float)
    if attitude_time_offset is None:
        off = estimate_time_offset(gyro, t_att, attitude.C_nb, max_offset=max_offset)
        if not off.observable:
            warnings.append("attitude–gyro time offset not observable (too little rotation, or "
                            f"beyond ±{max_offset:g} s): none applied"
                            if off.motion_rate < 2e-3 else
                            f"attitude–gyro time offset beyond ±{max_offset:g} s: check the time bases")
            off.offset = 0.0
    else:
        b, sig, rate = _offset_step(gyro, t_att, attitude.C_nb, float(attitude_time_offset), 10.0)
        off = TimeOffset(float(attitude_time_offset), float(np.hypot(b, sig)) if np.isfinite(sig)
                         else float(max_offset), False, True, 0, b, rate)
        if np.isfinite(sig) and abs(b) > max(3 * sig, 5e-4):
            warnings.append(f"the data suggest a further attitude time offset of {_fmt_ms(b)} "
                            f"(± {1e3 * sig:.3f} ms) beyond the one given")
    g = t_att - off.offset
    m = gyro.inside(g)
    if m.sum() < 3:
        raise InputError(src_att, f"fewer than 3 attitude samples inside the IMU span after the "
                         f"time offset of {_fmt_ms(off.offset)}", column="t")
    g = g[m]
    C_nb = attitude.C_nb[m]
    rv = gyro.rotations(g)
    w_b = gyro.rates_at(g)
    interp = float(np.sqrt(np.mean(gyro.interpolation_error(g) ** 2)))
    nav.sensor = dict(sensor, attitude_noise=float(np.hypot(sensor["attitude_noise"], interp)))
    sol = nav.run(g, C_nb, rotvec_b=rv, body_rates=w_b)
    # --- σ: sensors (incl. interpolation), residual timing, scale factor and misalignment
    dlat, dlon = timing_sensitivity(g, C_nb, w_b, sol, smooth=nav.smooth)
    win = max(2.0 / sol.gain, 30.0) / float(np.median(np.diff(g)))
    s_time_lat = off.sigma * _running_rms(dlat, win)
    s_time_lon = off.sigma * np.abs(dlon)
    u_rel = np.einsum("nji,nj->ni", C_nb, w_b)[1:] - sol.omega_n
    lp = low_pass(sol.t, low_pass(sol.t, u_rel, sol.gain, np.zeros(3)), sol.gain, np.zeros(3))
    sf = float(np.hypot(sensor["scale_factor"], sensor["misalignment"]))
    lp_n = np.linalg.norm(lp, axis=1)
    A = np.hypot(sol.omega_n[:, 1], sol.omega_n[:, 2])
    s_sf_lat = sf * lp_n / np.maximum(A, 1e-12)
    s_sf_lon = sf * np.r_[0.0, np.cumsum(0.5 * np.diff(sol.t) * (lp_n[1:] + lp_n[:-1]))]
    base_lat = sol.sigma_lat
    # σ of 90° means "no information" (a MEMS drift of many Ω): not larger
    sol.sigma_lat = np.minimum(np.sqrt(base_lat**2 + s_time_lat**2 + s_sf_lat**2), np.pi / 2)
    sol.sigma_lon = np.sqrt(sol.sigma_lon**2 + s_time_lon**2 + s_sf_lon**2)
    sol.sigma_terms = {"sensors": base_lat, "timing": s_time_lat, "scale_factor": s_sf_lat}
    # --- onto the IMU clock
    k0 = int(np.searchsorted(sol.t, sol.t[0] + 3.0 / sol.gain))
    k0 = min(k0, len(sol.t) - 1)
    step_att = float(np.median(np.diff(t_att)))
    sol.info = {
        "imu_rates": rates,
        "attitude_time_offset_s": off.offset,
        "attitude_time_offset_sigma_s": off.sigma,
        "attitude_time_offset_estimated": off.estimated,
        "attitude_time_offset_observable": off.observable,
        "attitude_rate_hz": 1.0 / step_att,
        "lat_error_per_ms_deg": float(np.degrees(1e-3 * np.sqrt(np.mean(dlat[k0:] ** 2)))),
        "lon_error_per_ms_deg": float(np.degrees(1e-3 * np.abs(dlon[-1]))),
        "interpolation_rad": interp,
    }
    if off.check is not None:
        sol.info["attitude_time_offset_check_s"] = off.check
    # the start row: (14) starts at lon0 at the first attitude time; latitude as first solved
    sol = _with_start_row(sol, float(g[0]), float(lon0))
    t_imu = np.asarray(imu.t, float)
    e = 1e-6 * gyro.step
    keep = (t_imu >= sol.t[0] - e) & (t_imu <= sol.t[-1] + e)
    if keep.sum() >= 2:
        out = sol.resample(t_imu[keep])
    else:   # attitude denser than the IMU around a short record: stay on the attitude grid
        out = sol
    if keep.sum() < len(t_imu) - 1:
        warnings.append(f"IMU trimmed to the attitude span: {int(keep.sum())} of {len(t_imu)} "
                        "samples")
    out.warnings = sol.warnings + warnings
    return out
