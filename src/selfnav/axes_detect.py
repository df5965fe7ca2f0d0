"""Detection of an IMU's axes from its data (issue 20): the up axis from gravity, the forward axis
and the fine yaw mounting from the GNSS accelerations on a vehicle (:mod:`selfnav.axes` holds the
notation these return in).

Pure functions of whatever window of samples they are given, so that a causal navigator can
call them on its first seconds; each returns what it found with a σ and a confidence, and
:func:`compare_frames` says in one line where a given frame disagrees with a detected one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from selfnav.axes import AxesError, ImuFrame, axes_from_matrix, axis_label
from selfnav.earth import radii
from selfnav.errors import SelfnavError
from selfnav.types import GnssData, ImuData


# --------------------------------------------------------------------------- detection: up
def _phi(x):
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def _block_means(x, n_blocks):
    n = len(x) // n_blocks * n_blocks
    if n_blocks < 2 or n == 0:
        return None
    return x[:n].reshape(n_blocks, -1, x.shape[1]).mean(axis=1)


@dataclass
class UpAxis:
    """The sensor axis that points up, found from gravity (:func:`detect_up_axis`).

    Attributes
    ----------
    axis : str
        ``"+z"``, ``"-x"``, …: the signed sensor axis nearest to the mean specific force.
    index, sign : int
        The same as an index 0..2 and ±1.
    up_s : (3,) unit vector
        Mean specific force direction in sensor axes (the measured up).
    tilt_rad : float
        Angle between ``up_s`` and the chosen axis.
    sigma_rad : float
        1σ of the direction ``up_s`` (scatter of the window, accelerometer bias prior).
    confidence : float
        Probability (Gaussian, from ``sigma_rad``) that the chosen axis is the nearest one to
        the true up; 0 when the mean |f| is not gravity.
    gravity_ratio : float
        ``|mean f| / 9.80665``.
    samples : int
    """

    axis: str
    index: int
    sign: int
    up_s: np.ndarray
    tilt_rad: float
    sigma_rad: float
    confidence: float
    gravity_ratio: float
    samples: int

    def to_dict(self) -> dict:
        return {"axis": self.axis, "tilt_deg": math.degrees(self.tilt_rad),
                "sigma_deg": math.degrees(self.sigma_rad), "confidence": self.confidence,
                "gravity_ratio": self.gravity_ratio, "samples": self.samples}


#: Standard gravity, m/s² (the unit of ``gravity_ratio``).
G0 = 9.80665


def detect_up_axis(f_s, *, accel_bias_sigma: float = 0.2, blocks: int = 10) -> UpAxis:
    """The up axis of a sensor from the specific force of a window of samples.

    The mean specific force of a window points up (``f = −g`` at rest; a vehicle's own
    accelerations average out over seconds). Its direction's σ combines the scatter of
    ``blocks`` consecutive block means (which sees the vehicle's accelerations, correlated
    over seconds) with an accelerometer bias prior ``accel_bias_sigma`` m/s² (the consumer
    grade's 2 mg is 0.02; 0.2 leaves room for cheaper parts). The confidence is the Gaussian
    probability that the true direction lies nearer to the chosen axis than to the next one:
    ``Φ((θ₂ − θ₁) / (2σ))``.

    Parameters
    ----------
    f_s : (N, 3) specific force, m/s², in the sensor's own axes
    accel_bias_sigma : m/s²
    blocks : number of block means for the scatter

    Returns
    -------
    UpAxis
    """
    f = np.asarray(f_s, dtype=float)
    if f.ndim != 2 or f.shape[1] != 3 or len(f) < 2:
        raise SelfnavError("detect_up_axis needs an (N, 3) specific force with N >= 2")
    m = f.mean(axis=0)
    norm = float(np.linalg.norm(m))
    u = m / norm if norm > 0 else np.array([0.0, 0.0, 1.0])
    bm = _block_means(f, min(blocks, len(f)))
    if bm is not None:
        scatter = float(np.linalg.norm(bm.std(axis=0, ddof=1))) / math.sqrt(len(bm))
    else:
        scatter = float(np.linalg.norm(f.std(axis=0))) / math.sqrt(len(f))
    sigma = math.hypot(scatter, accel_bias_sigma) / max(norm, 1e-9)
    ang = np.arccos(np.clip(np.abs(u), 0.0, 1.0))    # angle to ±each axis (nearest sign)
    order = np.argsort(ang)
    i = int(order[0])
    s = 1 if u[i] >= 0 else -1
    margin = 0.5 * float(ang[order[1]] - ang[i])
    ratio = norm / G0
    conf = _phi(margin / max(sigma, 1e-12)) if 0.5 < ratio < 1.5 else 0.0
    return UpAxis(axis_label(i, s), i, s, u, float(ang[i]), float(sigma), float(conf),
                  float(ratio), int(len(f)))


# --------------------------------------------------------------------------- detection: forward
@dataclass
class ForwardAxis:
    """The sensor axis that points forward on a vehicle (:func:`detect_forward_axis`).

    Attributes
    ----------
    axis : str
        Signed sensor axis (``"+x"``, ``"-y"``, …) nearest to the forward direction, among the
        two axes perpendicular to the up axis.
    index, sign : int
    forward_s : (3,) unit vector, the forward direction found, in sensor axes
    yaw_mount_rad : float
        Fine yaw of the IMU on the vehicle, rad (the ``yaw`` of ``--imu-mount``): the angle,
        clockwise seen from above, from the vehicle's forward direction to the chosen axis.
    sigma_yaw_rad : float
        1σ of ``yaw_mount_rad`` from the least-squares fit.
    confidence : float
        Gaussian probability that the chosen axis is the nearest to forward
        (``Φ((45° − |yaw|)/σ)``); 0 without enough acceleration or turning to see.
    along_gain, lateral_gain : float
        Length of the fitted forward and right vectors (≈ 1 when the specific force and the
        GNSS accelerations agree in scale).
    handed : int
        +1 when the lateral fit says right × forward = up (a right-handed, correctly signed
        triad), −1 when it says the opposite, 0 when there was no turning to tell.
    turn_correlation : float
        Correlation of the GNSS course rate with the gyro rate about −up (≈ +1 when the up
        axis and the gyro signs are right; NaN without turns).
    epochs : int
        GNSS epochs used.
    turn_gain, sigma_turn_gain, turn_r2 : float
        The GNSS course rate over the gyro rate about −up (least squares through zero), its
        1σ and the share of the course rate's variance it explains: ≈ 1 for gyros in rad/s,
        ≈ 1/57.3 for deg/s read as rad/s, ≈ −1 for gyros turning the other way
        (:func:`check_turn_gain`); NaN without turns.
    lateral_g95 : float
        95th percentile, over the epochs at 5-40 m/s, of the sideways acceleration the gyro
        rate implies for a vehicle that turns where it points (speed × rate about up), in g;
        NaN with fewer than 20 such epochs.
    turn_gain_one_blocks : int
        Stretches of :data:`TURN_GAIN_BLOCK_S` where the gain, fitted on that stretch alone, is
        decided and 1: the gyros are right there, whatever the whole record's fit says (a
        GNSS fault — a drift, a drag — turns the track for minutes, not the gyros).
    """

    axis: str
    index: int
    sign: int
    forward_s: np.ndarray
    yaw_mount_rad: float
    sigma_yaw_rad: float
    confidence: float
    along_gain: float
    lateral_gain: float
    handed: int
    turn_correlation: float
    epochs: int
    turn_gain: float = float("nan")
    sigma_turn_gain: float = float("nan")
    turn_r2: float = float("nan")
    lateral_g95: float = float("nan")
    turn_gain_one_blocks: int = 0

    def to_dict(self) -> dict:
        return {"axis": self.axis, "yaw_mount_deg": math.degrees(self.yaw_mount_rad),
                "sigma_yaw_deg": math.degrees(self.sigma_yaw_rad), "confidence": self.confidence,
                "along_gain": self.along_gain, "lateral_gain": self.lateral_gain,
                "handed": self.handed, "turn_correlation": self.turn_correlation,
                "turn_gain": self.turn_gain, "sigma_turn_gain": self.sigma_turn_gain,
                "turn_r2": self.turn_r2, "lateral_g95": self.lateral_g95,
                "turn_gain_one_blocks": self.turn_gain_one_blocks, "epochs": self.epochs}


def gnss_velocity_n(gnss: GnssData) -> tuple[np.ndarray, np.ndarray]:
    """ENU velocity of a GNSS record: its own where given, else central differences of the
    positions over ±1 s (at the fix times; the ends one-sided). Returns ``(t, velocity_n)``."""
    t = np.asarray(gnss.t, dtype=float)
    if gnss.velocity_n is not None and np.all(np.isfinite(gnss.velocity_n[:, :2])):
        v = np.array(gnss.velocity_n, dtype=float)
        v[:, 2] = np.where(np.isfinite(v[:, 2]), v[:, 2], 0.0)
        return t, v
    r_phi, r_lam = radii(gnss.lat, gnss.h)
    lon = np.unwrap(gnss.lon)
    p = np.column_stack([(lon - lon[0]) * r_lam * np.cos(gnss.lat), (gnss.lat - gnss.lat[0]) * r_phi,
                         gnss.h - gnss.h[0]])
    # central differences over ±1 s (at least one fix each side): the noise of a difference
    # of positions falls with its span
    m = max(1, int(round(1.0 / max(float(np.median(np.diff(t))), 1e-6)))) if len(t) > 2 else 1
    i = np.arange(len(t))
    a, b = np.clip(i - m, 0, len(t) - 1), np.clip(i + m, 0, len(t) - 1)
    span = np.where(t[b] > t[a], t[b] - t[a], np.nan)
    v = (p[b] - p[a]) / span[:, None]
    return t, v


def _interval_means(t_imu, x, t0, t1):
    """Mean of IMU rows (interval means ending at ``t_imu``) over ``[t0, t1]`` (cumulative sums,
    row granularity)."""
    c = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    i0 = np.searchsorted(t_imu, t0, side="right")
    i1 = np.searchsorted(t_imu, t1, side="right")
    n = np.maximum(i1 - i0, 1)
    return (c[i1] - c[i0]) / n[:, None], i1 - i0


def detect_forward_axis(imu: ImuData, gnss: GnssData, *, up: UpAxis | None = None,
                        min_speed: float = 1.0, span_s: float | None = None) -> ForwardAxis:
    """The forward axis of a sensor on a vehicle, from its horizontal specific force against the
    acceleration of the GNSS velocity.

    On a vehicle that does not slip sideways the horizontal specific force is, in the plane
    perpendicular to up, ``f_h = (a_along + g sin γ) F + a_lat R + c``: the along-track
    acceleration (the derivative of the GNSS speed, plus gravity along a climb of angle γ)
    along the forward direction ``F``, the lateral acceleration ``v · dχ/dt`` (χ the course)
    along the right direction ``R``, and a constant ``c`` (accelerometer bias and a tilt of the
    mounting). Both are averaged over ``span_s`` around each GNSS epoch on both sides (the IMU
    rows by their interval means), and ``F``, ``R``, ``c`` are fitted by least squares over the
    epochs faster than ``min_speed`` — as a *reverse* regression, ``a_along = F·(f_h − c)``
    and ``a_lat = R·(f_h − c)``, so that the noise of the differenced GNSS velocity sits in the
    responses and does not shrink the fit. The forward axis is the sensor axis nearest to ``F``; the
    fine yaw mounting angle is the angle between them, its σ from the fit's covariance with
    the residual variance.

    Parameters
    ----------
    imu : ImuData
        In the sensor's own axes (a reader given ``axes="detect"``).
    gnss : GnssData
        On the IMU's time base; velocity used where given, else from the positions.
    up : UpAxis, optional
        Default: :func:`detect_up_axis` of the IMU rows that overlap the GNSS span.
    min_speed : m/s
    span_s : s, averaging window (≥ 2 GNSS intervals); default 1 s with the receiver's
        velocity, 4 s with a velocity differenced from positions (twice differenced noise)

    Returns
    -------
    ForwardAxis
    """
    t_imu = np.asarray(imu.t, dtype=float)
    tg, vg = gnss_velocity_n(gnss)
    if span_s is None:
        span_s = 1.0 if gnss.velocity_n is not None else 4.0
    keep = (tg >= t_imu[0]) & (tg <= t_imu[-1])
    tg, vg = tg[keep], vg[keep]
    if up is None:
        m = (t_imu >= (tg[0] if len(tg) else t_imu[0])) & (t_imu <= (tg[-1] if len(tg) else t_imu[-1]))
        up = detect_up_axis(imu.f_ib_b[m] if m.sum() > 10 else imu.f_ib_b)
    u = np.asarray(up.up_s, dtype=float)
    empty = ForwardAxis("?", -1, 0, np.full(3, np.nan), float("nan"), float("nan"), 0.0,
                        float("nan"), float("nan"), 0, float("nan"), 0)
    if len(tg) < 5:
        return empty
    dtg = float(np.median(np.diff(tg)))
    half = max(0.5 * span_s, dtg)
    k = max(1, int(round(half / dtg)))
    # GNSS: speed, course, their rates over ±k epochs
    sp = np.hypot(vg[:, 0], vg[:, 1])
    chi = np.unwrap(np.arctan2(vg[:, 0], vg[:, 1]))
    i = np.arange(k, len(tg) - k)
    t0, t1 = tg[i - k], tg[i + k]
    a_al = (sp[i + k] - sp[i - k]) / (t1 - t0)
    chi_rate = (chi[i + k] - chi[i - k]) / (t1 - t0)
    s_mid = sp[i]
    slope = np.where(s_mid > 0.1, vg[i, 2] / np.maximum(np.hypot(s_mid, vg[i, 2]), 1e-9), 0.0)
    a_al = a_al + G0 * slope
    a_lat = s_mid * chi_rate
    # IMU: mean specific force and rate over the same spans
    f_mean, n_rows = _interval_means(t_imu, np.asarray(imu.f_ib_b, float), t0, t1)
    w_mean, _ = _interval_means(t_imu, np.asarray(imu.omega_ib_b, float), t0, t1)
    ok = (n_rows > 0) & (sp[i - k] > min_speed) & (sp[i + k] > min_speed) & (s_mid > min_speed)
    ok &= np.isfinite(a_al) & np.isfinite(a_lat)
    # course rate against the gyro about −up (heading clockwise)
    turn = -(w_mean @ u)
    corr = float("nan")
    if ok.sum() > 5 and np.std(chi_rate[ok]) > 1e-3 and np.std(turn[ok]) > 0:
        corr = float(np.corrcoef(chi_rate[ok], turn[ok])[0, 1])
    # the course's noise falls with the speed: the gain weighted by its square — over the
    # epochs whose GNSS accelerations a vehicle can have (outliers differenced into speeds of
    # 100 m/s weigh 10⁴ and took a simulated map drive's gain to −1: refused, exit 2)
    fit = ok & (np.abs(a_al) < MAX_GNSS_ACCEL) & (np.abs(a_lat) < MAX_GNSS_ACCEL)
    # ... and no epoch weighs more than one at twice the median speed (a fault that passes
    # the test above still reads fast: at 137 m/s it weighed 300 clean epochs)
    w_fit = np.minimum(s_mid, 2.0 * float(np.median(s_mid[fit])) if fit.any() else 0.0) ** 2
    gain, sig_gain_turn, r2 = _turn_gain(chi_rate[fit], turn[fit], w_fit[fit], 2.0 * k)
    ones = 0
    block = np.floor((tg[i] - tg[0]) / TURN_GAIN_BLOCK_S)
    for b in np.unique(block[fit]):
        sel = fit & (block == b)
        gb, sb, rb = _turn_gain(chi_rate[sel], turn[sel], w_fit[sel], 2.0 * k)
        ones += bool(_gain_decided(sb, rb) and abs(gb - 1.0) <= TURN_GAIN_Z * sb)
    # (below 40 m/s: an outlier differenced into a speed of 50-100 m/s, times a parking turn,
    # would ask g's of a car that stands)
    fast = ok & (s_mid > 5.0) & (s_mid < 40.0)
    lat_g = (float(np.percentile(s_mid[fast] * np.abs(turn[fast]), 95)) / G0
             if fast.sum() >= 20 else float("nan"))
    empty = replace(empty, turn_gain=gain, sigma_turn_gain=sig_gain_turn, turn_r2=r2,
                    lateral_g95=lat_g, turn_gain_one_blocks=ones)
    if ok.sum() < 8:
        return replace(empty, turn_correlation=corr, epochs=int(ok.sum()))
    # basis of the plane perpendicular to up
    e1 = np.cross(u, np.eye(3)[int(np.argmin(np.abs(u)))])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    B = np.column_stack([e1, e2])
    # reverse regression (the GNSS accelerations, the noisy side, as the responses):
    # a_along = F·(f_p − c), a_lat = R·(f_p − c), unbiased however noisy the GNSS
    fp = f_mean[ok] @ B                                 # (M, 2) in the plane
    X = np.column_stack([fp, np.ones(len(fp))])
    Y = np.column_stack([a_al[ok], a_lat[ok]])
    XtX = X.T @ X
    try:
        XtX_inv = np.linalg.inv(XtX)
    except np.linalg.LinAlgError:
        return replace(empty, turn_correlation=corr, epochs=int(ok.sum()))
    coef = XtX_inv @ X.T @ Y                            # columns: along, lateral
    res = Y - X @ coef
    dof = max(len(Y) - 3, 1)
    s2 = np.sum(res ** 2, axis=0) / dof                 # per response
    # each epoch's span overlaps its 2k neighbours': the residuals are correlated over 2k
    # epochs, so the least-squares covariance is inflated by 2k (fewer independent epochs)
    infl2 = 2.0 * k
    Fp, Rp = coef[:2, 0], coef[:2, 1]
    gain_f = float(np.linalg.norm(Fp))
    gain_r = float(np.linalg.norm(Rp))
    if not gain_f > 0:
        return replace(empty, turn_correlation=corr, epochs=int(ok.sum()))
    cov_f = infl2 * s2[0] * XtX_inv[:2, :2]
    cov_r = infl2 * s2[1] * XtX_inv[:2, :2]
    nf = Fp / gain_f
    perp = np.array([-nf[1], nf[0]])
    sig_perp = math.sqrt(float(perp @ cov_f @ perp)) / gain_f
    sig_gain = math.sqrt(float(nf @ cov_f @ nf))
    F = B @ nf
    handed = 0
    if gain_r > 0:
        nr = Rp / gain_r
        if gain_r > 3.0 * math.sqrt(float(nr @ cov_r @ nr)):
            R3 = B @ nr
            handed = 1 if float(np.cross(R3, F) @ u) > 0 else -1
    # nearest sensor axis to F among those perpendicular to up
    cand = [j for j in range(3) if j != up.index]
    best = max(cand, key=lambda j: abs(F[j]))
    sgn = 1 if F[best] >= 0 else -1
    a_vec = np.zeros(3)
    a_vec[best] = sgn
    a_vec -= (a_vec @ u) * u
    a_vec /= np.linalg.norm(a_vec)
    # yaw: from the vehicle's forward F to the IMU axis, clockwise seen from above (about −u)
    yaw = float(math.atan2(-(np.cross(F, a_vec) @ u), float(F @ a_vec)))
    conf = _phi((math.pi / 4 - abs(yaw)) / max(sig_perp, 1e-12))
    if gain_f < 3.0 * sig_gain:
        conf = 0.0                                      # no along-track acceleration to see
    return ForwardAxis(axis_label(best, sgn), best, sgn, F, yaw, float(sig_perp), float(conf),
                       gain_f, gain_r, handed, corr, int(ok.sum()), gain, sig_gain_turn, r2,
                       lat_g)


def _turn_gain(chi_rate, turn, weight, inflation):
    """Weighted least-squares gain (through zero) of the course rate on the gyro rate and its
    1σ, the residual variance inflated by the overlap of the spans, and the share of the
    course rate's (weighted) variance the fit explains; epochs beyond 3 robust σ of the fit (a
    GNSS outlier differenced into a course) dropped and the fit redone, twice. NaN with fewer
    than 8 epochs or no turning."""
    keep = np.isfinite(chi_rate) & np.isfinite(turn)
    for _ in range(3):
        w, x, y = weight[keep], turn[keep], chi_rate[keep]
        sxx = float(w @ (x * x))
        if len(x) < 8 or not sxx > 0:
            return float("nan"), float("nan"), float("nan")
        g = float(w @ (y * x)) / sxx
        z = (chi_rate - g * turn) * np.sqrt(weight)          # whitened residuals
        s2 = float(np.sum(z[keep] ** 2)) / (keep.sum() - 1)
        syy = float(w @ (y * y))
        r2 = 1.0 - float(np.sum(z[keep] ** 2)) / syy if syy > 0 else float("nan")
        new = keep & (np.abs(z) <= 3.0 * 1.4826 * float(np.median(np.abs(z[keep]))))
        if np.array_equal(new, keep):
            break
        keep = new
    return g, math.sqrt(inflation * s2 / sxx), r2


#: A turn gain is decided when its σ is below this, it lies within ``TURN_GAIN_Z`` σ of one
#: explanation and beyond ``TURN_GAIN_REFUTE_Z`` σ of the right one (1), and the fit explains
#: at least ``TURN_GAIN_MIN_R2`` of the course's turning (a ship yawing in the waves about a
#: straight course has a gain near 0 too, but nothing of its course explained).
TURN_GAIN_MAX_SIGMA = 0.1
TURN_GAIN_Z = 4.0
TURN_GAIN_REFUTE_Z = 10.0
TURN_GAIN_MIN_R2 = 0.25
#: s: the stretches fitted alone (``ForwardAxis.turn_gain_one_blocks``); a gain decided and 1
#: on one of them clears the gyros (a simulated map drive with a receiver drifting for its
#: first 284 s fitted −0.97 ± 0.08 over the whole record and was refused as gyro signs
#: flipped, exit 2; its clean stretch after the drift turns as one)
TURN_GAIN_BLOCK_S = 60.0
#: m/s²: GNSS accelerations (along, sideways) beyond this are a fault differenced into the
#: track, not the vehicle (1.5 g; the turn gain is fitted without them)
MAX_GNSS_ACCEL = 15.0
#: Sideways acceleration (g) a vehicle turning where it points cannot hold on 5 % of its epochs
#: at 5-40 m/s (a car's corners: under 1 g; gyros in deg/s read as rad/s: ×57)
MAX_LATERAL_G95 = 3.0


def _gain_decided(sigma, r2) -> bool:
    """A turn gain is sure enough to say something: σ within :data:`TURN_GAIN_MAX_SIGMA` and
    the fit explaining :data:`TURN_GAIN_MIN_R2` of the course's turning (False for NaN)."""
    return bool(sigma <= TURN_GAIN_MAX_SIGMA and r2 >= TURN_GAIN_MIN_R2)


