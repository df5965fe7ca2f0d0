"""Allan variance and identification of inertial sensor noise terms (IEEE Std 952, annex C).

The overlapping Allan variance of a rate record ``y_k`` (sample interval ``τ0``) at cluster time
``τ = m τ0`` uses the integrated signal ``θ_k = τ0 Σ_{i<k} y_i`` (``θ_0 = 0``)::

    σ²(τ) = Σ_k (θ_{k+2m} - 2 θ_{k+m} + θ_k)² / (2 τ² (N + 1 - 2m))

which is computed for every ``m`` from one cumulative sum (vectorized, O(N) per ``τ``). It is the
``oadev`` of ``allantools`` (the tests cross-check against it).

Noise terms, read from the log-log slopes of σ(τ):

* white noise (ARW for gyros, VRW for accelerometers), slope -1/2: ``σ = N/√τ``;
* bias instability, the floor: ``σ_min = B·sqrt(2 ln 2/π) ≈ 0.664 B``;
* rate random walk, slope +1/2: ``σ = K √(τ/3)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from selfnav.errors import InputError
from selfnav.io.imu import check_rest_units, longest_stretch
from selfnav.io.output import write_figure
from selfnav.sensors import FLICKER_FLOOR

#: Fewest samples an Allan analysis is run on.
MIN_SAMPLES = 100

RAD_S_TO_DEG_H = np.degrees(1.0) * 3600.0
SQRT_S_TO_SQRT_H = 60.0  # (x)/√s -> (x)/√h


def cluster_sizes(n: int, points_per_decade: int = 10) -> np.ndarray:
    """Log-spaced cluster sizes ``m`` from 1 to ``(n - 1) // 2``, unique integers."""
    top = max(1, (n - 1) // 2)
    k = max(2, int(np.ceil(np.log10(top) * points_per_decade)) + 1)
    return np.unique(np.round(np.logspace(0, np.log10(top), k)).astype(int))


def allan_deviation(rate, dt: float, m=None):
    """Overlapping Allan deviation of a rate record.

    Parameters
    ----------
    rate : (N,) or (N, K)
        Rate samples (rad/s, m/s², ...), the mean over each interval ``dt``.
    dt : float
        Sample interval, s.
    m : array of int, optional
        Cluster sizes; log-spaced, 10 per decade, by default.

    Returns
    -------
    tau : (M,) s
    adev : (M,) or (M, K), same units as ``rate``
    clusters : (M,) int, number of overlapping differences behind each value
    """
    y = np.asarray(rate, dtype=float)
    one = y.ndim == 1
    y = y[:, None] if one else y
    n = len(y)
    m = cluster_sizes(n) if m is None else np.asarray(m, dtype=int)
    m = m[(m >= 1) & (2 * m <= n)]
    # remove the mean first: the Allan variance ignores it, and this keeps the sums well scaled
    th = np.vstack([np.zeros((1, y.shape[1])), np.cumsum((y - y.mean(0)) * dt, axis=0)])
    av = np.empty((len(m), y.shape[1]))
    cnt = n + 1 - 2 * m
    for i, mm in enumerate(m):
        d = th[2 * mm:] - 2.0 * th[mm:-mm] + th[:-2 * mm]
        av[i] = np.einsum("ij,ij->j", d, d) / (2.0 * (mm * dt) ** 2 * cnt[i])
    ad = np.sqrt(av)
    return m * dt, (ad[:, 0] if one else ad), cnt


@dataclass
class NoiseTerms:
    """Noise terms of one sensor axis identified from its Allan deviation (SI units).

    white : ARW rad/√s or VRW (m/s)/√s (NaN if no slope -1/2 region)
    bias_instability : B, rad/s or m/s² (``σ_min / 0.664``)
    bias_instability_tau : τ of the floor, s
    bias_instability_bound : True if σ(τ) still falls at the longest τ (B is an upper bound)
    random_walk : rad/s/√s or m/s²/√s (NaN if no slope +1/2 region)
    """

    white: float
    bias_instability: float
    bias_instability_tau: float
    bias_instability_bound: bool
    random_walk: float


def _slopes(tau, adev, half_width: float = 0.25):
    """Log-log slope of σ(τ) over ±``half_width`` decades (single points are too noisy)."""
    lt, la = np.log10(tau), np.log10(adev)
    lo = np.searchsorted(lt, lt - half_width)
    hi = np.clip(np.searchsorted(lt, lt + half_width, side="right") - 1, 0, len(lt) - 1)
    lo = np.minimum(lo, np.maximum(hi - 1, 0))
    hi = np.maximum(hi, np.minimum(lo + 1, len(lt) - 1))
    den = lt[hi] - lt[lo]
    return np.where(den > 0, (la[hi] - la[lo]) / np.where(den > 0, den, 1.0), np.nan)


def identify(tau, adev, tolerance: float = 0.05, duration: float | None = None) -> NoiseTerms:
    """Identify white noise, bias instability and rate random walk from one σ(τ) curve.

    * Floor: the first τ where the (half-decade) slope reaches 0 (σ stops falling; B is read
      at the local minimum there), or the first flattest point (slope maximum above -0.25) of
      a shoulder, as a Gauss-Markov bias makes (no flat floor: σ falls again past ~2τ_c),
      such that σ does not fall below a third of it later; searched up to a tenth of the record
      (``duration``; 2.5 × the last τ by default), where σ(τ) is still well determined.
      ``B = σ_floor / 0.664`` (IEEE 952 C.1.3). Without such a point σ(τ) is still falling:
      B is the lowest σ/0.664 in that range, flagged as an upper bound.
      When σ rises from that minimum to a hump and falls again within a decade, B is read at
      the hump (the Allan peak of a Gauss-Markov bias). A candidate must also stand three
      standard errors of the slope above -1/2, so that the scatter of σ(τ) at long τ in a
      white-noise record is not read as a floor.
    * White noise: median of ``σ√τ`` over the points before the floor whose slope is within
      ``tolerance`` of -1/2 (a slope of -0.45 already means another term adds about 5 % to
      σ√τ, hence the tight default; it widens to twice that when nothing qualifies).
    * Rate random walk: median of ``σ√(3/τ)`` after the floor where the slope is within twice
      the tolerance of +1/2 (the slopes are noisier there).
    """
    tau = np.asarray(tau, dtype=float)
    adev = np.asarray(adev, dtype=float)
    ok = np.isfinite(adev) & (adev > 0)
    tau, adev = tau[ok], adev[ok]
    s = _slopes(tau, adev)
    idx = np.arange(len(tau))
    T = duration if duration is not None else 2.5 * tau[-1]
    search = tau <= max(T / 10.0, tau[min(2, len(tau) - 1)])
    # a floor must stand out of the noise of the slope: σ(τ) has a relative error of about
    # 1/√(2·EDF) with EDF ≈ 1.5 T/τ (overlapping estimator, white noise); the slope over
    # ±0.25 decade (Δlnτ = 1.15) then has an error of √2·1/√(2·EDF)/1.15.
    slope_err = 1.0 / np.sqrt(T / tau) / 1.15   # EDF taken as T/τ, on the safe side
    cand = search & (s >= -0.25) & (s > -0.5 + 3.0 * slope_err)
    # the first point where σ(τ) stops falling, or the first flattest point of a shoulder
    peak = np.zeros(len(s), bool)
    peak[1:-1] = (s[1:-1] >= s[:-2]) & (s[1:-1] > s[2:])
    hit = np.flatnonzero(cand & ((s >= 0.0) | peak))
    best, bound = None, True
    for k in hit:  # the first floor or shoulder that σ does not fall far below later
        if s[k] >= 0.0:
            near = np.flatnonzero(np.abs(np.log10(tau) - np.log10(tau[k])) <= 0.25)
            k = int(near[np.argmin(adev[near])])
        if not np.any(search & (idx > k) & (adev < adev[k] / 3.0)):
            best, bound = int(k), False
            # a hump within a decade after the minimum (σ rises, then falls again) is the
            # Gauss-Markov bias's Allan peak: read B there
            win = np.flatnonzero(search & (idx >= k) & (tau <= 10.0 * tau[k]))
            j = int(win[np.argmax(adev[win])])
            if j != win[-1] and j > k and s[j] > -0.5 + 3.0 * slope_err[j] and np.any(
                    (idx > j) & (s < -3.0 * slope_err)):
                best = j
            break
    if best is None:  # σ still falling through the usable range: an upper bound
        best = int(np.flatnonzero(search)[np.argmin(adev[search])])
    k = best

    def pick(mask, target, widen=1.0):
        for tol in (widen * tolerance, 2 * widen * tolerance):
            sel = mask & (np.abs(s - target) < tol)
            if sel.any():
                return sel
        return None

    sel = pick(idx <= k, -0.5)
    white = float(np.median(adev[sel] * np.sqrt(tau[sel]))) if sel is not None else np.nan
    sel = pick((idx > k) & search, 0.5, widen=2.0)   # long τ: noisier slopes
    rrw = float(np.median(adev[sel] * np.sqrt(3.0 / tau[sel]))) if sel is not None else np.nan
    return NoiseTerms(white, float(adev[k] / FLICKER_FLOOR), float(tau[k]), bound, rrw)


def analyze_imu(imu, m=None) -> dict:
    """Allan deviations and noise terms of all six axes of an :class:`~selfnav.io.ImuData`.

    The Allan variance needs evenly spaced samples: gaps of a few samples are bridged, and a
    record with longer gaps is analysed on its longest gap-free stretch (one warning says so).
    Rates that fit deg/s better than rad/s get a warning too
    (:func:`selfnav.io.imu.check_rest_units`).

    Returns
    -------
    dict with ``tau`` (M,), ``gyro_adev`` (M, 3) rad/s, ``accel_adev`` (M, 3) m/s²,
    ``gyro`` and ``accel``: lists of three :class:`NoiseTerms`, ``dt``, ``samples`` and
    ``t_start``, ``t_end`` (the stretch analysed, s).
    """
    imu = longest_stretch(imu, "the Allan analysis")
    if len(imu) < MIN_SAMPLES:
        raise InputError(imu.source or "IMU data", f"has {len(imu)} samples: too short for an "
                         f"Allan analysis (at least {MIN_SAMPLES})")
    check_rest_units(imu)
    dt = imu.dt
    tau, ag, cnt = allan_deviation(imu.omega_ib_b, dt, m)
    _, aa, _ = allan_deviation(imu.f_ib_b, dt, m)
    return {
        "tau": tau, "clusters": cnt, "gyro_adev": ag, "accel_adev": aa, "dt": dt,
        "samples": len(imu), "t_start": float(imu.t[0]), "t_end": float(imu.t[-1]),
        "gyro": [identify(tau, ag[:, k], duration=imu.duration) for k in range(3)],
        "accel": [identify(tau, aa[:, k], duration=imu.duration) for k in range(3)],
    }


def plot_allan(result: dict, path, title: str = "Allan deviation"):
    """Log-log plot of the gyro (°/h) and accelerometer (m/s²) Allan deviations, with the
    identified white-noise and bias-instability lines; written as PNG to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tau = result["tau"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), constrained_layout=True)
    scale = {"gyro": np.degrees(1.0) * 3600.0, "accel": 1.0}
    units = {"gyro": "°/h", "accel": "m/s²"}
    colors = ("tab:red", "tab:green", "tab:blue")
    for ax, key in zip(axes, ("gyro", "accel")):
        ad = result[f"{key}_adev"] * scale[key]
        for k in range(3):
            ax.loglog(tau, ad[:, k], "-", color=colors[k], label="xyz"[k])
            term = result[key][k]
            if np.isfinite(term.white):
                ax.loglog(tau, term.white * scale[key] / np.sqrt(tau), ":", color=colors[k], lw=0.8)
            ax.axhline(term.bias_instability * FLICKER_FLOOR * scale[key], color=colors[k],
                       ls="--", lw=0.6)
        ax.set_xlabel("τ, s")
        ax.set_ylabel(f"Allan deviation, {units[key]}")
        ax.set_title(f"{key}: dotted N/√τ, dashed 0.664·B")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle(title)
    try:
        write_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
    return path


def summary(res: dict) -> dict:
    """The ``selfnav allan --json`` keys (DESIGN §6: lists of three, x y z) and the details, in
    the units their names say."""
    g, a = res["gyro"], res["accel"]
    return {
        "arw_deg_per_sqrt_h": [np.degrees(x.white) * SQRT_S_TO_SQRT_H for x in g],
        "bias_instability_deg_per_h": [x.bias_instability * RAD_S_TO_DEG_H for x in g],
        "vrw_m_per_s_per_sqrt_h": [x.white * SQRT_S_TO_SQRT_H for x in a],
        "accel_bias_instability_m_per_s2": [x.bias_instability for x in a],
        "gyro_rate_random_walk_deg_per_h_per_sqrt_h": [
            x.random_walk * RAD_S_TO_DEG_H * SQRT_S_TO_SQRT_H for x in g],
        "accel_random_walk_m_per_s2_per_sqrt_h": [x.random_walk * SQRT_S_TO_SQRT_H for x in a],
        "gyro_bias_instability_tau_s": [x.bias_instability_tau for x in g],
        "accel_bias_instability_tau_s": [x.bias_instability_tau for x in a],
        "gyro_bias_instability_is_upper_bound": [x.bias_instability_bound for x in g],
        "accel_bias_instability_is_upper_bound": [x.bias_instability_bound for x in a],
        "samples": res["samples"], "dt_s": res["dt"],
        "t_start_s": res.get("t_start"), "t_end_s": res.get("t_end"),
    }
