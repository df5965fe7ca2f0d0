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

from selfnav import attitude as att
from selfnav.earth import OMEGA_EARTH, normal_gravity
from selfnav.errors import InputError, NotAtRestError, SelfnavError

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
    tilt_change: float = 0.0
    tilt_change_sigma: float = 0.0
    positions: int = 1
    gyro_bias_b: np.ndarray | None = None
    accel_bias_b: np.ndarray | None = None
    gyro_bias_sigma: np.ndarray | None = None
    accel_bias_sigma: np.ndarray | None = None
    warnings: list = field(default_factory=list)

    def to_dict(self) -> dict:
        d = {
            "latitude_deg": np.degrees(self.latitude),
            "sigma_deg": np.degrees(self.sigma),
            "heading_deg": np.degrees(self.heading),
            "pitch_deg": np.degrees(self.pitch),
            "roll_deg": np.degrees(self.roll),
            "samples": self.samples,
            "duration_s": self.duration,
            "method": self.method,
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
            "warnings": list(self.warnings),
        }
        if self.gyro_bias_b is not None:
            d["gyro_bias_deg_per_h"] = self.gyro_bias_b / DEG_PER_H
            d["gyro_bias_sigma_deg_per_h"] = self.gyro_bias_sigma / DEG_PER_H
            d["accel_bias_ug"] = self.accel_bias_b / G_STD * 1e6
            d["accel_bias_sigma_ug"] = self.accel_bias_sigma / G_STD * 1e6
        return d


def _check_at_rest(imu, path):
    """Refuse wrong gyro units and data that are not at rest; return the plain means."""
    n = len(imu)
    w_mean = imu.omega_ib_b.mean(axis=0)
    f_mean = imu.f_ib_b.mean(axis=0)
    ratio = np.linalg.norm(w_mean) / OMEGA_EARTH
    if 30.0 < ratio < 90.0:
        raise InputError(path, f"mean gyro rate is {ratio:.1f} × Earth rate: the gyros look like "
                         "deg/s, the file needs rad/s", column="wx")
    if 1.0e5 < ratio < 4.0e5:
        raise InputError(path, f"mean gyro rate is {ratio:.3g} × Earth rate: the gyros look like "
                         "deg/h, the file needs rad/s", column="wx")
    w_std = imu.omega_ib_b.std(axis=0)
    noise_allow = 5.0 * np.linalg.norm(w_std) / np.sqrt(max(n, 1))
    if np.linalg.norm(w_mean) > 5.0 * OMEGA_EARTH + noise_allow:
        raise NotAtRestError(f"{path}: not at rest: the mean gyro rate is {ratio:.1f} × Earth rate "
                             f"({np.linalg.norm(w_mean) / DEG_PER_H:.4g} °/h); the unit is turning "
                             "(or the gyros are not in rad/s)")
    # rotation accumulated by the gyros after removing their mean
    ang = np.cumsum(imu.omega_ib_b - w_mean, axis=0) * imu.dt
    exc = float(np.max(np.linalg.norm(ang - ang[0], axis=1)))
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
    fn = np.linalg.norm(imu.f_ib_b, axis=1)
    rms_dev = float(np.sqrt(np.mean((fn - fn.mean()) ** 2)))
    if rms_dev > 2.0:
        raise NotAtRestError(f"{path}: not at rest: |f| varies by {rms_dev:.2f} m/s² RMS "
                             "(the unit is accelerating)")
    return w_mean, f_mean


def _blocks(n: int, n_blocks: int):
    edges = np.linspace(0, n, n_blocks + 1).astype(int)
    lab = np.repeat(np.arange(n_blocks), np.diff(edges))
    return lab


def _tilt_series(f_b, f_ref_unit):
    """Small tilt (rad, body axes) of each sample relative to the reference gravity direction."""
    fh = f_b / np.linalg.norm(f_b, axis=1, keepdims=True)
    return np.cross(fh, f_ref_unit)


def _jackknife(values_full, values_deleted):
    """Delete-one-block jackknife standard error, vectorized over trailing dims."""
    m = values_deleted.shape[0]
    mean = values_deleted.mean(axis=0)
    var = (m - 1) / m * np.sum((values_deleted - mean) ** 2, axis=0)
    return np.sqrt(var)