def check_turn_gain(fwd: "ForwardAxis", source: str = "IMU data", *,
                    along_nose: bool = False) -> None:
    """Raise :class:`~selfnav.errors.InputError` when the gyros turn decisively unlike the GNSS
    track: 57.3× faster (deg/s read as rad/s) or the other way (gyro signs flipped against the
    accelerometers', latitude and longitude swapped: the up axis comes from gravity, so an axis
    negated in both sensors does not flip it). Nothing when there is too little turning to
    tell, or the gain is near 1 — over the record or on one stretch of it
    (``turn_gain_one_blocks``: a GNSS fault turns the track for minutes). ``along_nose`` (a
    car, a walker, a rover: it turns where it points): gyro rates that, times the GNSS speed,
    ask more than 3 g sideways on 5 % of the epochs at 5-40 m/s are deg/s too, however noisy
    the course (the gain undecided).
    """
    from selfnav.errors import InputError

    if along_nose and fwd.lateral_g95 > MAX_LATERAL_G95:
        raise InputError(source, f"at over 5 m/s the gyro rate about up asks {fwd.lateral_g95:.3g} "
                         "g sideways (95th percentile; a car's corners stay under 1 g): the gyros "
                         "look like deg/s, the file needs rad/s")
    g, sg = fwd.turn_gain, fwd.sigma_turn_gain
    if not (np.isfinite(g) and _gain_decided(sg, fwd.turn_r2)):
        return
    if fwd.turn_gain_one_blocks > 0:        # the gyros turn as the track where it is clean
        return
    if abs(g - 1.0) <= TURN_GAIN_REFUTE_Z * sg:
        return
    if abs(g - math.radians(1.0)) <= TURN_GAIN_Z * max(sg, 1e-3):      # deg/s read as rad/s
        raise InputError(source, f"the GNSS track turns {g:.4f} ± {sg:.4f} rad per radian the "
                         f"gyros turn ({fwd.epochs} epochs; 1/57.3 = 0.0175 for gyros in "
                         "deg/s): they look like deg/s, the file needs rad/s")
    if abs(g + 1.0) <= TURN_GAIN_Z * sg:
        raise InputError(source, f"the gyros turn one way and the GNSS track the other (gain "
                         f"{g:.2f} ± {sg:.2f} over {fwd.epochs} epochs): gyro signs flipped "
                         "against the accelerometers' (a logger that inverts its gyros) or "
                         "latitude and longitude swapped in the GNSS file")


