"""Latitude, heading and tilt of a site from an IMU at rest (seed 000, Avrutov 2018; DESIGN §3).

At rest the gyros measure ``ω = C_n^b Ω_n`` with ``Ω_n = (0, Ω cos φ, Ω sin φ)`` (ENU) and the
accelerometers the specific force ``f = C_n^b (0, 0, g)``. The angle between the two vectors is
``90° − φ`` whatever the orientation ``C_n^b`` (seed §2). Two estimators are offered:

``seed``
    Formula (1.4) in specific-force form, ``sin φ = (ω · f) / (Ω g)`` with the constants
    Ω = 15.041 °/h and g = 9.81 m/s² (seed §1). Its noise grows as 1/cos φ and any error in the
    assumed g or Ω enters directly.
``optimal`` (default)
    ``φ = atan2(ω · u, |ω × u|)`` with ``u = f/|f|``, the angle between the *measured* vectors.
    With |ω| and |f| free (a sensor scale error common to three axes), the six mean values
    determine exactly the six unknowns (φ, three attitude angles, |ω|, |f|), so this is the
    maximum-likelihood estimate under white noise and its delta-method variance is the
    Cramér–Rao bound, ``σ_φ² = (ARW²/Ω² + VRW²/g²) / T`` for isotropic noise, the same at every
    latitude and orientation.

Disturbed rest (a vehicle with people moving in it, wind on a mast): a net tilt change ``Δθ`` over
the record adds ``Δθ/T`` to the mean gyro rate. The tilt is seen by the accelerometers, so the
tilt-compensated rate is the least-squares slope of ``∫ω dt − θ_tilt(t)``; it is used when the
tilt change is significant (``rest="auto"``).

The multi-position estimator (:func:`estimate_latitude_multiposition`) fits the gyro and
accelerometer biases jointly with φ and the attitude of every position.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from numba import njit

from selfnav import attitude as att
from selfnav.earth import OMEGA_EARTH, normal_gravity
from selfnav.errors import InputError, NotAtRestError, SelfnavError, warn
from selfnav.io.imu import check_rest_units, longest_stretch

DEG = np.pi / 180.0
DEG_PER_H = DEG / 3600.0
G_STD = 9.80665

#: Constants of the seed's formula (1.4): Ω = 15.041 °/h, g = 9.81 m/s² (seed §1, §3).
SEED_OMEGA = 15.041 * DEG_PER_H
SEED_G = 9.81


# --------------------------------------------------------------------------------------------
# Closed-form estimators and the bound
# --------------------------------------------------------------------------------------------
def latitude_seed(omega_b, f_b, omega: float = SEED_OMEGA, g: float = SEED_G):
    """Seed 000 (1.3)-(1.4) in specific-force form: ``φ = arcsin((ω·f)/(Ω g))``, rad."""
    omega_b = np.asarray(omega_b, dtype=float)
    f_b = np.asarray(f_b, dtype=float)
    s = np.sum(omega_b * f_b, axis=-1) / (omega * g)  # seed 000, (1.3) with f = -g
    return np.arcsin(np.clip(s, -1.0, 1.0))  # seed 000, (1.4)


def latitude_angle(omega_b, f_b):
    """``φ = atan2(ω·u, |ω×u|)``: 90° minus the angle between ω and f (seed 000 (1.1)), rad."""
    omega_b = np.asarray(omega_b, dtype=float)
    f_b = np.asarray(f_b, dtype=float)
    u = f_b / np.linalg.norm(f_b, axis=-1, keepdims=True)
    return np.arctan2(np.sum(omega_b * u, axis=-1), np.linalg.norm(np.cross(omega_b, u), axis=-1))


def cramer_rao_bound(arw, vrw, duration, g: float = G_STD, omega: float = OMEGA_EARTH):
    """Cramér–Rao bound of the latitude (rad, 1σ) for isotropic white sensor noise.

    Parameters
    ----------
    arw : float
        Angle random walk, rad/√s (rate noise density).
    vrw : float
        Velocity random walk, (m/s)/√s.
    duration : float
        Averaging time, s.

    Notes
    -----
    The mean rate has covariance ``ARW²/T · I``; only its component in the plane of ω and f,
    across ω, turns the angle: ``σ² = ARW²/(Ω² T)``. Likewise the tilt of f in that plane:
    ``VRW²/(g² T)``. Independent of latitude and orientation.
    """
    return np.sqrt((np.asarray(arw) / omega) ** 2 + (np.asarray(vrw) / g) ** 2) / np.sqrt(duration)


def time_to_accuracy(arw, vrw, sigma, g: float = G_STD, omega: float = OMEGA_EARTH):
    """Averaging time (s) for the Cramér–Rao bound to reach ``sigma`` (rad): the inverse of
    :func:`cramer_rao_bound`."""
    return ((np.asarray(arw) / omega) ** 2 + (np.asarray(vrw) / g) ** 2) / np.asarray(sigma) ** 2


def grade_table(lat=np.radians(45.0), duration=600.0):
    """Error budget of the single-position method per sensor grade (``selfnav.sensors``).

    For each grade: the noise bound after ``duration``, the bias-limited error (a horizontal
    gyro bias across the meridian does not matter; a vertical one gives ``b/(Ω cos φ)``, a
    north accelerometer bias ``b/g``, seed 000 (4.4)), and the time for the noise alone to reach
    0.01°. Angles in degrees, times in seconds.
    """
    from selfnav.sensors import GRADES

    rows = []
    for name, m in GRADES.items():
        arw = float(np.max(np.atleast_1d(m.gyro.white)))
        vrw = float(np.max(np.atleast_1d(m.accel.white)))
        bg = float(np.max(np.atleast_1d(m.gyro.bias)))
        ba = float(np.max(np.atleast_1d(m.accel.bias)))
        rows.append({
            "grade": m.name,
            "noise_deg": float(np.degrees(cramer_rao_bound(arw, vrw, duration))),
            "gyro_bias_limited_deg": float(np.degrees(bg / (OMEGA_EARTH * np.cos(lat)))),
            "accel_bias_limited_deg": float(np.degrees(ba / G_STD)),
            "time_to_0.01deg_s": float(time_to_accuracy(arw, vrw, np.radians(0.01))),
        })
    return rows


def latitude_gradient(omega_b, f_b):
    """Gradient of :func:`latitude_angle` with respect to ``(ω, f)``, shape ``(6,)``.

    For the delta-method variance ``σ² = ∇ᵀ Σ ∇`` of the mean vectors' covariance Σ.
    """
    w = np.asarray(omega_b, dtype=float)
    f = np.asarray(f_b, dtype=float)
    wn, fn = np.linalg.norm(w), np.linalg.norm(f)
    wh, fh = w / wn, f / fn
    c = float(np.clip(wh @ fh, -1.0, 1.0))  # sin φ
    cosphi = np.sqrt(max(1.0 - c * c, 1e-300))
    # φ = asin(ŵ·f̂); d(ŵ·f̂)/dw = (f̂ − c ŵ)/|w|
    dw = (fh - c * wh) / wn / cosphi
    df = (wh - c * fh) / fn / cosphi
    return np.concatenate([dw, df])


# --------------------------------------------------------------------------------------------
# Error model and requirements (seed 000 §4)
# --------------------------------------------------------------------------------------------
def latitude_error(omega_b, f_b, d_omega_b, d_f_b):
    """First-order latitude error from sensor errors, seed 000 (4.3) in specific-force form, rad.

    ``Δφ = (ω·Δf + f·Δω) / sqrt(Ω² g² − (ω·f)²)`` (the seed's sign with ``g = −f``).
    """
    w = np.asarray(omega_b, dtype=float)
    f = np.asarray(f_b, dtype=float)
    num = w @ np.asarray(d_f_b, dtype=float) + f @ np.asarray(d_omega_b, dtype=float)
    den = np.sqrt(max((w @ w) * (f @ f) - (w @ f) ** 2, 1e-300))  # seed 000, (4.3)
    return num / den


def requirements(dphi, lat, *, seed_constants: bool = False):
    """Gyro drift and accelerometer error that each produce a latitude error ``dphi``.

    Seed 000 (4.5) ``ΔΩ_z = Δφ Ω cos φ`` and (4.8) ``Δg = Δφ g cos φ``.

    Parameters
    ----------
    dphi : array_like
        Latitude error, rad.
    lat : float
        Latitude, rad.
    seed_constants : bool
        Reproduce the seed's printed table: it evidently used Ω = 15 °/h and converted radians
        to degrees with π = 3.14 (erratum, see docs/latitude.md).

    Returns
    -------
    dict with ``dphi_deg``, ``dphi_arcmin``, ``gyro_drift_deg_per_h``, ``accel_error_g``.
    """
    dphi = np.asarray(dphi, dtype=float)
    if seed_constants:
        rad2deg, omega_deg_h = 180.0 / 3.14, 15.0
    else:
        rad2deg, omega_deg_h = 180.0 / np.pi, OMEGA_EARTH / DEG_PER_H
    return {
        "dphi_deg": dphi * rad2deg,
        "dphi_arcmin": dphi * rad2deg * 60.0,
        "gyro_drift_deg_per_h": dphi * omega_deg_h * np.cos(lat),  # seed 000, (4.5)
        "accel_error_g": dphi * np.cos(lat),  # seed 000, (4.8) in units of g
    }


#: The first column of the seed's table, Δφ in degrees (rows 1, 2, 4, 6, 10, 20, 40 × the first).
SEED_TABLE_DPHI_DEG = 0.000449868 * np.array([1, 2, 4, 6, 10, 20, 40])


def requirements_table(dphi_deg, lat_deg: float = 60.0, *, seed_constants: bool = False):
    """The seed's requirements table from Δφ in degrees (edge function: degrees in and out).

    With ``seed_constants`` the degrees are converted with π = 3.14, as the seed evidently did.
    """
    dphi_deg = np.asarray(dphi_deg, dtype=float)
    pi = 3.14 if seed_constants else np.pi
    return requirements(dphi_deg * pi / 180.0, np.radians(lat_deg), seed_constants=seed_constants)


# --------------------------------------------------------------------------------------------
# The estimator on data
# --------------------------------------------------------------------------------------------
def latitude_confidence(sigma: float) -> str:
    """``"high"`` (σ ≤ 0.1°), ``"medium"`` (≤ 2°) or ``"low"``: how far a latitude σ lets a user
    trust the number (a record that does not determine the latitude has a σ of tens of
    degrees, capped at 90°)."""
    s = float(np.degrees(sigma))
    return "high" if s <= 0.1 else "medium" if s <= 2.0 else "low"


@dataclass
class LatitudeResult:
    """Result of a latitude estimate. Angles in rad; :meth:`to_dict` gives degrees."""

    latitude: float
    sigma: float
    sigma_noise: float
    heading: float
    pitch: float
    roll: float
    sigma_heading: float
    samples: int
    duration: float
    method: str
    omega_mean_b: np.ndarray
    f_mean_b: np.ndarray
    earth_rate_ratio: float
    earth_rate_ratio_sigma: float
    gravity_ratio: float
    disturbance_compensated: bool = False
    disturbance_detected: bool = False
    tilt_change: float = 0.0
    tilt_change_sigma: float = 0.0
    positions: int = 1
    gyro_bias_b: np.ndarray | None = None
    accel_bias_b: np.ndarray | None = None
    gyro_bias_sigma: np.ndarray | None = None
    accel_bias_sigma: np.ndarray | None = None
    warnings: list = field(default_factory=list)

    # degrees at the edge (DESIGN §2): the same numbers as to_dict()
    @property
    def latitude_deg(self) -> float:
        return float(np.degrees(self.latitude))

    lat_deg = latitude_deg

    @property
    def sigma_deg(self) -> float:
        return float(np.degrees(self.sigma))

    @property
    def sigma_noise_deg(self) -> float:
        return float(np.degrees(self.sigma_noise))

    @property
    def heading_deg(self) -> float:
        return float(np.degrees(self.heading))

    @property
    def sigma_heading_deg(self) -> float:
        return float(np.degrees(self.sigma_heading))

    @property
    def pitch_deg(self) -> float:
        return float(np.degrees(self.pitch))

    @property
    def roll_deg(self) -> float:
        return float(np.degrees(self.roll))

    @property
    def tilt_change_deg(self) -> float:
        return float(np.degrees(self.tilt_change))

    @property
    def computed(self) -> str:
        """What was computed, as ``to_dict()["method"]`` says it: ``"optimal"`` (the angle of
        the mean vectors, tilt-compensated where the rest was disturbed), ``"plain"`` (the same
        angle without the compensation on a record found disturbed: not optimal there),
        ``"seed"`` (formula (1.4)), ``"multiposition"``."""
        if self.positions > 1:
            return "multiposition"
        if self.method == "seed":
            return "seed"
        if self.disturbance_detected and not self.disturbance_compensated:
            return "plain"
        return "optimal"

    @property
    def estimate(self) -> str:
        """The estimate in words (the demo's and ``--json``'s ``estimate``)."""
        comp = ("tilt-compensated (disturbed rest)" if self.disturbance_compensated
                else "no tilt compensation")
        return {"multiposition": f"multi-position: {self.positions} positions solved jointly "
                                 "with the sensor biases",
                "seed": f"seed formula (1.4), {comp}",
                "plain": "plain: angle of the mean vectors, no tilt compensation although the "
                         "rest was disturbed",
                "optimal": f"optimal: angle of the mean vectors, {comp}"}[self.computed]

    def to_dict(self) -> dict:
        d = {
            "latitude_deg": np.degrees(self.latitude),
            "sigma_deg": np.degrees(self.sigma),
            "heading_deg": np.degrees(self.heading),
            "pitch_deg": np.degrees(self.pitch),
            "roll_deg": np.degrees(self.roll),
            "samples": self.samples,
            "duration_s": self.duration,
            "method": self.computed,
            "estimate": self.estimate,
            "rest": "disturbed" if self.disturbance_compensated else "still",
            "sigma_noise_deg": np.degrees(self.sigma_noise),
            "sigma_heading_deg": np.degrees(self.sigma_heading),
            "omega_mean_deg_per_h": self.omega_mean_b / DEG_PER_H,
            "f_mean_m_per_s2": self.f_mean_b,
            "earth_rate_ratio": self.earth_rate_ratio,
            "earth_rate_ratio_sigma": self.earth_rate_ratio_sigma,
            "gravity_ratio": self.gravity_ratio,
            "disturbance_compensated": self.disturbance_compensated,
            "tilt_change_deg": np.degrees(self.tilt_change),
            "positions": self.positions,
            "confidence": latitude_confidence(self.sigma),
            "warnings": list(self.warnings),
        }
        if self.gyro_bias_b is not None:
            d["gyro_bias_deg_per_h"] = self.gyro_bias_b / DEG_PER_H
            d["gyro_bias_sigma_deg_per_h"] = self.gyro_bias_sigma / DEG_PER_H
            d["accel_bias_ug"] = self.accel_bias_b / G_STD * 1e6
            d["accel_bias_sigma_ug"] = self.accel_bias_sigma / G_STD * 1e6
        return d


@njit(cache=True)
def _rest_stats(w, f, dt):  # pragma: no cover - compiled
    """One pass for the means, then one for the largest gyro-integrated excursion from the mean.

    Returns ``(w_mean, f_mean, w_var, fnorm_mean, fnorm_var, max_excursion)``.
    """
    n = w.shape[0]
    sw = np.zeros(3)
    sf = np.zeros(3)
    sww = np.zeros(3)
    sfn = 0.0
    sfn2 = 0.0
    for k in range(n):
        for i in range(3):
            sw[i] += w[k, i]
            sf[i] += f[k, i]
            sww[i] += w[k, i] * w[k, i]
        fn = np.sqrt(f[k, 0] ** 2 + f[k, 1] ** 2 + f[k, 2] ** 2)
        sfn += fn
        sfn2 += fn * fn
    wm = sw / n
    fm = sf / n
    wv = sww / n - wm * wm
    fnm = sfn / n
    fnv = sfn2 / n - fnm * fnm
    a0, a1, a2 = 0.0, 0.0, 0.0
    exc = 0.0
    for k in range(n):
        a0 += (w[k, 0] - wm[0]) * dt
        a1 += (w[k, 1] - wm[1]) * dt
        a2 += (w[k, 2] - wm[2]) * dt
        e = a0 * a0 + a1 * a1 + a2 * a2
        if e > exc:
            exc = e
    return wm, fm, wv, fnm, fnv, np.sqrt(exc)


#: Gyro white noise above which a gyro may be MEMS grade, °/√h: a tactical FOG has 0.012, a
#: MEMS 0.15-1 (the industrial ADIS16465 0.15; PX4's filtered consumer gyros ~0.6).
MEMS_ARW_DEG_PER_SQRT_H = 0.3
#: |mean ω| / Ω of Earth-rate data in deg/s read as rad/s (180/π).
DEG_PER_S_RATIO = 180.0 / np.pi


def _check_at_rest(imu, path):
    """Refuse wrong gyro units and data that are not at rest; return the plain means."""
    n = len(imu)
    w_mean, f_mean, w_var, _, fn_var, exc = _rest_stats(
        np.ascontiguousarray(imu.omega_ib_b), np.ascontiguousarray(imu.f_ib_b), imu.dt)
    ratio = np.linalg.norm(w_mean) / OMEGA_EARTH
    # a gyro noisier than any navigation or tactical gyro read in deg/s is a MEMS gyro, whose
    # bias alone is tens of Earth rates: its mean rate says nothing about units or turning
    arw = float(np.degrees(np.sqrt(np.median(np.clip(w_var, 0, None)) * imu.dt)) * 60.0)
    mems = arw > MEMS_ARW_DEG_PER_SQRT_H
    if abs(ratio / DEG_PER_S_RATIO - 1.0) < 0.03:     # the Earth rate in deg/s: 57.3 × Ω
        raise InputError(path, f"mean gyro rate is {ratio:.1f} × Earth rate: the gyros look like "
                         "deg/s, the file needs rad/s", column="wx")
    if 1.0e5 < ratio < 4.0e5:
        raise InputError(path, f"mean gyro rate is {ratio:.3g} × Earth rate: the gyros look like "
                         "deg/h, the file needs rad/s", column="wx")
    noise_allow = 5.0 * np.sqrt(np.sum(np.clip(w_var, 0, None))) / np.sqrt(max(n, 1))
    if mems and ratio > 5.0:
        warn(f"{path}: the gyros are noisy (white noise {arw:.2g} °/√h, MEMS grade) and their "
             f"mean rate is {ratio:.3g} × the Earth rate: a MEMS bias (or a slow turn, or "
             "deg/s) hides the Earth rate, so this record does not determine the latitude (its "
             "σ says so)")
    elif np.linalg.norm(w_mean) > 5.0 * OMEGA_EARTH + noise_allow:
        raise NotAtRestError(f"{path}: not at rest: the mean gyro rate is {ratio:.1f} × Earth rate "
                             f"({np.linalg.norm(w_mean) / DEG_PER_H:.4g} °/h); the unit is turning "
                             "(or the gyros are not in rad/s)")
    if exc > 5.0 * DEG:
        raise NotAtRestError(f"{path}: not at rest: the gyros show the unit turning by "
                             f"{np.degrees(exc):.1f}° during the record")
    m = max(n // 10, 1)
    fa, fb = imu.f_ib_b[:m].mean(axis=0), imu.f_ib_b[-m:].mean(axis=0)
    cosang = fa @ fb / (np.linalg.norm(fa) * np.linalg.norm(fb))
    tilt = np.arccos(np.clip(cosang, -1, 1))
    if tilt > 5.0 * DEG:
        raise NotAtRestError(f"{path}: not at rest: the gravity direction changed by "
                             f"{np.degrees(tilt):.1f}° between the start and end of the record")
    rms_dev = float(np.sqrt(max(fn_var, 0.0)))
    if rms_dev > 2.0:
        raise NotAtRestError(f"{path}: not at rest: |f| varies by {rms_dev:.2f} m/s² RMS "
                             "(the unit is accelerating)")
    return w_mean, f_mean


def _check_seed_solvable(imu, path) -> None:
    """Seed (1.4) needs ``|ω·f| < Ω g``: refuse, in one line, a record whose gyro errors push the
    ratio past 1 (the arcsine has no solution and the formula would print 90°)."""
    w, f = imu.omega_ib_b.mean(axis=0), imu.f_ib_b.mean(axis=0)
    s = float(w @ f / (SEED_OMEGA * SEED_G))
    if abs(s) >= 1.0:
        raise SelfnavError(f"{path}: the seed formula (1.4) has no solution on this record: "
                           f"(ω·f)/(Ω g) = {s:.4f}, beyond ±1 (gyro bias or scale errors larger "
                           "than the formula tolerates); use --method optimal")


def _blocks(n: int, n_blocks: int):
    edges = np.linspace(0, n, n_blocks + 1).astype(int)
    lab = np.repeat(np.arange(n_blocks), np.diff(edges))
    return lab


def _tilt_series(f_b, f_ref_unit):
    """Small tilt (rad, body axes) of each sample relative to the reference gravity direction."""
    fh = f_b / np.linalg.norm(f_b, axis=1, keepdims=True)
    return np.cross(fh, f_ref_unit)


@njit(cache=True)
def gyro_attitude(omega, dt):  # pragma: no cover - compiled
    """Cumulative attitude ``q_k = C_{b_k}^{b_0}`` (inertial) from rates, scalar-first quaternions.

    Rotation-vector update with the two-sample coning correction
    ``φ_k = ω_k Δt + (ω_{k−1} Δt × ω_k Δt) / 12``; ``q[0]`` is the identity, ``q[k]`` follows
    sample ``k − 1``. Summing rates instead would turn rocking (coning) into a false rate.
    """
    n = omega.shape[0]
    q = np.empty((n + 1, 4))
    q[0, 0], q[0, 1], q[0, 2], q[0, 3] = 1.0, 0.0, 0.0, 0.0
    px, py, pz = 0.0, 0.0, 0.0
    for k in range(n):
        ax, ay, az = omega[k, 0] * dt[k], omega[k, 1] * dt[k], omega[k, 2] * dt[k]
        cx = (py * az - pz * ay) / 12.0
        cy = (pz * ax - px * az) / 12.0
        cz = (px * ay - py * ax) / 12.0
        rx, ry, rz = ax + cx, ay + cy, az + cz
        px, py, pz = ax, ay, az
        th = np.sqrt(rx * rx + ry * ry + rz * rz)
        if th < 1e-3:  # series: error below th^6 / 46080
            t2 = th * th
            c, s = 1.0 - t2 / 8.0 + t2 * t2 / 384.0, 0.5 - t2 / 48.0 + t2 * t2 / 3840.0
        else:
            c, s = np.cos(th / 2.0), np.sin(th / 2.0) / th
        dw, dx, dy, dz = c, rx * s, ry * s, rz * s
        w0, x0, y0, z0 = q[k, 0], q[k, 1], q[k, 2], q[k, 3]
        w1 = w0 * dw - x0 * dx - y0 * dy - z0 * dz
        x1 = w0 * dx + x0 * dw + y0 * dz - z0 * dy
        y1 = w0 * dy - x0 * dz + y0 * dw + z0 * dx
        z1 = w0 * dz + x0 * dy - y0 * dx + z0 * dw
        nrm = np.sqrt(w1 * w1 + x1 * x1 + y1 * y1 + z1 * z1)
        q[k + 1, 0], q[k + 1, 1], q[k + 1, 2], q[k + 1, 3] = w1 / nrm, x1 / nrm, y1 / nrm, z1 / nrm
    return q


def _quat_conj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _sample_intervals(imu):
    return np.diff(imu.t, prepend=imu.t[0] - imu.dt)


def _batch_cov(x, m):
    """Covariance of a sum from its ``m`` block contributions ``x`` (rows), batch-means style."""
    return (x.T @ x) * m / max(m - 1, 1)


def _rate_estimates(imu, lab, n_blocks, compensate):
    """Earth rate in body axes, mean specific force, and their covariances from the data.

    ``still``: the rotation vector of each block's gyro-integrated attitude (coning-free), summed
    over the blocks and divided by the time. ``compensate``: the tilt ``a(t)`` seen by the
    accelerometers is taken out of the gyro attitude, ``Z(t) = R(t) exp(−[a(t)])``, and the Earth
    rate is the least-squares slope of ``Y(t) = rotvec(Ẑ_0ᵀ Z(t))`` (``Ẑ_0`` absorbs the initial
    tilt). The slope is a weighted sum of the increments of Y; its covariance is the sum over
    blocks of the weighted residual increments (a batch-means estimate that stays valid for the
    random-walk character of Y and for slowly correlated noise).

    Returns ``(w, cov_w, f, cov_f)``.
    """
    w, f = imu.omega_ib_b, imu.f_ib_b
    dt = _sample_intervals(imu)
    cnt = np.bincount(lab, minlength=n_blocks).astype(float)
    f_sum = np.stack([np.bincount(lab, f[:, k], n_blocks) for k in range(3)], 1)
    f_full = f_sum.sum(0) / cnt.sum()
    fb = f_sum / cnt[:, None]
    cov_f = _batch_cov((fb - f_full) * (cnt / cnt.sum())[:, None], n_blocks)
    q = gyro_attitude(np.ascontiguousarray(w), np.ascontiguousarray(dt))
    if not compensate:
        edges = np.concatenate([[0], np.cumsum(np.bincount(lab, minlength=n_blocks))])
        rho = att.quat_to_rotvec(att.quat_multiply(_quat_conj(q[edges[:-1]]), q[edges[1:]]))
        Tb = np.bincount(lab, dt, n_blocks)
        w_full = rho.sum(0) / Tb.sum()
        cov_w = _batch_cov((rho - np.outer(Tb, w_full)) / Tb.sum(), n_blocks)
        return w_full, cov_w, f_full, cov_f
    f_ref = f_full / np.linalg.norm(f_full)
    a = _tilt_series(f, f_ref)
    Z = att.quat_multiply(q[1:], _quat_conj(att.rotvec_to_quat(a)))
    t = imu.t - imu.t[0]
    c = (t - t.mean()) / np.sum((t - t.mean()) ** 2)  # slope = Σ c_k Y_k
    Z0 = Z[0]
    for _ in range(3):  # Ẑ_0 = mean of Z(t) exp(−[ω t]), then the slope again
        Y = att.quat_to_rotvec(att.quat_multiply(_quat_conj(Z0), Z))
        w_full = c @ Y
        qe = att.quat_multiply(Z, _quat_conj(att.rotvec_to_quat(t[:, None] * w_full)))
        qe = qe * np.sign(qe @ qe[0])[:, None]
        Z0 = qe.mean(0)
        Z0 = Z0 / np.linalg.norm(Z0)
    # Noise of Y: a random walk (gyro noise, density q) plus white noise (tilt noise, σ_w²).
    # The tilt noise hides the random walk at short lags, so fit the structure function of the
    # L-sample moving average of Y at lag L (the modified-Allan idea): D(L) ≈ (2/3) q L Δt + 2σ_w²/L.
    # The slope is Σ_i W_i ΔY_i with W_i = Σ_{k≥i} c_k: var = q Σ W_i² Δt_i + σ_w² Σ c_k².
    n = len(t)
    dtm = float(np.mean(np.diff(t)))
    resid = Y - t[:, None] * w_full
    cs = np.vstack([np.zeros(3), np.cumsum(resid, axis=0)])
    lags = np.unique(np.geomspace(1, max(n // 8, 2), 20).astype(int))
    D = []
    for L in lags:
        ma = (cs[L:] - cs[:-L]) / L
        D.append(np.mean((ma[L:] - ma[:-L]) ** 2, axis=0))
    D = np.array(D)
    A = np.column_stack([2.0 / 3.0 * lags * dtm, 2.0 / lags])
    W = np.cumsum(c[::-1])[::-1][1:]
    sW2 = np.sum(W * W * np.diff(t))
    var = np.empty(3)
    for k in range(3):
        wts = 1.0 / D[:, k]
        sol, *_ = np.linalg.lstsq(A * wts[:, None], D[:, k] * wts, rcond=None)
        qd, sw2 = max(sol[0], 0.0), max(sol[1], 0.0)
        var[k] = qd * sW2 + sw2 * np.sum(c * c)
    cov_w = np.diag(var)
    return w_full, cov_w, f_full, cov_f


def _delta_sigma(fn, x, cov, eps=1e-7):
    """Standard deviation of ``fn(x)`` by the delta method with a numerical gradient."""
    x = np.asarray(x, dtype=float)
    f0 = fn(x)
    grad = np.empty(len(x))
    for i in range(len(x)):
        h = eps * max(abs(x[i]), 1e-12) if x[i] != 0 else eps
        xp = x.copy()
        xp[i] += h
        d = fn(xp) - f0
        if np.ndim(d) == 0 and abs(d) > np.pi:  # angle wrap
            d = np.angle(np.exp(1j * d))
        grad[i] = d / h
    return float(np.sqrt(max(grad @ cov @ grad, 0.0)))


def _tilt_change(imu, lab, n_blocks):
    """Tilt change between the first and last tenth of the record and its standard error."""
    n = len(imu)
    m = max(n // 10, 2)
    f = imu.f_ib_b
    fr = f.mean(0)
    fr = fr / np.linalg.norm(fr)
    th0, th1 = _tilt_series(f[:m], fr), _tilt_series(f[-m:], fr)
    d = th1.mean(0) - th0.mean(0)
    # noise of the tilt means from the scatter of 10 sub-means in each tenth
    def se(x):
        k = max(min(10, len(x) // 2), 2)
        sub = np.array([c.mean(0) for c in np.array_split(x, k)])
        return sub.std(0, ddof=1) / np.sqrt(k)

    s = np.sqrt(se(th0) ** 2 + se(th1) ** 2)
    return d, s


#: |mean ω| / Ω − 1 below this is no gyro error worth a warning (1 ppm of the Earth rate,
#: 1.5e-5 °/h: the rounding of a file's digits, not a sensor)
RATIO_FLOOR = 1e-6
#: |mean f| may differ from normal gravity by this (anomaly, unknown height) besides its noise
GRAVITY_TOLERANCE = 5e-4
#: false-alarm probability of the Earth-rate and gravity checks (two-sided)
CHECK_FALSE_ALARM = 1e-3


def _t_quantile(dof: int) -> float:
    """Two-sided :data:`CHECK_FALSE_ALARM` quantile of Student's t with ``dof`` degrees of
    freedom: the σ of the checks comes from the blocks' own scatter, so it is itself uncertain
    (3.88 for 19 dof, where a 3σ normal test would warn on 0.7 % of clean records)."""
    from scipy.stats import t as student_t

    return float(student_t.ppf(1.0 - CHECK_FALSE_ALARM / 2.0, max(int(dof), 1)))


def disturbance_matters(tilt: float, tilt_sigma: float, duration: float, cov_w) -> bool:
    """Is a tilt change between the first and last tenth of a record a disturbance to
    compensate?

    Two conditions: it stands out of the accelerometer's white noise (4σ), and it moves the
    Earth-rate estimate by more than the gyro noise does — a tilt ``Δθ`` over ``T`` reads as a
    rate ``Δθ/T`` to the gyros, compared with twice the RMS σ ``cov_w`` of the compensated
    rate estimate (the still estimate's batch σ would count the disturbance as noise). Below
    that the compensation cannot improve the estimate, and an accelerometer's
    bias instability explains the "tilt" as well (a navigation-grade IMU that never moved shows
    1–2″ at 7–22σ of its white noise over 10 minutes, 0.003 °/h of rate against a noise of
    0.005 °/h); a real disturbance (the Xi'an vehicle's 0.2°, the rocking tests' 650″) passes
    both by orders of magnitude.
    """
    if not tilt > 4.0 * tilt_sigma:
        return False
    noise_w = float(np.sqrt(max(np.trace(np.asarray(cov_w)) / 3.0, 0.0)))
    return tilt / max(duration, 1e-9) > 2.0 * noise_w


def estimate_latitude(imu, *, method: str = "optimal", rest: str = "auto", h: float | None = None,
                      n_blocks: int = 20) -> LatitudeResult:
    """Latitude, heading, pitch and roll from one static record (seed 000).

    Parameters
    ----------
    imu : ImuData
    method : {"optimal", "seed"}
        ``seed`` is formula (1.4) with Ω = 15.041 °/h, g = 9.81; ``optimal`` the angle between the
        measured vectors (module docstring).
    rest : {"auto", "still", "disturbed"}
        ``disturbed`` removes tilt changes seen by the accelerometers from the gyro mean; ``auto``
        does so when the tilt change between the first and last tenth of the record matters
        (:func:`disturbance_matters`: beyond four times its noise, and larger, as a rate, than
        the gyro noise).
    h : float, optional
        Height above the ellipsoid for the gravity check, m (default: the file's, else 0).
    n_blocks : int
        Blocks for the jackknife standard error (sigma from the data's own scatter).
    """
    path = imu.source or "IMU data"
    if method not in ("optimal", "seed"):
        raise SelfnavError(f"unknown latitude method '{method}' (use optimal or seed)")
    if rest not in ("auto", "still", "disturbed"):
        raise SelfnavError(f"unknown rest mode '{rest}' (use auto, still or disturbed)")
    imu = longest_stretch(imu, "the latitude estimate")
    n = len(imu)
    if n < 100:
        raise InputError(path, f"{n} samples: the latitude method needs at least 100 samples "
                         "at rest (a few seconds)")
    _check_at_rest(imu, path)
    check_rest_units(imu, path)
    if method == "seed":
        _check_seed_solvable(imu, path)
    nb = int(min(n_blocks, n // 50))
    nb = max(nb, 2)
    lab = _blocks(n, nb)
    dtilt, dtilt_s = _tilt_change(imu, lab, nb)
    tilt_mag = float(np.linalg.norm(dtilt))
    tilt_sig = float(np.linalg.norm(dtilt_s))
    still = _rate_estimates(imu, lab, nb, False)
    comp = _rate_estimates(imu, lab, nb, True) if (
        rest == "disturbed" or tilt_mag > 4.0 * tilt_sig) else None
    detected = comp is not None and disturbance_matters(tilt_mag, tilt_sig, imu.duration,
                                                        comp[1])
    compensate = rest == "disturbed" or (rest == "auto" and detected)
    w_full, cov_w, f_full, cov_f = comp if compensate else still
    tq = _t_quantile(nb - 1)
    warnings = []
    if compensate:
        warnings.append(f"disturbed rest: the tilt changed by {np.degrees(tilt_mag) * 3600:.0f}″ "
                        f"({tilt_mag / max(tilt_sig, 1e-300):.0f}σ) during the record; the gyro "
                        "attitude was compensated with the accelerometer tilt")
    fn = latitude_seed if method == "seed" else latitude_angle
    x = np.concatenate([w_full, f_full])
    cov = np.zeros((6, 6))
    cov[:3, :3], cov[3:, 3:] = cov_w, cov_f
    lat = float(fn(w_full, f_full))
    sigma_noise = _delta_sigma(lambda v: float(fn(v[:3], v[3:])), x, cov)
    C_nb = att.triad_nb(f_full, w_full)
    roll, pitch, heading = (float(v) for v in att.euler_from_dcm_nb(C_nb))
    sig_heading = _delta_sigma(lambda v: float(att.euler_from_dcm_nb(att.triad_nb(v[3:], v[:3]))[2]),
                               x, cov)

    # honest sigma: widen for sensor errors the noise cannot explain
    wnorm = float(np.linalg.norm(w_full))
    ratio = wnorm / OMEGA_EARTH
    ratio_sig = float(np.sqrt(w_full @ cov_w @ w_full)) / wnorm / OMEGA_EARTH
    hh = imu.meta.get("h0_m", 0.0) if h is None else h
    g_normal = float(normal_gravity(lat, hh))
    gratio = float(np.linalg.norm(f_full) / g_normal)
    gratio_sig = float(np.sqrt(max(f_full @ cov_f @ f_full, 0.0))) / np.linalg.norm(f_full) / g_normal
    sigma2 = sigma_noise**2
    if abs(ratio - 1.0) > max(tq * ratio_sig, RATIO_FLOOR):
        sigma2 += (ratio - 1.0) ** 2
        # the same unexplained rate, horizontal, turns the gyrocompass heading by up to
        # (ratio − 1)/cos φ rad
        sig_heading = float(min(np.hypot(sig_heading, (ratio - 1.0) / max(np.cos(lat), 1e-3)),
                                np.pi))
        warnings.append(f"|mean ω| is {100 * (ratio - 1):+.2f}% off Earth rate "
                        f"({abs(ratio - 1) / max(ratio_sig, 1e-300):.0f}σ of its noise): gyro bias "
                        f"or scale error; sigma widened by {np.degrees(abs(ratio - 1)):.3f}°")
    # |f| may differ from normal gravity by anomaly and unknown height (allow 0.05 %), and
    # by the noise of the mean specific force
    if abs(gratio - 1.0) > GRAVITY_TOLERANCE + tq * gratio_sig:
        sigma2 += (gratio - 1.0) ** 2
        warnings.append(f"|mean f| is {100 * (gratio - 1):+.3f}% off normal gravity: accelerometer "
                        f"bias or scale error (or a wrong height); sigma widened by "
                        f"{np.degrees(abs(gratio - 1)):.3f}°")
    if method == "seed":
        # the seed's fixed constants: its formula is off by the norm mismatch itself
        sigma2 += (np.tan(lat) * ((wnorm / SEED_OMEGA) * (np.linalg.norm(f_full) / SEED_G) - 1.0)) ** 2
    if abs(lat) > 85.0 * DEG:
        warnings.append("near the pole the heading is poorly defined")
    # a first-order σ beyond 90° says only that the record does not determine the latitude
    sigma = float(min(np.sqrt(sigma2), np.pi / 2))
    if sigma > 10.0 * DEG:
        warnings.append(f"σ {np.degrees(sigma):.1f}°: this record hardly determines the latitude")
    for w in warnings:
        warn(f"{path}: {w}")
    return LatitudeResult(
        latitude=lat, sigma=sigma, sigma_noise=sigma_noise,
        heading=heading, pitch=pitch, roll=roll, sigma_heading=sig_heading,
        samples=n, duration=imu.duration, method=method,
        omega_mean_b=w_full, f_mean_b=f_full, earth_rate_ratio=ratio,
        earth_rate_ratio_sigma=ratio_sig, gravity_ratio=gratio,
        disturbance_compensated=bool(compensate), disturbance_detected=bool(detected),
        tilt_change=tilt_mag,
        tilt_change_sigma=tilt_sig, warnings=warnings,
    )


def error_budget(result: LatitudeResult, gyro_bias: float = 0.005 * DEG_PER_H,
                 accel_bias: float = 50e-6 * G_STD) -> dict:
    """Latitude error per sensor error for a measured record (seed 000 (4.3)), rad.

    Each gyro axis with a bias ``gyro_bias`` (rad/s) and each accelerometer with ``accel_bias``
    (m/s²), one at a time, with the record's own mean vectors; plus the measured noise.
    """
    w, f = result.omega_mean_b, result.f_mean_b
    out = {}
    for k, ax in enumerate("xyz"):
        e = np.zeros(3)
        e[k] = 1.0
        out[f"gyro_{ax}"] = float(latitude_error(w, f, e * gyro_bias, np.zeros(3)))
        out[f"accel_{ax}"] = float(latitude_error(w, f, np.zeros(3), e * accel_bias))
    out["noise"] = result.sigma_noise
    out["rss"] = float(np.sqrt(sum(v**2 for v in out.values())))
    return out


# --------------------------------------------------------------------------------------------
# Multi-position
# --------------------------------------------------------------------------------------------
def estimate_latitude_multiposition(imu, *, gyro_bias_prior: float = 1.0 * DEG_PER_H,
                                    accel_bias_prior: float = 10e-3 * G_STD,
                                    h: float | None = None) -> LatitudeResult:
    """Latitude with gyro and accelerometer biases from 2-12 static positions.

    Model per position p (seed 000 (2.2)-(2.3) plus constant biases)::

        ω̄_p = C_p Ω_n(φ) + b_g,     f̄_p = C_p (0, 0, g) + b_a

    with the attitude ``C_p`` of each position free, Earth rate Ω known, and g tied to normal
    gravity by a weak prior. Weighted least squares over φ, g, b_g, b_a and the attitudes, with
    weak priors on the biases (for the components a set of positions cannot separate); the
    parameter covariance is the Cramér–Rao bound of this model. Turns about the vertical alone
    leave the vertical biases to the Earth-rate magnitude: then the latitude comes from the radius
    of the circle the horizontal Earth rate draws, weak near the equator.
    """
    from scipy.optimize import least_squares

    path = imu.source or "IMU data"
    if imu.position is None:
        raise InputError(path, "multi-position data need a 'position' column or several files")
    ids = np.unique(imu.position)
    P = len(ids)
    if not 2 <= P <= 12:
        raise InputError(path, f"{P} positions: the multi-position method takes 2 to 12",
                         column="position")
    W, F, SW, SF, parts = [], [], [], [], []
    for p in ids:
        part = imu.select(imu.position == p)
        part.source = f"{path} (position {p})"
        part = longest_stretch(part, f"position {p}")
        if len(part) < 100:
            raise InputError(path, f"position {p} has {len(part)} samples; at least 100 are needed",
                             column="position")
        _check_at_rest(part, part.source)
        n = len(part)
        nb = max(min(20, n // 50), 2)
        lab = _blocks(n, nb)
        w_full, cov_w, f_full, cov_f = _rate_estimates(part, lab, nb, False)
        W.append(w_full)
        F.append(f_full)
        # per-axis standard errors from the block scatter, floored by the white-noise value
        SW.append(np.maximum(np.sqrt(np.diag(cov_w)), part.omega_ib_b.std(0) / np.sqrt(n)))
        SF.append(np.maximum(np.sqrt(np.diag(cov_f)), part.f_ib_b.std(0) / np.sqrt(n)))
        parts.append(part)
    W, F, SW, SF = map(np.asarray, (W, F, SW, SF))
    lat0 = float(np.median(latitude_angle(W, F)))
    C0 = att.triad_nb(F, W)
    hh = (imu.meta.get("h0_m", 0.0) if h is None else h)
    g0 = float(np.mean(np.linalg.norm(F, axis=1)))

    def unpack(x):
        return x[0], x[1], x[2:5], x[5:8], x[8:].reshape(P, 3)

    def residuals(x):
        lat, g, bg, ba, dth = unpack(x)
        C = np.swapaxes(att.rotvec_to_dcm(dth), -1, -2) @ C0  # C_p = exp(-[δθ_p]) C_p0
        om_n = np.array([0.0, OMEGA_EARTH * np.cos(lat), OMEGA_EARTH * np.sin(lat)])
        rw = (C @ om_n + bg - W) / SW
        rf = (C @ np.array([0.0, 0.0, g]) + ba - F) / SF
        prior = np.concatenate([bg / gyro_bias_prior, ba / accel_bias_prior,
                                [(g - normal_gravity(lat, hh)) / 0.02]])
        return np.concatenate([rw.ravel(), rf.ravel(), prior])

    x0 = np.concatenate([[lat0, g0], np.zeros(6), np.zeros(3 * P)])
    sol = least_squares(residuals, x0, method="lm", x_scale="jac", xtol=1e-14, ftol=1e-14)
    J = sol.jac
    cov = np.linalg.pinv(J.T @ J)
    chi2 = float(np.sum(sol.fun[:6 * P] ** 2))
    scale = max(1.0, chi2 / max(6 * P - (len(x0) - 9), 1)) if 6 * P > len(x0) - 9 else 1.0
    lat, g, bg, ba, dth = unpack(sol.x)
    sd = np.sqrt(np.diag(cov) * scale)
    warnings = []
    if scale > 4.0:
        warnings.append(f"the positions disagree with the model (χ²/dof = {scale:.1f}): "
                        "moving between positions, or scale errors; sigma widened")
    for w in warnings:
        warn(f"{path}: {w}")
    C1 = np.swapaxes(att.rotvec_to_dcm(dth[0]), -1, -2) @ C0[0]
    roll, pitch, heading = (float(v) for v in att.euler_from_dcm_nb(C1))
    n_all = len(imu)
    ratio = float(np.mean(np.linalg.norm(W - bg, axis=1)) / OMEGA_EARTH)
    return LatitudeResult(
        latitude=float(lat), sigma=float(sd[0]), sigma_noise=float(np.sqrt(cov[0, 0])),
        heading=heading, pitch=pitch, roll=roll, sigma_heading=float(np.sqrt(sd[10] ** 2 + sd[8] ** 2)),
        samples=n_all, duration=float(sum(p.duration for p in parts)), method="multiposition",
        omega_mean_b=W[0], f_mean_b=F[0], earth_rate_ratio=ratio, earth_rate_ratio_sigma=float("nan"),
        gravity_ratio=float(g / normal_gravity(lat, hh)), positions=P,
        gyro_bias_b=bg, accel_bias_b=ba, gyro_bias_sigma=sd[2:5], accel_bias_sigma=sd[5:8],
        warnings=warnings,
    )


__all__ = [
    "latitude_seed", "latitude_angle", "cramer_rao_bound", "latitude_gradient", "latitude_error",
    "requirements", "requirements_table", "time_to_accuracy", "grade_table", "estimate_latitude", "estimate_latitude_multiposition", "error_budget",
    "LatitudeResult", "SEED_TABLE_DPHI_DEG", "asdict",
]
