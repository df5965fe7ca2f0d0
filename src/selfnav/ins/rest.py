"""At-rest start-up pieces shared by the attitude filter and the navigators (issue 20): bias-aware
stillness, levelling at rest, magnetic heading, IGRF declination.

Each is a pure function of whatever window of samples it is given (causal callers pass their
first seconds):

* :func:`find_still` — stillness relative to the record's own noise floor (the quietest
  windows), not to absolute thresholds: a consumer IMU's stop is found although its noise is
  a hundred times a tactical unit's, and a gyro bias of 1 °/s does not count as motion (only
  the *variation* is tested, and the window means must agree with each other);
* :func:`level_at_rest` — roll and pitch from the mean specific force (DESIGN §2:
  ``up_b = (−sin γ cos θ, sin θ, cos γ cos θ)``), gyro bias from the mean rate, each with a σ
  that keeps the accelerometer bias (indistinguishable from tilt at rest: ``δθ = b_a/g``) and
  the unknown horizontal Earth rate;
* :func:`heading_from_magnetometer` — tilt-compensated heading
  (:func:`selfnav.sensors.magnetic_heading`, ``H = D + atan2(−m_x, m_y)`` of the levelled
  field) with a σ from the field's noise, the tilt σ through the inclination
  (``δH ≈ tan I · δθ``), the declination σ and a disturbance floor;
  :func:`declination_at` gives IGRF-14's declination and inclination.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from selfnav import attitude as att
from selfnav import sensors
from selfnav.earth import OMEGA_EARTH, earth_rate_n
from selfnav.errors import SelfnavError

# =========================================================================== stillness
@dataclass
class Stillness:
    """Still samples of a window (:func:`find_still`).

    Attributes
    ----------
    mask : (N,) bool, per sample
    window_s : float, length of the test windows
    gyro_floor, accel_floor : float
        Noise floors: the median of the quietest windows' rate and specific-force scatter
        (rad/s, m/s², per-axis RMS of the std).
    still_windows, windows : int
    """

    mask: np.ndarray
    window_s: float
    gyro_floor: float
    accel_floor: float
    still_windows: int
    windows: int

    def stretches(self, t, min_s: float = 0.0):
        """``(start, stop)`` index pairs of consecutive still samples lasting at least ``min_s``."""
        m = np.concatenate([[False], self.mask, [False]])
        d = np.diff(m.astype(int))
        a, b = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        t = np.asarray(t, dtype=float)
        dt = median_interval(t)
        return [(int(i), int(j)) for i, j in zip(a, b) if t[j - 1] - t[i] + dt >= min_s]


def median_interval(t) -> float:
    """Median sample interval of a time series, s (0 for fewer than two samples)."""
    return float(np.median(np.diff(t))) if len(t) > 1 else 0.0


#: Ceilings of a still window's scatter, whatever the floor: beyond them nothing is still
#: (a record that moves throughout must not call its quietest motion "rest"). Generous: a
#: consumer MEMS at rest scatters ~0.002 rad/s and ~0.02 m/s²; a hand holding it still ~0.01
#: and ~0.05; walking ~0.5 and ~2.
MAX_STILL_GYRO_STD = 0.05
MAX_STILL_ACCEL_STD = 0.3
#: Largest gyro bias a still window may show, rad/s (5 × the consumer grade's 1 °/s turn-on
#: σ): a steady turn has a quiet gyro too, but its mean rate is beyond any bias.
MAX_GYRO_BIAS = math.radians(5.0)


def find_still(t, omega_b, f_b, *, window_s: float = 0.25, factor: float = 2.5,
               max_gyro_std: float = MAX_STILL_GYRO_STD,
               max_accel_std: float = MAX_STILL_ACCEL_STD,
               max_bias: float = MAX_GYRO_BIAS) -> Stillness:
    """Still samples of a record, relative to its own noise floor (bias-aware).

    The samples are cut into windows of ``window_s``; in each the scatter (per-axis std, RMS
    over the axes) of the rates and of the specific force is measured. The floor is the
    median scatter of the quietest windows (the 5 %, at least 3); a window is still when both
    its scatters are within ``factor`` × the floor (and the ceilings), its mean rate agrees with
    the median mean rate of the still windows (a steady turn is not rest: within ``factor`` ×
    the floor scatter plus 1 % of the rate; a trembling hand's window means scatter as its
    samples do) and its mean |f| with theirs.
    Gyro and accelerometer *biases* never enter: only variation and agreement do (and a mean
    rate beyond ``max_bias``, more than any gyro bias, is a turn).

    Parameters
    ----------
    t : (N,) s;  omega_b, f_b : (N, 3) any axes, rad/s and m/s²
    window_s, factor, max_gyro_std, max_accel_std : see above

    Returns
    -------
    Stillness
    """
    t = np.asarray(t, dtype=float)
    w = np.asarray(omega_b, dtype=float)
    f = np.asarray(f_b, dtype=float)
    n = len(t)
    dt = median_interval(t) or 0.01
    k = max(3, int(round(window_s / dt)))
    nw = n // k
    mask = np.zeros(n, bool)
    if nw < 1:
        return Stillness(mask, window_s, float("nan"), float("nan"), 0, 0)
    W = w[:nw * k].reshape(nw, k, 3)
    F = f[:nw * k].reshape(nw, k, 3)
    sw = np.sqrt(np.mean(W.std(axis=1) ** 2, axis=1))
    sa = np.sqrt(np.mean(F.std(axis=1) ** 2, axis=1))
    q = max(3, int(math.ceil(0.05 * nw)))
    floor_w = float(np.median(np.sort(sw)[:q]))
    floor_a = float(np.median(np.sort(sa)[:q]))
    ok = (sw <= factor * max(floor_w, 1e-12)) & (sa <= factor * max(floor_a, 1e-12))
    ok &= (sw <= max_gyro_std) & (sa <= max_accel_std)
    mw = W.mean(axis=1)
    ok &= np.linalg.norm(mw, axis=1) <= max_bias
    if ok.any():
        mf = np.linalg.norm(F.mean(axis=1), axis=1)
        ref_w = np.median(mw[ok], axis=0)
        ref_f = float(np.median(mf[ok]))
        # a hand holding the unit still trembles: its window means scatter like its samples
        tol_w = factor * max(floor_w, 1e-12) + 0.01 * np.linalg.norm(ref_w)
        tol_f = factor * max(floor_a, 1e-12) + 0.005 * ref_f
        ok &= np.linalg.norm(mw - ref_w, axis=1) <= tol_w
        ok &= np.abs(mf - ref_f) <= tol_f
    mask[:nw * k] = np.repeat(ok, k)
    return Stillness(mask, window_s, floor_w, floor_a, int(ok.sum()), int(nw))


# =========================================================================== levelling
@dataclass
class Levelling:
    """Roll, pitch and gyro bias from samples at rest (:func:`level_at_rest`), body RFU.

    Attributes
    ----------
    roll, pitch : rad
    sigma_roll, sigma_pitch : rad (noise of the mean ⊕ accelerometer bias prior / g)
    gyro_bias_b : (3,) rad/s, mean rate minus the Earth rate where it is known
    sigma_gyro_bias : (3,) rad/s
    f_mean_b : (3,) m/s², the mean specific force (``|f_mean_b|`` the local gravity as the
        accelerometers see it)
    gyro_noise, accel_noise : per-sample std of the rates and specific force (median axis)
    samples : int
    duration_s : float
    """

    roll: float
    pitch: float
    sigma_roll: float
    sigma_pitch: float
    gyro_bias_b: np.ndarray
    sigma_gyro_bias: np.ndarray
    f_mean_b: np.ndarray
    gyro_noise: float
    accel_noise: float
    samples: int
    duration_s: float

    def to_dict(self) -> dict:
        return {"roll_deg": math.degrees(self.roll), "pitch_deg": math.degrees(self.pitch),
                "sigma_roll_deg": math.degrees(self.sigma_roll),
                "sigma_pitch_deg": math.degrees(self.sigma_pitch),
                "gyro_bias_deg_per_s": np.degrees(self.gyro_bias_b).tolist(),
                "samples": self.samples, "duration_s": self.duration_s}


def level_at_rest(f_b, omega_b=None, *, dt: float, accel_bias_sigma: float = 0.2,
                  lat: float | None = None, heading: float | None = None) -> Levelling:
    """Level a unit at rest: roll and pitch from the mean specific force, the gyro bias from
    the mean rate (DESIGN §2; seed 000 (2.2)–(2.3)).

    Parameters
    ----------
    f_b : (N, 3) m/s², body RFU, samples at rest (:func:`find_still`)
    omega_b : (N, 3) rad/s or None
    dt : s, sample interval (for the noise of the mean)
    accel_bias_sigma : m/s², 1σ of the accelerometer bias, which at rest cannot be told from a
        tilt: it is in ``sigma_roll``/``sigma_pitch`` (``b_a/g``) and must be in the filter
        that starts from this (correlated with the tilt)
    lat : rad, optional: removes the Earth rate's vertical part ``Ω sin φ`` (and, with
        ``heading``, all of it); the unknown part goes into ``sigma_gyro_bias``
    heading : rad, optional

    Returns
    -------
    Levelling
    """
    f = np.asarray(f_b, dtype=float)
    if f.ndim != 2 or len(f) < 2:
        raise SelfnavError("level_at_rest needs at least two samples at rest")
    fm = f.mean(axis=0)
    g = float(np.linalg.norm(fm))
    up = fm / g
    pitch = math.asin(max(-1.0, min(1.0, float(up[1]))))
    roll = math.atan2(-float(up[0]), float(up[2]))
    n = len(f)
    acc_noise = float(np.median(f.std(axis=0)))
    s_tilt = math.hypot(acc_noise / math.sqrt(n), accel_bias_sigma) / g
    if omega_b is None:
        wb = np.zeros(3)
        s_b = np.full(3, np.nan)
        gyr_noise = float("nan")
    else:
        w = np.asarray(omega_b, dtype=float)
        wm = w.mean(axis=0)
        gyr_noise = float(np.median(w.std(axis=0)))
        unknown = OMEGA_EARTH
        if lat is not None:
            C_nb = att.dcm_nb_from_euler(roll, pitch, heading if heading is not None else 0.0)
            om = C_nb @ earth_rate_n(lat)
            if heading is None:
                om = (om @ up) * up           # only the vertical part is known
                unknown = OMEGA_EARTH * abs(math.cos(lat))
            else:
                unknown = 0.0
            wm = wm - om
        wb = wm
        s_b = np.sqrt(w.std(axis=0) ** 2 / n + unknown ** 2)
    return Levelling(roll, pitch, s_tilt, s_tilt, wb, s_b, fm, gyr_noise, acc_noise, n,
                     float(n * dt))


# =========================================================================== magnetic heading
def declination_at(lat: float, lon: float, h: float = 0.0, date=None) -> tuple[float, float]:
    """IGRF-14 declination and inclination, rad, at a place (and date; default the package's
    fixed date :data:`selfnav.igrf.DEFAULT_DATE`)."""
    b = sensors.earth_field_n(lat, lon, h, date, "igrf")
    d, i = sensors.declination_inclination(b)
    return float(d), float(i)


#: Heading σ floor of a magnetometer, deg: the residual hard/soft iron and local disturbances
#: a calibrated unit still sees (a few degrees is typical; a car body without calibration: 10+).
MAG_FLOOR_DEG = 2.0
#: σ of IGRF's declination against the local field, deg (crustal anomalies; IGRF's own).
IGRF_DECLINATION_SIGMA_DEG = 0.5


def heading_from_magnetometer(mag_b, roll: float, pitch: float, *, declination: float = 0.0,
                              sigma_tilt: float = 0.0, sigma_declination: float = 0.0,
                              floor_deg: float = MAG_FLOOR_DEG) -> tuple[float, float]:
    """Heading (clockwise from true North, rad) and its σ from magnetometer samples at a known
    tilt.

    The mean of the samples is levelled with ``roll``, ``pitch``
    (:func:`selfnav.sensors.magnetic_heading`: ``H = D + atan2(−m_x, m_y)``). σ² is the sum of
    the field noise over the horizontal field (``σ_m / B_h / √N``), the tilt error through the
    inclination (``tan I · sigma_tilt``: at 70° dip, 2.7 × the tilt σ), the declination σ and
    ``floor_deg`` (residual iron, disturbances).

    Parameters
    ----------
    mag_b : (N, 3) or (3,) any unit, body RFU
    roll, pitch, sigma_tilt : rad
    declination, sigma_declination : rad (0: magnetic heading)
    floor_deg : deg

    Returns
    -------
    heading, sigma : rad
    """
    m = np.atleast_2d(np.asarray(mag_b, dtype=float))
    mm = m.mean(axis=0)
    h = float(sensors.magnetic_heading(mm, roll, pitch, declination))
    Rt = np.swapaxes(att.frame_rotation(1, roll) @ att.frame_rotation(0, pitch), -1, -2)
    ml = Rt @ mm
    bh = math.hypot(ml[0], ml[1])
    if not bh > 0:
        return h, math.pi
    noise = float(np.median(m.std(axis=0))) / math.sqrt(len(m)) if len(m) > 1 else 0.0
    tan_i = abs(ml[2]) / bh
    s2 = (noise / bh) ** 2 + (tan_i * sigma_tilt) ** 2 + sigma_declination ** 2 + math.radians(
        floor_deg) ** 2
    return h, math.sqrt(s2)