# --------------------------------------------------------------------------- detected frames
def frame_from_detection(up: UpAxis, forward: ForwardAxis | None = None, *,
                         yaw: bool = True) -> ImuFrame:
    """The :class:`ImuFrame` of what was detected: the up axis ``U``, the forward axis ``F``
    and the third axis by the right-hand rule; with ``yaw`` the fine yaw mounting angle.

    Without a forward axis (``None`` or no confidence) the sensor axis after the up axis in the
    cyclic order x → y → z is taken as forward (the heading is then the navigator's business:
    a mounting yaw of 90° only turns the heading).
    """
    if up.index < 0:
        raise AxesError("no up axis detected")
    U = np.zeros(3)
    U[up.index] = up.sign
    if forward is not None and forward.index >= 0 and forward.index != up.index:
        Fv = np.zeros(3)
        Fv[forward.index] = forward.sign
        yaw_deg = math.degrees(forward.yaw_mount_rad) if yaw else 0.0
    else:
        Fv = np.zeros(3)
        Fv[(up.index + 1) % 3] = 1.0
        yaw_deg = 0.0
    Rv = np.cross(Fv, U)                 # R × F = U  ⇔  R = F × U
    # P maps sensor → RFU: rows are the sensor-axis coordinates of R, F, U
    P = np.vstack([Rv, Fv, U])
    return ImuFrame(axes_from_matrix(P), (0.0, 0.0, yaw_deg), "", "detected")


