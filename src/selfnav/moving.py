"""Latitude and longitude of a moving object from gyros and attitude (seeds 002/003, DESIGN §4).

The navigation frame's absolute rate ``ω_n = ω_in^n = (ω_ξ, ω_η, ω_ζ)`` (ENU) satisfies
``ω_η = (Ω + λ̇) cos φ``, ``ω_ζ = (Ω + λ̇) sin φ`` (seed 002, (1)), so

    φ = arctan(ω_ζ / ω_η)                         seed 002, (2), (13)
    λ = λ0 + ∫ (ω_η / cos φ − Ω) dt                seed 002, (3), (14)

``ω_n`` comes from gyro rates and an attitude source, three ways:

* ``euler``: the seed's kinematic form (6)–(12), ``ω_n = C_b^n (ω_b − ω_nb^b(θ̇, γ̇, ψ̇))`` with
  numerically differentiated Euler angles;
* ``discrete``: from consecutive attitude matrices and coning-corrected gyro increments,
  ``[ζ_k] = log(C_b^n(k) exp([Δθ_k]) C_n^b(k+1))``, ``ω_n ≈ ζ_k / Δt`` (no angle derivative);
* ``observer`` (default): the Luenberger observer (15)–(22). The printed correction
  ``−(Ĉ − C*) K C`` is stable only while ``K C − [ω_b]`` stays positive (the body turned less
  than ~90°); the stable form ``−K (Ĉ − C*)`` works for any rotation. In the navigation frame
  the stable observer is exactly form ``discrete`` followed by a first-order low-pass of time
  constant 1/K (a test checks this).

A second first-order stage of the same time constant smooths the observer output: attitude noise
enters the observer output as ``K δ`` (seed: "a larger K increases the effect of δ"), and the
second stage averages it (error model: :func:`error_budget`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from selfnav import attitude as att
from selfnav.earth import OMEGA_EARTH
from selfnav.io.csvio import write_csv
from selfnav.kernels import mat3_mul, nav_increments, rodrigues
from selfnav.moving_budget import BUDGET_KEYS, error_budget, grade_errors

#: The two conventions for IMU rate rows (``--imu-rates``): the package's one convention
#: (:class:`selfnav.types.ImuData`, mean over the interval ending at ``t``) and point samples.
RATE_CONVENTIONS = ("interval-mean", "instantaneous")

def gain_from_bandwidth(bandwidth_hz: float) -> float:
    """Observer gain ``K = 2π B`` (1/s) for a first-order bandwidth ``B`` in Hz."""
    if not bandwidth_hz > 0:
        raise ValueError("bandwidth must be positive")
    return 2.0 * np.pi * float(bandwidth_hz)


# ----------------------------------------------------------------------------- gyro increments
def gyro_increments(t, omega_ib_b):
    """Coning-corrected rotation vectors over ``[t_k, t_{k+1}]`` from rate samples, (N-1, 3).

    The integral uses the 4-point cubic rule ``Δt/24 (−ω_{k−1} + 13ω_k + 13ω_{k+1} − ω_{k+2})``
    (trapezoid at the two end intervals); the coning term of a linearly varying rate is
    ``Δt²/12 ω_k × ω_{k+1}``.
    """
    t = np.asarray(t, float)
    w = np.asarray(omega_ib_b, float)
    dt = np.diff(t)[:, None]
    a = 0.5 * dt * (w[:-1] + w[1:])
    if len(t) >= 4:
        h = dt[1:-1]
        a[1:-1] = h / 24.0 * (-w[:-3] + 13.0 * w[1:-2] + 13.0 * w[2:-1] - w[3:])
    return a + dt**2 / 12.0 * np.cross(w[:-1], w[1:])


def coning_increments(dtheta):
    """Rotation vectors from raw angle increments: ``Δθ_k + Δθ_{k−1} × Δθ_k / 12``."""
    d = np.asarray(dtheta, float)
    out = d.copy()
    out[1:] += np.cross(d[:-1], d[1:]) / 12.0
    return out


def check_rates(rates: str) -> str:
    """``rates`` if it is one of :data:`RATE_CONVENTIONS`, else ValueError."""
    if rates not in RATE_CONVENTIONS:
        raise ValueError(f"unknown rate convention '{rates}' ({' or '.join(RATE_CONVENTIONS)})")
    return rates


def gyro_rotations(t, omega_ib_b, rates="interval-mean"):
    """Rotation vectors over ``[t_k, t_{k+1}]`` (N-1, 3) from gyro rate rows at ``t`` (N,).

    ``rates="interval-mean"`` (the package's convention, :class:`selfnav.types.ImuData`): row
    ``k+1`` is the mean rate over ``[t_k, t_{k+1}]``, so the increment is ``ω_{k+1} Δt_k``
    exactly, coning-corrected by :func:`coning_increments`; row 0 (its interval starts before
    ``t_0``) is not used. ``"instantaneous"``: point samples, integrated by
    :func:`gyro_increments`.
    """
    t = np.asarray(t, float)
    w = np.asarray(omega_ib_b, float)
    if check_rates(rates) == "instantaneous":
        return gyro_increments(t, w)
    return coning_increments(w[1:] * np.diff(t)[:, None])


def rates_at_knots(t, rotvec_b):
    """Body rates at the knots ``t`` (N,) from rotation vectors over the N-1 intervals.

    The rotation over an interval divided by its length is the interval's mean rate; the rate at
    a knot is ``(−a_{k−2} + 7a_{k−1} + 7a_k − a_{k+1})/12`` from the four neighbouring means
    (4th order on a uniform grid), the mean of the two neighbours next to the ends.
    """
    t = np.asarray(t, float)
    a = np.asarray(rotvec_b, float) / np.diff(t)[:, None]
    out = np.empty((len(t), 3))
    out[0], out[-1] = a[0], a[-1]
    out[1:-1] = 0.5 * (a[:-1] + a[1:])
    if len(a) >= 4:
        out[2:-2] = (-a[:-3] + 7.0 * a[1:-2] + 7.0 * a[2:-1] - a[3:]) / 12.0
    return out


# ----------------------------------------------------------------------------- ω_n, two ways
def omega_n_discrete(t, C_nb, rotvec_b):
    """Form (b): mean ``ω_n`` over each interval from attitude matrices and gyro increments.

    ``C_b^n(k+1) = exp(−[ζ_k]) C_b^n(k) exp([Δθ_k])`` gives
    ``ζ_k = log(C_b^n(k) exp([Δθ_k]) C_n^b(k+1))``; returns ``(t_mid, ζ_k/Δt)``.
    """
    t = np.asarray(t, float)
    zeta = nav_increments(np.ascontiguousarray(C_nb, dtype=float),
                          np.ascontiguousarray(rotvec_b, dtype=float))
    return 0.5 * (t[1:] + t[:-1]), zeta / np.diff(t)[:, None]


def _derivative(t, x):
    """d/dt on a (nearly) uniform grid: 5-point stencil inside, 2nd order at the ends."""
    d = np.gradient(x, t, axis=0, edge_order=2)
    dt = np.diff(t)
    if len(t) >= 5 and np.allclose(dt, dt[0], rtol=1e-6):
        h = dt[0]
        d[2:-2] = (x[:-4] - 8 * x[1:-3] + 8 * x[3:-1] - x[4:]) / (12.0 * h)
    return d


def omega_nb_b_euler(t, roll, pitch, heading):
    """``ω_nb^b`` from Euler angles by seed 002 (6), rates by numerical derivative.

    Heading is unwrapped first (a 359° → 1° step is +2°, not −358°).
    """
    ang = np.column_stack([roll, pitch, np.unwrap(heading)])
    r = _derivative(np.asarray(t, float), ang)
    return att.euler_rates_to_body(roll, pitch, r[:, 0], r[:, 1], r[:, 2])


def omega_n_euler(t, omega_ib_b, C_nb):
    """Form (a), seed 002 (9)–(12): ``ω_n = C_b^n (ω_b − ω_nb^b)`` at each sample, (N, 3)."""
    roll, pitch, heading = att.euler_from_dcm_nb(C_nb)
    w = np.asarray(omega_ib_b, float) - omega_nb_b_euler(t, roll, pitch, heading)  # (9)
    return np.einsum("nji,nj->ni", np.asarray(C_nb, float), w)  # (10)-(12), C_b^n = (C_n^b)^T


# ----------------------------------------------------------------------------- latitude, longitude
def latitude_from_rate(omega_n, branch=None):
    """Latitude from ``ω_n`` by seed 002 (13), rad.

    ``branch`` is the sign of ``Ω + λ̇``; ``None`` takes ``sign(ω_η)``, which makes this exactly
    ``arctan(ω_ζ / ω_η)`` (the ratio cancels the common factor, so a westbound vehicle faster than
    the Earth turns still gets the right latitude, where a naive ``atan2(ω_ζ, ω_η)`` would be 180°
    off). With a known branch the form ``atan2(s ω_ζ, s ω_η)`` is also defined at the poles.
    """
    w = np.asarray(omega_n, float)
    s = np.where(w[..., 1] >= 0, 1.0, -1.0) if branch is None else np.asarray(branch, float)
    return np.arctan2(s * w[..., 2], s * w[..., 1])


@numba.njit(cache=True)
def _branch_track(w, lat0, rel_floor):  # pragma: no cover - compiled
    n = w.shape[0]
    s_out = np.empty(n)
    lat = np.empty(n)
    ref = lat0
    s = 1.0
    p0 = w[0, 1] * np.cos(lat0) + w[0, 2] * np.sin(lat0)
    if p0 < 0:
        s = -1.0
    for k in range(n):
        a = np.hypot(w[k, 1], w[k, 2])
        if a > rel_floor:
            if abs(w[k, 1]) > 0.1 * a:          # |φ| < 84°: the seed's ratio, s = sign(ω_η)
                s = 1.0 if w[k, 1] > 0 else -1.0
            else:                               # near a pole: continuity with the last latitude
                p = w[k, 1] * np.cos(ref) + w[k, 2] * np.sin(ref)
                if abs(p) > 0.5 * a:
                    s = 1.0 if p > 0 else -1.0
        lat[k] = np.arctan2(s * w[k, 2], abs(w[k, 1]))   # in [-90°, 90°]
        s_out[k] = s
        ref = lat[k]
    return lat, s_out


def latitude_track(omega_n, lat0, *, floor=0.02 * OMEGA_EARTH):
    """Latitude series with the branch ``sign(Ω + λ̇)`` tracked from ``lat0`` (DESIGN §4).

    Away from the poles (``|ω_η| > 0.1 |(ω_η, ω_ζ)|``) the branch is ``sign(ω_η)``, i.e. (13);
    near a pole, where noise can flip ``ω_η``, it is the sign of the projection of
    ``(ω_η, ω_ζ)`` on the polar direction ``(cos φ, sin φ)`` of the previous estimate. It is held
    while ``|Ω + λ̇|`` is below ``floor`` (latitude not observable). The latitude is
    ``atan2(s ω_ζ, |ω_η|)``, always within ±90°. Returns ``(lat, branch)``.
    """
    return _branch_track(np.ascontiguousarray(omega_n, dtype=float), float(lat0), float(floor))


def longitude_rate(omega_n, branch):
    """``λ̇`` by seed 002 (14): ``ω_η / cos φ − Ω``.

    With φ from (13) this equals ``s·hypot(ω_η, ω_ζ) − Ω``, the form used here: no division by
    ``cos φ``, so it stays finite at the poles.
    """
    w = np.asarray(omega_n, float)
    return np.asarray(branch, float) * np.hypot(w[..., 1], w[..., 2]) - OMEGA_EARTH


def integrate_longitude(t, lon_rate, lon0):
    """``λ = λ0 + ∫ λ̇ dt`` (seed 002 (14)) by the trapezoid rule, ``λ(t_0) = λ0``."""
    t = np.asarray(t, float)
    inc = 0.5 * np.diff(t) * (lon_rate[1:] + lon_rate[:-1])
    return lon0 + np.concatenate([[0.0], np.cumsum(inc)])


# ----------------------------------------------------------------------------- observer
@numba.njit(cache=True)
def _observer_kernel(dtheta, dt, C_bn_star, C_hat0, K, printed, drift):  # pragma: no cover
    n = dtheta.shape[0]
    out = np.empty((n, 3))
    err = np.empty(n)
    C_hat = C_hat0.copy()
    R = np.empty((3, 3))
    Cm = np.empty((3, 3))
    E = np.empty((3, 3))
    Wn = np.empty((3, 3))
    for k in range(n):
        v = dtheta[k] - drift * dt[k]
        rodrigues(v[0], v[1], v[2], R)
        mat3_mul(C_hat, R, Cm)                               # Ĉ propagated with the gyros, (16)
        Cs = C_bn_star[k + 1]
        E[:, :] = Cm - Cs                                    # Ĉ − C*
        if printed:
            wb = dtheta[k] / dt[k]
            Wb = np.array([[0.0, -wb[2], wb[1]], [wb[2], 0.0, -wb[0]], [-wb[1], wb[0], 0.0]])
            Wn[:, :] = (E @ (K * Cs - Wb)) @ Cs.T            # (20)-(22): Δ (K C − [ω_b]) C^T
            C_hat = Cm - dt[k] * K * (E @ Cs)                # printed correction −(Ĉ − C*) K C
        else:
            a = 1.0 - np.exp(-K * dt[k])
            mat3_mul(E, Cs.T, Wn)                            # stable: [ω_n] ≈ K (Ĉ − C*) C*^T
            Wn *= a / dt[k]
            C_hat[:, :] = Cm - a * E                         # stable correction −K (Ĉ − C*)
        out[k, 0] = 0.5 * (Wn[2, 1] - Wn[1, 2])
        out[k, 1] = 0.5 * (Wn[0, 2] - Wn[2, 0])
        out[k, 2] = 0.5 * (Wn[1, 0] - Wn[0, 1])
        err[k] = np.sqrt(np.sum(E * E))
    return out, err, C_hat


@dataclass
class LuenbergerObserver:
    """Luenberger observer of seed 002 (15)–(22) for ``[ω_n]`` on the generalized Poisson equation.

    ``Ĉ̇ = Ĉ([ω_b] + [ω_d]) − corr`` with ``corr = (Ĉ − C*) K C`` (``form="printed"``, seed (16))
    or ``corr = K (Ĉ − C*)`` (``form="stable"``, DESIGN §4 erratum). In steady state
    ``[ω_n] ≈ (Ĉ − C*)(K C − [ω_b]) C^T`` (printed, (20)–(22)) or ``K (Ĉ − C*) C*^T`` (stable).
    A known gyro drift ``drift_b`` (rad/s) is removed from the gyro increments (the ``Ĉ[ω_d]``
    term of (22)); by default it is unknown (zero) and enters ``ω_n`` as ``C ω_d``.

    Discrete in time: each increment's exact rotation, then the correction (exact exponential
    decay ``a = 1 − e^{−KΔt}`` for the stable form, an Euler step for the printed one).
    """

    gain: float
    form: str = "stable"
    drift_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    C_hat: np.ndarray | None = None

    def __post_init__(self):
        if self.form not in ("stable", "printed"):
            raise ValueError(f"unknown observer form '{self.form}' (stable or printed)")
        if not self.gain > 0:
            raise ValueError("observer gain K must be positive")
        self.drift_b = np.asarray(self.drift_b, float)

    def run(self, dt, dtheta_b, C_bn_star):
        """Batch: ``dtheta_b`` (N, 3) rotation vectors, ``C_bn_star`` (N+1, 3, 3) measured ``C_b^n``.

        ``Ĉ`` starts at ``C_hat`` (default ``C_bn_star[0]``). Returns ``(omega_n_hat (N, 3),
        |Ĉ − C*| (N,))`` at the ends of the intervals.
        """
        dtheta_b = np.ascontiguousarray(dtheta_b, float)
        dt = np.broadcast_to(np.asarray(dt, float), (len(dtheta_b),)).copy()
        C_star = np.ascontiguousarray(C_bn_star, float)
        if self.C_hat is None:
            self.C_hat = C_star[0].copy()
        w, e, self.C_hat = _observer_kernel(dtheta_b, dt, C_star, np.ascontiguousarray(self.C_hat, float),
                                            float(self.gain), self.form == "printed", self.drift_b)
        return w, e

    def update(self, dt, dtheta_b, C_bn_star_next):
        """Streaming: one interval; returns the ``ω_n`` estimate (3,) at its end."""
        if self.C_hat is None:
            raise ValueError("set C_hat (the initial C_b^n) before streaming updates")
        C_star = np.stack([self.C_hat, np.asarray(C_bn_star_next, float)])
        w, _, self.C_hat = _observer_kernel(np.asarray(dtheta_b, float)[None], np.array([float(dt)]),
                                            C_star, np.ascontiguousarray(self.C_hat, float),
                                            float(self.gain), self.form == "printed", self.drift_b)
        return w[0]


@numba.njit(cache=True)
def _ema(x, a, y0):  # pragma: no cover - compiled
    y = np.empty_like(x)
    prev = y0.copy()
    for k in range(x.shape[0]):
        prev = prev + a[k] * (x[k] - prev)
        y[k] = prev
    return y


def low_pass(t, x, gain, y0=None):
    """First-order low-pass ``ẏ = K (x − y)`` sampled exactly (``a_k = 1 − e^{−K Δt_k}``)."""
    t = np.asarray(t, float)
    x = np.ascontiguousarray(x, float)
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0] if len(t) > 1 else 1.0))
    a = 1.0 - np.exp(-gain * dt)
    y0 = x[0] if y0 is None else np.asarray(y0, float)
    return _ema(x, a, np.ascontiguousarray(y0, float))


# ----------------------------------------------------------------------------- navigator
@dataclass
class MovingSolution:
    """Output of :class:`MovingBaseNavigator` and :func:`selfnav.moving_driver.navigate_moving`
    (rad, rad/s, s).

    ``sigma_terms`` holds the latitude σ per source (rad, arrays or scalars) when the driver
    computed them; ``info`` the run's JSON-ready facts (time offset, rate convention, ...).
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    omega_n: np.ndarray
    sigma_lat: np.ndarray
    sigma_lon: np.ndarray
    branch: np.ndarray
    gain: float
    method: str
    observer: str
    warnings: list = field(default_factory=list)
    sigma_terms: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """JSON-ready summary in degrees."""
        k0 = int(np.searchsorted(self.t, self.t[0] + 3.0 / self.gain))
        k0 = min(k0, len(self.t) - 1)
        out = {
            "samples": len(self.t), "duration_s": float(self.t[-1] - self.t[0]),
            "method": self.method, "observer": self.observer, "gain_per_s": self.gain,
            "latitude_end_deg": float(np.degrees(self.lat[-1])),
            "longitude_end_deg": float(np.degrees(self.lon[-1])),
            "latitude_mean_deg": float(np.degrees(np.mean(self.lat[k0:]))),
            "sigma_lat_end_deg": float(np.degrees(self.sigma_lat[-1])),
            "sigma_lon_end_deg": float(np.degrees(self.sigma_lon[-1])),
            "transient_s": float(3.0 / self.gain),
            "branch_flips": int(np.count_nonzero(np.diff(self.branch))),
        }
        if self.sigma_terms:   # RMS after the start-up transient
            out["sigma_lat_terms_deg"] = {
                k: float(np.degrees(np.sqrt(np.mean(np.square(np.broadcast_to(v, self.t.shape)[k0:])))))
                for k, v in self.sigma_terms.items()}
        out.update(self.info)
        out["warnings"] = list(self.warnings)
        return out

    def resample(self, t) -> "MovingSolution":
        """The solution at other times ``t`` inside its span (linear; longitude unwrapped)."""
        t = np.asarray(t, float)
        lon = np.interp(t, self.t, np.unwrap(self.lon))
        k = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 1)

        def lin(x):
            x = np.asarray(x, float)
            if x.ndim == 1:
                return np.interp(t, self.t, x)
            return np.column_stack([np.interp(t, self.t, c) for c in x.T])

        terms = {n: (lin(v) if np.ndim(v) == 1 and len(v) == len(self.t) else v)
                 for n, v in self.sigma_terms.items()}
        return MovingSolution(t, lin(self.lat), (lon + np.pi) % (2 * np.pi) - np.pi,
                              lin(self.omega_n), lin(self.sigma_lat), lin(self.sigma_lon),
                              self.branch[k], self.gain, self.method, self.observer,
                              list(self.warnings), terms, dict(self.info))

    def to_csv(self, path, *, step_s: float = 0.0, comments=()):
        """Write ``t, lat_deg, lon_deg, sigma_lat_deg, sigma_lon_deg`` atomically (``comments``
        go into the JSON sidecar ``<path>.json``, the CSV starts with its header row); with
        ``step_s > 0`` one row per ``step_s`` seconds (and the last). Returns the row count."""
        keep = np.ones(len(self.t), bool)
        if step_s > 0:
            b = np.floor((self.t - self.t[0]) / step_s)
            keep = np.r_[True, np.diff(b) > 0]
            keep[-1] = True
        write_csv(path, {"t": self.t[keep], "lat_deg": np.degrees(self.lat[keep]),
                         "lon_deg": np.degrees(self.lon[keep]),
                         "sigma_lat_deg": np.degrees(self.sigma_lat[keep]),
                         "sigma_lon_deg": np.degrees(self.sigma_lon[keep])},
                  fmt={"t": "%.6f", "lat_deg": "%.9f", "lon_deg": "%.9f"},
                  sidecar={"format": "selfnav solution", "method": "moving base (seeds 002/003)",
                           "datum": "wgs84", "notes": list(comments),
                           "columns": {"t": "time, s", "lat_deg": "latitude, deg",
                                       "lon_deg": "longitude, deg",
                                       "sigma_lat_deg": "1σ of the latitude, deg",
                                       "sigma_lon_deg": "1σ of the longitude, deg"}})
        return int(keep.sum())