def _rate_estimates(imu, lab, n_blocks, compensate):
    """Mean rate (plain or tilt-compensated) for the full record and each block deletion.

    Returns ``(w_full, f_full, w_del, f_del)`` with ``w_del`` of shape ``(n_blocks, 3)``.
    """
    w, f = imu.omega_ib_b, imu.f_ib_b
    cnt = np.bincount(lab, minlength=n_blocks).astype(float)
    f_sum = np.stack([np.bincount(lab, f[:, k], n_blocks) for k in range(3)], 1)
    f_full = f_sum.sum(0) / cnt.sum()
    f_del = (f_sum.sum(0) - f_sum) / (cnt.sum() - cnt)[:, None]
    if not compensate:
        w_sum = np.stack([np.bincount(lab, w[:, k], n_blocks) for k in range(3)], 1)
        return w_sum.sum(0) / cnt.sum(), f_full, (w_sum.sum(0) - w_sum) / (cnt.sum() - cnt)[:, None], f_del
    # least-squares slope of Y(t) = ∫ω dt − θ_tilt(t): the rate with the tilt changes removed
    dt = np.diff(imu.t, prepend=imu.t[0] - imu.dt)
    G = np.cumsum(w * dt[:, None], axis=0)
    Y = G - _tilt_series(f, f_full / np.linalg.norm(f_full))
    t = imu.t - imu.t[0]
    S = lambda x: np.bincount(lab, x, n_blocks)  # noqa: E731
    St, Stt = S(t), S(t * t)
    SY = np.stack([S(Y[:, k]) for k in range(3)], 1)
    StY = np.stack([S(t * Y[:, k]) for k in range(3)], 1)

    def slope(n, st, stt, sy, sty):
        n, st, stt = (np.asarray(v, dtype=float)[..., None] for v in (n, st, stt))
        return (n * sty - st * sy) / (n * stt - st * st)

    w_full = slope(cnt.sum(), St.sum(), Stt.sum(), SY.sum(0), StY.sum(0))
    w_del = slope(cnt.sum() - cnt, St.sum() - St, Stt.sum() - Stt, SY.sum(0) - SY, StY.sum(0) - StY)
    return w_full, f_full, w_del, f_del