def compare_frames(given: ImuFrame, detected: ImuFrame, *, yaw_tolerance_deg: float = 10.0,
                   up: UpAxis | None = None, forward: ForwardAxis | None = None) -> str | None:
    """One line when a given frame disagrees with a detected one (None when they agree).

    The up axes are compared when ``up`` is confident (≥ 0.99); forward when ``forward`` is;
    the yaw mounting when its difference exceeds both ``yaw_tolerance_deg`` and 3σ.
    """
    Pg, Pd = given.axes.matrix, detected.axes.matrix
    msgs = []
    if up is None or up.confidence >= 0.99:
        if not np.array_equal(Pg[2], Pd[2]):
            msgs.append(f"up is sensor axis {_axis_of(Pd[2])} by gravity, not "
                        f"{_axis_of(Pg[2])}")
    if forward is not None and forward.confidence >= 0.99:
        if not np.array_equal(Pg[1], Pd[1]):
            msgs.append(f"forward is sensor axis {_axis_of(Pd[1])} by the GNSS accelerations, "
                        f"not {_axis_of(Pg[1])}")
        elif abs(given.mount_deg[2] - detected.mount_deg[2]) > max(
                yaw_tolerance_deg, 3 * math.degrees(forward.sigma_yaw_rad)):
            msgs.append(f"yaw mounting {detected.mount_deg[2]:.1f}° ± "
                        f"{math.degrees(forward.sigma_yaw_rad):.1f}° by the GNSS accelerations, "
                        f"not {given.mount_deg[2]:g}°")
    if not msgs:
        return None
    return (f"IMU {given.describe()} disagrees with the data: " + "; ".join(msgs)
            + f" (detected axes {detected.axes.letters})")