class MovingBaseNavigator:
    """Latitude and longitude from gyros and attitude (seed 002 (13), (14)).

    Parameters
    ----------
    lat0, lon0 : rad. ``lat0`` only fixes the branch ``sign(Ω + λ̇)``; ``lon0`` starts (14).
    gain : observer gain K, 1/s; or ``bandwidth_hz`` (``K = 2πB``); default B = 0.01 Hz.
    method : {"observer", "discrete", "euler"}
    observer : {"stable", "printed"} (``method="observer"`` only)
    smooth : a second first-order stage of time constant 1/K on ``ω_n`` (default on)
    drift_b : known gyro drift to remove, rad/s (3,)
    sensor : dict with at least ``gyro_bias``, ``arw``, ``attitude_noise``, ``attitude_rate``
        for the sigmas (default: :func:`grade_errors` of ``"navigation"``)

    The attitude and the gyros must share one clock: :func:`selfnav.moving_driver.navigate_moving`
    estimates and removes the offset between them; this class takes the times as given.
    """

    def __init__(self, lat0, lon0, *, gain=None, bandwidth_hz=None, method="observer",
                 observer="stable", smooth=True, drift_b=None, sensor=None):
        if gain is not None and bandwidth_hz is not None:
            raise ValueError("give the gain K or the bandwidth, not both")
        self.gain = float(gain) if gain is not None else gain_from_bandwidth(bandwidth_hz or 0.01)
        if not self.gain > 0:
            raise ValueError("gain K must be positive")
        if method not in ("observer", "discrete", "euler"):
            raise ValueError(f"unknown method '{method}' (observer, discrete or euler)")
        self.lat0, self.lon0 = float(lat0), float(lon0)
        self.method, self.observer, self.smooth = method, observer, bool(smooth)
        self.drift_b = np.zeros(3) if drift_b is None else np.asarray(drift_b, float)
        self.sensor = dict(grade_errors("navigation") if sensor is None else sensor)
        self._obs = None
        self._state = None
        #: group delay of the filters (1/K per stage), compensated with φ̇ = −ω_ξ
        self.lead = (2.0 if self.smooth else 1.0) / self.gain

    # -- batch
    def run(self, t, C_nb, *, omega_ib_b=None, dtheta_b=None, rotvec_b=None,
            rates="interval-mean", body_rates=None) -> MovingSolution:
        """Batch over ``t`` (N,) and attitude ``C_nb`` (N, 3, 3) measured at ``t``.

        The gyros are one of: rate rows ``omega_ib_b`` (N, 3) in the convention ``rates``
        (:func:`gyro_rotations`: ``"interval-mean"``, the package's, or ``"instantaneous"``);
        raw increments ``dtheta_b`` (N-1, 3) over ``[t_k, t_{k+1}]`` (coning corrected here);
        or rotation vectors ``rotvec_b`` (N-1, 3). ``body_rates`` (N, 3), the gyro rates *at*
        ``t``, serve the ``euler`` form (default: instantaneous rows as given, otherwise
        :func:`rates_at_knots`). The solution is at ``t[1:]``.
        """
        t = np.asarray(t, float)
        C_nb = np.asarray(C_nb, float)
        if sum(x is not None for x in (omega_ib_b, dtheta_b, rotvec_b)) != 1:
            raise ValueError("give gyro rates, increments or rotation vectors (one of them)")
        if len(t) < 3:
            raise ValueError("at least 3 samples are needed")
        check_rates(rates)
        dt = np.diff(t)
        if omega_ib_b is not None:
            rv = gyro_rotations(t, omega_ib_b, rates)
        else:
            rv = np.asarray(rotvec_b, float) if rotvec_b is not None else coning_increments(dtheta_b)
        K = self.gain
        t_out = t[1:]
        if self.method == "euler":
            if body_rates is None:
                body_rates = (np.asarray(omega_ib_b, float) if omega_ib_b is not None
                              and rates == "instantaneous" else rates_at_knots(t, rv))
            raw = omega_n_euler(t, body_rates - self.drift_b, C_nb)[1:]
        else:
            _, raw = omega_n_discrete(t, C_nb, rv - self.drift_b * dt[:, None])
        n_init = max(1, min(len(raw), int(np.searchsorted(t_out, t_out[0] + 1.0 / K))))
        w0 = raw[:n_init].mean(axis=0)
        if self.method == "observer":
            C_bn = np.swapaxes(C_nb, -1, -2)
            a0 = 1.0 - np.exp(-K * dt[0])
            obs = LuenbergerObserver(K, self.observer, self.drift_b,
                                     att.rotvec_to_dcm((1 - a0) / a0 * w0 * dt[0]) @ C_bn[0])
            w, _ = obs.run(dt, rv, C_bn)
            self._obs = obs
        else:
            w = low_pass(t_out, raw, K, w0)
        if self.smooth:
            w = low_pass(t_out, w, K, w0)
        lat, branch = latitude_track(w, self.lat0)
        lat = lat + self.lead * (-w[:, 0])  # lag of the filters: φ̇ = −ω_ξ (seed (1))
        lon_rate = longitude_rate(w, branch)
        t_all = np.r_[t[0], t_out]
        lon = integrate_longitude(t_all, np.r_[lon_rate[0], lon_rate], self.lon0)[1:]
        # the same lag in λ̇: λ(t) ≈ λ0 + ∫λ̇_f + L (λ̇_f(t) − λ̇_f(t_0)) (exact for a steadily
        # changing λ̇, the filters started at the mean over 1/K as here)
        lon = lon + self.lead * (lon_rate - lon_rate[0])
        lon = (lon + np.pi) % (2 * np.pi) - np.pi
        s_lat, s_lon = self.sigmas(t_out - t[0], w, dt)
        warn = []
        A = np.hypot(w[:, 1], w[:, 2])
        if np.any(A < 0.1 * OMEGA_EARTH):
            warn.append("|Ω + λ̇| fell below 10 % of Earth rate: latitude unobservable there "
                        "(westbound at about the Earth's surface speed)")
        if not np.all(np.isfinite(w)):
            warn.append("the observer diverged (printed form after the body turned ~90°?)")
        return MovingSolution(t_out, lat, lon, w, s_lat, s_lon, branch, K, self.method,
                              self.observer if self.method == "observer" else "-", warn)

    def sigmas(self, tau, w, dt):
        """Latitude and longitude σ (rad) of the sensor model at elapsed times ``tau`` for the
        estimate ``w`` (:func:`error_budget`, plus the start-up transient)."""
        s = self.sensor
        # |Ω + λ̇| from the estimate, kept within [0.05, 2] Ω: a biased estimate must not
        # shrink the sigma (MEMS drifts make the measured |ω_n| many times Ω)
        A = np.clip(np.hypot(w[:, 1], w[:, 2]), 0.05 * OMEGA_EARTH, 2.0 * OMEGA_EARTH)
        terms = {k: s[k] for k in BUDGET_KEYS}
        h = float(np.median(dt))
        sig_w = error_budget(gain=self.gain, dt=h, smooth=self.smooth, **terms)["rate_total"]
        # start: the filters begin at the mean of the raw ω_n over 1/K, whose error is √2 × the
        # one-stage σ (the white parts averaged over 1/K); it decays as (1 + Kτ) e^{−Kτ} (two
        # stages) or e^{−Kτ}. In the longitude its integral (2/K or 1/K × the error) is taken
        # back by the lag compensation's −L λ̇_f(t₀), which leaves L × the filtered white noise
        K = self.gain
        sig_w0 = np.sqrt(2.0) * error_budget(gain=K, dt=h, smooth=False, **terms)["rate_total"]
        decay = (1.0 + K * tau) * np.exp(-K * tau) if self.smooth else np.exp(-K * tau)
        s_lat = np.minimum(np.hypot(sig_w, decay * sig_w0) / A, np.pi / 2)   # 90°: no information
        rate_bias = np.hypot(s["gyro_bias"], s["attitude_rate"])
        white = error_budget(gain=K, dt=h, smooth=self.smooth,
                             **dict(terms, gyro_bias=0.0, attitude_rate=0.0))["rate_total"]
        s_lon = np.sqrt((rate_bias * tau) ** 2 + s["arw"] ** 2 * tau + s["attitude_noise"] ** 2
                        + (self.lead * white) ** 2)
        return s_lat, s_lon

    # -- streaming
    def update(self, dt, dtheta_b, C_nb_next):
        """Streaming step: raw gyro increment over ``dt`` and the attitude at its end.

        Call :meth:`start` first. Returns ``(lat, lon)`` rad. The observer state starts at the
        steady state of the Earth rate at ``lat0`` (a transient of a few 1/K otherwise).
        """
        st = self._state
        if st is None:
            raise ValueError("call start(C_nb0) before update()")
        dtheta_b = np.asarray(dtheta_b, float)
        rv = dtheta_b + np.cross(st["prev"], dtheta_b) / 12.0 if st["prev"] is not None else dtheta_b
        st["prev"] = dtheta_b
        C_bn_next = np.asarray(C_nb_next, float).T
        w = self._obs.update(dt, rv, C_bn_next)
        a = 1.0 - np.exp(-self.gain * dt)
        if self.smooth:
            st["y"] = st["y"] + a * (w - st["y"])
            w = st["y"]
        lat, s = latitude_track(w[None], st["lat"])
        lr = longitude_rate(w, s[0])
        st["lon"] += 0.5 * dt * (lr + st["lon_rate"]) if st["lon_rate"] is not None else dt * lr
        if st["lon_rate"] is None:
            st["lon_rate0"] = lr
        st["lon_rate"], st["lat"] = lr, float(lat[0])
        return st["lat"] - self.lead * w[0], st["lon"] + self.lead * (lr - st["lon_rate0"])

    def start(self, C_nb0):
        """Initialise streaming from the first attitude ``C_n^b`` (streaming always runs the
        observer: the stable form unless ``observer="printed"``)."""
        w0 = OMEGA_EARTH * np.array([0.0, np.cos(self.lat0), np.sin(self.lat0)])
        form = self.observer if self.method == "observer" else "stable"
        self._obs = LuenbergerObserver(self.gain, form, self.drift_b,
                                       att.rotvec_to_dcm(w0 / self.gain) @ np.asarray(C_nb0, float).T)
        self._state = {"prev": None, "y": w0.copy(), "lat": self.lat0, "lon": self.lon0,
                       "lon_rate": None}