def _tilt_change(imu, lab, n_blocks):
    """Tilt change between the first and last tenth of the record and its standard error."""
    n = len(imu)
    m = max(n // 10, 2)
    f = imu.f_ib_b
    fr = f.mean(0)
    fr = fr / np.linalg.norm(fr)
    th = _tilt_series(f, fr)
    d = th[-m:].mean(0) - th[:m].mean(0)
    # noise of the tilt means from the scatter of 10 sub-means in each tenth
    def se(x):
        k = max(min(10, len(x) // 2), 2)
        sub = np.array([c.mean(0) for c in np.array_split(x, k)])
        return sub.std(0, ddof=1) / np.sqrt(k)

    s = np.sqrt(se(th[:m]) ** 2 + se(th[-m:]) ** 2)
    return d, s


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
        does so when the tilt change between the first and last tenth of the record exceeds four
        times its noise.
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
    n = len(imu)
    if n < 100:
        raise InputError(path, f"{n} samples: the latitude method needs at least 100 samples "
                         "at rest (a few seconds)")
    _check_at_rest(imu, path)
    nb = int(min(n_blocks, n // 50))
    nb = max(nb, 2)
    lab = _blocks(n, nb)
    dtilt, dtilt_s = _tilt_change(imu, lab, nb)
    tilt_mag = float(np.linalg.norm(dtilt))
    tilt_sig = float(np.linalg.norm(dtilt_s))
    compensate = rest == "disturbed" or (rest == "auto" and tilt_mag > 4.0 * tilt_sig)
    w_full, f_full, w_del, f_del = _rate_estimates(imu, lab, nb, compensate)
    warnings = []
    if compensate:
        warnings.append(f"disturbed rest: the tilt changed by {np.degrees(tilt_mag) * 3600:.0f}″ "
                        f"({tilt_mag / max(tilt_sig, 1e-300):.0f}σ) during the record; the gyro "
                        "mean was compensated with the accelerometer tilt")

    if method == "seed":
        fn = latitude_seed
    else:
        fn = latitude_angle
    lat = float(fn(w_full, f_full))
    lat_del = fn(w_del, f_del)
    sigma_noise = float(_jackknife(lat, lat_del))
    C_nb = att.triad_nb(f_full, w_full)
    roll, pitch, heading = (float(x) for x in att.euler_from_dcm_nb(C_nb))
    hd = att.euler_from_dcm_nb(att.triad_nb(f_del, w_del))[2]
    hd = np.angle(np.exp(1j * (hd - heading)))
    sig_heading = float(_jackknife(0.0, hd))

    # honest sigma: widen for sensor errors the noise cannot explain
    wnorm = float(np.linalg.norm(w_full))
    ratio = wnorm / OMEGA_EARTH
    ratio_sig = float(_jackknife(ratio, np.linalg.norm(w_del, axis=1) / OMEGA_EARTH))
    hh = imu.meta.get("h0_m", 0.0) if h is None else h
    g_normal = float(normal_gravity(lat, hh))
    gratio = float(np.linalg.norm(f_full) / g_normal)
    sigma2 = sigma_noise**2
    if abs(ratio - 1.0) > 3.0 * ratio_sig:
        sigma2 += (ratio - 1.0) ** 2
        warnings.append(f"|mean ω| is {100 * (ratio - 1):+.2f}% off Earth rate "
                        f"({abs(ratio - 1) / max(ratio_sig, 1e-300):.0f}σ of its noise): gyro bias "
                        f"or scale error; sigma widened by {np.degrees(abs(ratio - 1)):.3f}°")
    # |f| may differ from normal gravity by anomaly and unknown height: allow 0.05 %
    if abs(gratio - 1.0) > 5e-4:
        sigma2 += (gratio - 1.0) ** 2
        warnings.append(f"|mean f| is {100 * (gratio - 1):+.3f}% off normal gravity: accelerometer "
                        f"bias or scale error (or a wrong height); sigma widened by "
                        f"{np.degrees(abs(gratio - 1)):.3f}°")
    if method == "seed":
        # the seed's fixed constants: its formula is off by the norm mismatch itself
        sigma2 += (np.tan(lat) * ((wnorm / SEED_OMEGA) * (np.linalg.norm(f_full) / SEED_G) - 1.0)) ** 2
    if abs(lat) > 85.0 * DEG:
        warnings.append("near the pole the heading is poorly defined")
    return LatitudeResult(
        latitude=lat, sigma=float(np.sqrt(sigma2)), sigma_noise=sigma_noise,
        heading=heading, pitch=pitch, roll=roll, sigma_heading=sig_heading,
        samples=n, duration=imu.duration, method=method,
        omega_mean_b=w_full, f_mean_b=f_full, earth_rate_ratio=ratio,
        earth_rate_ratio_sigma=ratio_sig, gravity_ratio=gratio,
        disturbance_compensated=bool(compensate), tilt_change=tilt_mag,
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
        if len(part) < 100:
            raise InputError(path, f"position {p} has {len(part)} samples; at least 100 are needed",
                             column="position")
        _check_at_rest(part, part.source)
        n = len(part)
        nb = max(min(20, n // 50), 2)
        lab = _blocks(n, nb)
        w_full, f_full, w_del, f_del = _rate_estimates(part, lab, nb, False)
        W.append(w_full)
        F.append(f_full)
        # per-axis standard errors from the block scatter, floored by the white-noise value
        SW.append(np.maximum(_jackknife(w_full, w_del), part.omega_ib_b.std(0) / np.sqrt(n)))
        SF.append(np.maximum(_jackknife(f_full, f_del), part.f_ib_b.std(0) / np.sqrt(n)))
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
    dof = max(len(sol.fun) - len(x0), 1)
    chi2 = float(np.sum(sol.fun[:6 * P] ** 2))
    scale = max(1.0, chi2 / max(6 * P - (len(x0) - 9), 1)) if 6 * P > len(x0) - 9 else 1.0
    lat, g, bg, ba, dth = unpack(sol.x)
    sd = np.sqrt(np.diag(cov) * scale)
    warnings = []
    if scale > 4.0:
        warnings.append(f"the positions disagree with the model (χ²/dof = {scale:.1f}): "
                        "moving between positions, or scale errors; sigma widened")
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
    "requirements", "requirements_table", "estimate_latitude", "estimate_latitude_multiposition", "error_budget",
    "LatitudeResult", "SEED_TABLE_DPHI_DEG", "asdict",
]