def imu_axes_report(imu: ImuData, gnss: GnssData, *, along_nose: bool = True) -> dict:
    """The axes of an IMU record as read, checked against the data before a navigator runs on
    it (issue 20, part 2): the up axis from gravity (the IMU rows the GNSS overlaps), the
    forward axis from the GNSS accelerations, the gyro turn gain (:func:`check_turn_gain`:
    gyros in deg/s or turning the other way raise :class:`~selfnav.errors.InputError`).

    Rows read into the vehicle's RFU frame should show up ``+z`` and forward ``+y``: where a
    confident detection says otherwise, one warning line names what was found (forward only
    ``along_nose``: a platform that moves along its nose — a drone, a boat, an aircraft may
    fly or drift sideways). Rows left in the sensor's own axes (``--imu-axes detect``) are
    reported with the axes the detection reads them as (:func:`detected_frame` turns the
    report into a frame). Returns the report (``up``, ``forward``, ``axes_found``,
    ``axes_up_only``, ``agrees``, ``applied``) for the solution's statistics; the rows are not
    changed here.
    """
    from selfnav.errors import warn

    src = imu.source or "IMU data"
    t = np.asarray(imu.t, float)
    m = (t >= gnss.t[0]) & (t <= gnss.t[-1])
    up = detect_up_axis(imu.f_ib_b[m] if m.sum() > 10 else imu.f_ib_b)
    fwd = detect_forward_axis(imu, gnss, up=up)
    check_turn_gain(fwd, src, along_nose=along_nose)
    found = up_only = None
    if up.index >= 0 and up.confidence >= 0.99:
        up_only = frame_from_detection(up, None).axes.letters
        if fwd.index >= 0 and fwd.confidence >= 0.99:
            found = frame_from_detection(up, fwd, yaw=False).axes.letters
    rep = {"up": up.to_dict(), "forward": fwd.to_dict(), "axes_found": found,
           "axes_up_only": up_only, "agrees": None, "applied": None}
    if imu.meta.get("axes") == "sensor":
        return rep
    bad = []
    if up.index >= 0 and up.confidence >= 0.99 and up.axis != "+z":
        bad.append(f"up is its {up.axis} by gravity")
    if along_nose and fwd.index >= 0 and fwd.confidence >= 0.99 and up.axis == "+z" \
            and fwd.axis != "+y":
        bad.append(f"forward is its {fwd.axis} by the GNSS accelerations")
    rep["agrees"] = not bad
    if bad:
        given = imu.meta.get("axes_preset") or imu.meta.get("axes") or "the format's axes"
        warn(f"{src}: read with IMU axes {given}, the data disagree: " + "; ".join(bad)
             + " (expected +z up, +y forward): check --imu-axes")
    return rep