# ----------------------------------------------------------------------------- error model
def rate_error_to_position(omega_n, d_omega_n):
    """First-order latitude and longitude-rate errors from an ``ω_n`` error (rad, rad/s).

    From (13): ``Δφ = (cos φ δω_ζ − sin φ δω_η) / (Ω + λ̇)``; from (14):
    ``Δλ̇ = cos φ δω_η + sin φ δω_ζ``. A gyro drift ``d_b`` gives ``δω_n = C_b^n d_b``; a constant
    attitude error ``ε`` (``C* = (I + [ε]) C``) gives ``δω_n = ε × ω_n``, i.e. ``Δφ = ε_E`` (a tilt
    about East is a latitude error one for one); an attitude error that changes adds ``ε̇``.
    """
    w = np.asarray(omega_n, float)
    d = np.asarray(d_omega_n, float)
    lat = latitude_from_rate(w)
    A = np.where(w[..., 1] >= 0, 1.0, -1.0) * np.hypot(w[..., 1], w[..., 2])
    c, s = np.cos(lat), np.sin(lat)
    return (c * d[..., 2] - s * d[..., 1]) / A, c * d[..., 1] + s * d[..., 2]


# ----------------------------------------------------------------------------- seed example
SEED_OMEGA_B = np.array([0.1, 0.2, 0.3])       # seed 002, example, s^-1
SEED_OMEGA_N = np.array([4e-5, 6e-5, 9e-5])    # s^-1


