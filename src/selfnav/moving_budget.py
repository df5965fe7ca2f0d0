"""Error budget of the moving-base method (seeds 002/003, DESIGN §4): grades, noise, timing.

The sensor vocabulary is the package's one, :data:`selfnav.sensors.GRADES` (navigation,
tactical, industrial, consumer): the gyro terms come from there; the attitude source, which
:mod:`selfnav.sensors` does not model, is a per-grade table here (:data:`ATTITUDE_SOURCES`).
:func:`error_budget` gives the latitude σ per source for a gain K; :func:`grade_table` the best
each grade can do; :func:`timing_sensitivity` the latitude and longitude error per second of
attitude–gyro clock offset on a given motion (the term that dominates on a rolling ship).
"""
from __future__ import annotations

import numpy as np

from selfnav import sensors
from selfnav.earth import OMEGA_EARTH
from selfnav.units import DEG, DEG_PER_H, DEG_PER_SQRT_H

#: Attitude-source errors per grade (the attitude reference paired with an IMU of that grade;
#: :mod:`selfnav.sensors` does not model them): white noise per attitude sample (rad) and the
#: drift rate of the attitude error (rad/s). Typical values, stated for the tables:
#: a navigation-grade INS/gyrocompass, a tactical INS, an industrial AHRS, a consumer AHRS.
ATTITUDE_SOURCES = {
    "navigation": dict(attitude_noise=0.001 * DEG, attitude_rate=0.002 * DEG_PER_H),
    "tactical": dict(attitude_noise=0.01 * DEG, attitude_rate=0.5 * DEG_PER_H),
    "industrial": dict(attitude_noise=0.05 * DEG, attitude_rate=5.0 * DEG_PER_H),
    "consumer": dict(attitude_noise=0.5 * DEG, attitude_rate=50.0 * DEG_PER_H),
}


def grade_errors(grade: str) -> dict:
    """The moving-base error model of a grade of :data:`selfnav.sensors.GRADES`.

    Gyro terms come from the grade's gyro triad: ``gyro_bias`` (rad/s) is the turn-on bias and
    the Gauss-Markov bias instability together (``hypot``; the GM process acts as a bias over
    runs shorter than its τ), ``arw`` (rad/√s), ``scale_factor`` and ``misalignment``
    (fractions, rad); the attitude terms from :data:`ATTITUDE_SOURCES`.
    """
    key = sensors.grade_key(grade)
    if key not in sensors.GRADES:
        raise ValueError(f"unknown grade '{grade}' (use {', '.join(sensors.GRADE_NAMES)})")
    g = sensors.GRADES[key].gyro
    gm = np.max(np.broadcast_to(g.bias_instability, (3,))) * sensors.FLICKER_FLOOR / sensors.GM_ALLAN_PEAK
    return dict(gyro_bias=float(np.hypot(np.max(g.bias), gm)), arw=float(np.max(g.white)),
                scale_factor=float(np.max(g.scale_factor)), misalignment=float(np.max(g.misalignment)),
                **ATTITUDE_SOURCES[key])


#: The four terms :func:`error_budget` takes, per grade (the names of ``sensors.GRADES``).
BUDGET_KEYS = ("gyro_bias", "arw", "attitude_noise", "attitude_rate")


def error_budget(*, gyro_bias, arw, attitude_noise, attitude_rate, gain, dt,
                 smooth=True, lat_rate=0.0, A=None) -> dict:
    """Latitude error (rad, 1σ) per source for gain K, and the longitude drift rate.

    Per navigation axis, the ``ω_n`` error is: gyro bias ``b``; attitude-error drift rate ``r``;
    angle random walk ``N`` filtered: ``N √(K/4)`` (two stages; ``N √(K/2)`` one stage);
    white attitude noise ``σ_δ`` per sample differenced by the Poisson equation and filtered:
    ``σ_δ √(Δt K³/4)`` (two stages; ``K σ_δ`` one stage — the seed's "larger K, larger effect of
    δ"). Each divided by ``A = Ω + λ̇`` is a latitude error; the lag is ``φ̇ · 2/K`` (``1/K``).
    The longitude error grows as ``√(b² + r²) t`` plus the random walk ``N √t``.
    """
    K = float(gain)
    A = OMEGA_EARTH if A is None else float(A)
    stages = 2 if smooth else 1
    rate = {
        "gyro_bias": float(gyro_bias),
        "attitude_rate": float(attitude_rate),
        "arw": float(arw) * np.sqrt(K / (2.0 * stages)),
        "attitude_noise": float(attitude_noise) * (np.sqrt(dt * K**3 / 4.0) if smooth else K),
    }
    total = float(np.sqrt(sum(v * v for v in rate.values())))
    lag = abs(lat_rate) * stages / K
    out = {f"lat_{k}": v / A for k, v in rate.items()}
    out.update(rate_total=total, lat_lag=lag, lat_total=float(np.hypot(total / A, lag)),
               lon_rate_error=float(np.hypot(gyro_bias, attitude_rate)), gain=K)
    return out


def _noise_gain(g, dt, target):
    """Largest K whose filtered noise equals ``target`` rad/s (two stages)."""
    from scipy.optimize import brentq

    def f(lk):
        var = g["arw"] ** 2 * np.exp(lk) / 4 + g["attitude_noise"] ** 2 * dt * np.exp(3 * lk) / 4
        return np.log(var) - 2 * np.log(target)

    return float(np.exp(brentq(f, -30.0, 10.0)))


def grade_table(dt=0.01, grades=None, hours=1.0) -> list:
    """Accuracy each sensor grade can reach (rad) and the averaging time it needs.

    The bias floor ``√(b² + r²)/Ω`` cannot be averaged away; the gain at which the filtered
    noise equals it sets the time constant 1/K (equivalent averaging time 4/K). Verdict: usable
    below 0.1°, marginal below 1°, otherwise not usable. Latitude figures are capped at 90° and
    longitude at 180° (no information).
    """
    rows = []
    if grades is None:
        grades = {name: grade_errors(name) for name in sensors.GRADE_NAMES}
    for name, g in grades.items():
        floor_rate = float(np.hypot(g["gyro_bias"], g["attitude_rate"]))
        K = _noise_gain(g, dt, floor_rate)
        floor = floor_rate / OMEGA_EARTH
        sig = error_budget(gain=K, dt=dt, **{k: g[k] for k in BUDGET_KEYS})["lat_total"]
        deg = min(float(np.degrees(sig)), 90.0)   # 90°: no information (drift ≳ Ω)
        rows.append({"grade": name, "gyro_bias_deg_h": g["gyro_bias"] / DEG_PER_H,
                     "arw_deg_rth": g["arw"] / DEG_PER_SQRT_H, "attitude_noise_deg": g["attitude_noise"] / DEG,
                     "attitude_rate_deg_h": g["attitude_rate"] / DEG_PER_H,
                     "lat_floor_deg": min(float(np.degrees(floor)), 90.0), "gain_per_s": K,
                     "time_constant_s": 1.0 / K, "lat_sigma_deg": float(deg),
                     "lon_error_deg": min(float(np.degrees(floor_rate * hours * 3600.0)), 180.0),
                     "verdict": "usable" if deg < 0.1 else ("marginal" if deg < 1.0 else "not usable")})
    return rows