def detected_frame(rep: dict, source: str = "IMU data") -> tuple[ImuFrame, bool]:
    """The frame ``--imu-axes detect`` reads a record in, from :func:`imu_axes_report`'s
    report: the axes found and the fine yaw mounting when the forward axis was found (its σ
    below 2°; else no yaw), or — forward not found — the up axis with the sensor axis after it
    taken as forward (then ``False``: the caller must not trust a forward axis, e.g. turn the
    sideways constraint off). :class:`~selfnav.errors.InputError` when not even up was found.
    """
    from selfnav.axes import imu_frame
    from selfnav.errors import InputError

    if rep["axes_found"]:
        f = rep["forward"]
        yaw = f["yaw_mount_deg"] if f["sigma_yaw_deg"] < 2.0 else 0.0
        return replace(imu_frame(rep["axes_found"], (0.0, 0.0, yaw)), source="detected"), True
    if rep["axes_up_only"]:
        return replace(imu_frame(rep["axes_up_only"]), source="detected"), False
    raise InputError(source, "--imu-axes detect: no up axis found (the mean specific force is "
                     f"not gravity: {rep['up']['gravity_ratio']:.3g} g, or too scattered); give "
                     "--imu-axes")


def _axis_of(row) -> str:
    j = int(np.flatnonzero(row)[0])
    return axis_label(j, int(row[j]))


__all__ = ["ForwardAxis", "UpAxis", "check_turn_gain", "compare_frames", "detect_forward_axis",
           "detect_up_axis", "detected_frame", "frame_from_detection", "gnss_velocity_n",
           "imu_axes_report"]