def seed_example(drift_b, *, gain=50.0, form="stable", t_end=10.0, dt=1e-3, known_drift=False):
    """The seed's example: constant ``ω_b``, ``ω_n``, gyro drift ``drift_b``, ``C(0) = I``.

    The true ``C_b^n(t) = exp(−[ω_n] t) exp([ω_b] t)`` solves (15); the gyros read
    ``ω_b + ω_d``. Returns ``(t, ω̂_n − ω_n (N, 3), |Ĉ − C*|)``.
    """
    drift_b = np.asarray(drift_b, float)
    t = np.arange(int(round(t_end / dt)) + 1) * dt
    C = att.rotvec_to_dcm(-SEED_OMEGA_N * t[:, None]) @ att.rotvec_to_dcm(SEED_OMEGA_B * t[:, None])
    d = np.tile((SEED_OMEGA_B + drift_b) * dt, (len(t) - 1, 1))
    obs = LuenbergerObserver(gain, form, drift_b if known_drift else np.zeros(3), C[0].copy())
    with np.errstate(all="ignore"):
        w, e = obs.run(dt, d, C)
    return t[1:], w - SEED_OMEGA_N, e


def seed_steady_error(t, drift_b, *, gain=50.0):
    """Analytic steady-state ``ω_n`` error of the stable observer, the counterpart of (20)–(22).

    In navigation axes ``m = vee((Ĉ − C) C^T)`` obeys ``ṁ = −K m + ω_n + C ω_d`` (to first
    order), whose steady solution is ``m = ω_n/K + C(t) v`` with ``(K I + [ω_b]) v = ω_d``; so the
    error is ``K C(t) (K I + [ω_b])⁻¹ ω_d``: the drift, rotated with the body, of magnitude
    ``|K (K I + [ω_b])⁻¹ ω_d|``.
    """
    t = np.asarray(t, float)
    C = att.rotvec_to_dcm(-SEED_OMEGA_N * t[:, None]) @ att.rotvec_to_dcm(SEED_OMEGA_B * t[:, None])
    v = np.linalg.solve(gain * np.eye(3) + att.skew(SEED_OMEGA_B), np.asarray(drift_b, float))
    return gain * C @ v
