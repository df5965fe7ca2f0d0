"""The native IMU CSV reader (DESIGN §6: ``t, wx, wy, wz, fx, fy, fz``), the unit checks every
IMU reader applies, and the gaps of a record (:func:`imu_gaps`, :func:`bridge_gaps`,
:func:`imu_segments`, :func:`longest_stretch`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from selfnav.earth import OMEGA_EARTH
from selfnav.errors import InputError, warn
from selfnav.io.csvio import check_time, read_table
from selfnav.types import ImuData

IMU_COLUMNS = ("t", "wx", "wy", "wz", "fx", "fy", "fz")


def check_imu_units(imu: ImuData, path=None) -> None:
    """Reject gyro and accelerometer values whose magnitudes betray wrong units.

    Gyros: a rate above 35 rad/s (2000 deg/s, the top of MEMS ranges) for more than 1 % of the
    samples means deg/s or deg/h. Accelerometers: a median |f| near 1 means g units; above
    60 m/s^2 means cm/s^2, mg or counts; below 3 m/s^2 is not a specific force on Earth.
    """
    path = path or imu.source
    w = np.sqrt(np.einsum("ij,ij->i", imu.omega_ib_b, imu.omega_ib_b))
    if np.mean(w > 35.0) > 0.01:
        raise InputError(path, f"gyro rates reach {np.max(w):.4g} (median {np.median(w):.4g}): "
                         "these look like deg/s or deg/h, the file needs rad/s", column="wx")
    fn = np.sqrt(np.einsum("ij,ij->i", imu.f_ib_b, imu.f_ib_b))
    med = float(np.median(fn))
    if 0.7 < med < 1.4:
        raise InputError(path, f"median specific force is {med:.4g}: this looks like g units, the "
                         "file needs m/s^2 (multiply by 9.80665)", column="fx")
    if med > 60.0:
        raise InputError(path, f"median specific force is {med:.4g}: this looks like cm/s^2, mg or "
                         "raw counts, the file needs m/s^2", column="fx")
    if med < 3.0:
        raise InputError(path, f"median specific force is {med:.4g} m/s^2, far from gravity "
                         "(9.8): is it gravity-compensated acceleration, or in other units? "
                         "The file needs specific force in m/s^2", column="fx")


def read_imu_csv(path) -> ImuData:
    """Read the native IMU CSV (DESIGN §6)."""
    tab = read_table(path, IMU_COLUMNS, optional=("mx", "my", "mz", "position"))
    t = check_time(tab, min_rows=2)
    w = np.column_stack([tab["wx"], tab["wy"], tab["wz"]])
    f = np.column_stack([tab["fx"], tab["fy"], tab["fz"]])
    mag = None
    if all(k in tab for k in ("mx", "my", "mz")):
        mag = np.column_stack([tab["mx"], tab["my"], tab["mz"]])
    pos = tab["position"].astype(int) if "position" in tab else None
    imu = ImuData(t, w, f, mag, pos, source=str(path))
    check_imu_units(imu, path)
    return imu


def earth_rate_ratio(imu: ImuData) -> float:
    """|mean ω| / Earth rate: ~1 at rest; ~57 for deg/s, ~2e5 for deg/h."""
    return float(np.linalg.norm(imu.omega_ib_b.mean(axis=0)) / OMEGA_EARTH)


# --------------------------------------------------------------------------------------------
# Gaps: rows missing from a record (dropouts, a logger that stalled)
# --------------------------------------------------------------------------------------------
#: Gaps of at most this many missing samples are bridged (filled by linear interpolation):
#: at 100 Hz that is 50 ms, over which a vehicle's rates and specific force change little.
MAX_BRIDGE_SAMPLES = 5

#: A step longer than this many nominal sample intervals is a gap (timing jitter is not).
GAP_FACTOR = 1.5


@dataclass(frozen=True)
class ImuGap:
    """Samples missing between two rows of an IMU record.

    Attributes
    ----------
    index : int
        Row index of the first sample after the gap.
    t_before, t_after : float
        Time of the last row before and the first row after the gap, s.
    missing : int
        Samples missing at the nominal interval.
    duration : float
        Time no row covers, s (``t_after − t_before − dt``: the row at ``t_after`` covers the
        interval that ends there).
    """

    index: int
    t_before: float
    t_after: float
    missing: int
    duration: float

    def describe(self) -> str:
        """``"a 60 s IMU gap at t = 1234.560 s (6000 samples missing)"``."""
        d = self.duration
        span = f"{d / 3600:.3g} h" if d >= 3600 else f"{d:.4g} s"
        return f"a {span} IMU gap at t = {self.t_before:.3f} s ({self.missing} samples missing)"


def imu_gaps(imu: ImuData, min_missing: int = 1) -> list[ImuGap]:
    """Gaps of a record: steps longer than :data:`GAP_FACTOR` nominal (median) intervals.

    Parameters
    ----------
    imu : ImuData
    min_missing : int
        Report only gaps with at least this many missing samples (``MAX_BRIDGE_SAMPLES + 1``
        gives the gaps :func:`bridge_gaps` leaves, those that end a segment).
    """
    if len(imu) < 3:
        return []
    dt = imu.dt
    d = np.diff(imu.t)
    idx = np.flatnonzero(d > GAP_FACTOR * dt)
    out = []
    for k in idx:
        missing = int(round(d[k] / dt)) - 1
        if missing >= max(min_missing, 1):
            out.append(ImuGap(int(k + 1), float(imu.t[k]), float(imu.t[k + 1]), missing,
                              float(d[k] - dt)))
    return out


def imu_segments(imu: ImuData, max_bridge_samples: int = MAX_BRIDGE_SAMPLES) -> list[slice]:
    """Row slices of the stretches between gaps longer than ``max_bridge_samples`` samples."""
    cuts = [g.index for g in imu_gaps(imu, max_bridge_samples + 1)]
    edges = [0, *cuts, len(imu)]
    return [slice(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def bridge_gaps(imu: ImuData, max_bridge_samples: int = MAX_BRIDGE_SAMPLES) -> ImuData:
    """Fill gaps of at most ``max_bridge_samples`` missing samples by linear interpolation.

    The rows inserted lie evenly over the gap (rate, specific force and magnetometer
    interpolated between the rows either side; the position index of the row before); longer
    gaps are left for the caller (:func:`imu_segments`). ``meta["bridged_samples"]`` counts the
    rows added. Returns ``imu`` itself when nothing is bridged.
    """
    short = [g for g in imu_gaps(imu) if g.missing <= max_bridge_samples]
    if not short:
        return imu
    t_new = np.concatenate([
        g.t_before + (g.t_after - g.t_before) * np.arange(1, g.missing + 1) / (g.missing + 1)
        for g in short])
    t = np.concatenate([imu.t, t_new])
    order = np.argsort(t, kind="stable")

    def fill(x):
        if x is None:
            return None
        x = np.asarray(x)
        if x.ndim == 1:  # position index: the row before
            k = np.searchsorted(imu.t, t_new, side="right") - 1
            return np.concatenate([x, x[k]])[order]
        cols = [np.interp(t_new, imu.t, x[:, j]) for j in range(x.shape[1])]
        return np.concatenate([x, np.column_stack(cols)])[order]

    meta = dict(imu.meta)
    meta["bridged_samples"] = int(meta.get("bridged_samples", 0) + len(t_new))
    return ImuData(t[order], fill(imu.omega_ib_b), fill(imu.f_ib_b), fill(imu.mag_b),
                   fill(imu.position), imu.source, meta)


def longest_stretch(imu: ImuData, what: str = "the analysis",
                    max_bridge_samples: int = MAX_BRIDGE_SAMPLES) -> ImuData:
    """The longest gap-free stretch of a record (short gaps bridged), with a one-line
    :class:`~selfnav.errors.SelfnavWarning` naming the gaps when there are any."""
    imu = bridge_gaps(imu, max_bridge_samples)
    segs = imu_segments(imu, max_bridge_samples)
    if len(segs) <= 1:
        return imu
    gaps = imu_gaps(imu, max_bridge_samples + 1)
    best = max(segs, key=lambda s: imu.t[s.stop - 1] - imu.t[s.start])
    part = imu.select(best)
    first = gaps[0].describe()
    more = f" and {len(gaps) - 1} more" if len(gaps) > 1 else ""
    warn(f"{imu.source or 'IMU data'}: {first}{more}; {what} uses the longest gap-free stretch, "
         f"{part.t[0]:.3f}-{part.t[-1]:.3f} s ({len(part)} of {len(imu)} samples)")
    return part


#: Angle random walk no gyro has, °/√h: rad/s data of a MEMS gyro in deg/s read as rad/s shows
#: 57 × its noise (consumer 0.4 °/√h → 24 °/√h).
MAX_PLAUSIBLE_ARW_DEG_PER_SQRT_H = 6.0


def rest_noise_density(x, dt: float) -> float:
    """White-noise density of a signal at rest from its sample-to-sample differences (bias and
    slow drift cancel): median over the axes of ``std(Δx)/√2 · √dt``, units of x times √s."""
    x = np.asarray(x, dtype=float)
    if len(x) < 3:
        return float("nan")
    return float(np.median(np.std(np.diff(x, axis=0), axis=0)) / np.sqrt(2.0) * np.sqrt(dt))


#: RMS variation of |f| above which a record is not at rest, m/s² (a consumer MEMS at rest:
#: ~0.02; a car on a road: ~0.6).
MAX_REST_F_RMS = 0.2


#: RMS of the 1-s mean gyro rate (beyond its white noise) above which a record turns, rad/s
#: (0.5 °/s: no gyro's bias wanders that much within a record; a car's corners: 10-30 °/s, a
#: ship's roll: a few °/s)
MAX_REST_RATE_RMS = np.radians(0.5)
#: RMS of the 1-s mean specific force per axis (beyond its white noise) above which a record
#: moves, m/s² (0.5: a 3° tilt swing or a car's accelerations; the Xi'an vehicle's 0.2° drift:
#: 0.03)
MAX_REST_F_AXIS_RMS = 0.5


def _excess_rms(x, n_block: int) -> np.ndarray:
    """RMS of the ``n_block``-sample means of ``x`` (per column) beyond what its white noise
    alone gives them (the noise from the sample-to-sample differences)."""
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    k = len(x) // n_block
    means = x[: k * n_block].reshape(k, n_block, -1).mean(axis=1)
    white2 = np.var(np.diff(x, axis=0), axis=0) / 2.0 / n_block
    return np.sqrt(np.clip(np.var(means, axis=0) - white2, 0.0, None))


def motion_of(imu: ImuData) -> str:
    """What says a record meant to be at rest moves (empty when nothing does), judged on 1-s
    means beyond the sensor's white noise (so a noisy sensor at rest is not "moving"): the
    rate turning (:data:`MAX_REST_RATE_RMS`), ``|f|`` varying (:data:`MAX_REST_F_RMS`: the
    unit accelerating), or the specific force swinging on an axis (:data:`MAX_REST_F_AXIS_RMS`:
    tilting, rocking)."""
    n_block = max(int(round(1.0 / imu.dt)), 1)
    if len(imu) < 10 * n_block:
        n_block = max(len(imu) // 10, 1)
    if len(imu) < 2 * n_block or len(imu) < 10:
        return ""
    f = imu.f_ib_b
    w = _excess_rms(imu.omega_ib_b, n_block).max()
    fn = float(_excess_rms(np.sqrt(np.einsum("ij,ij->i", f, f)), n_block)[0])
    fa = _excess_rms(f, n_block).max()
    if w > MAX_REST_RATE_RMS:
        return f"the gyros show it turning, {np.degrees(w):.2g} °/s RMS (1-s means)"
    if fn > MAX_REST_F_RMS:
        return f"|f| varies by {fn:.2g} m/s² RMS (1-s means): the unit is accelerating"
    if fa > MAX_REST_F_AXIS_RMS:
        return f"the specific force swings by {fa:.2g} m/s² RMS on an axis (1-s means): tilting"
    return ""


def check_rest_units(imu: ImuData, path=None) -> None:
    """One-line warnings for a record meant to be at rest (``allan``, ``latitude``): one that
    moves, and gyros that fit deg/s better than rad/s.

    * moving (:func:`motion_of`: the 1-s means turning, ``|f|`` varying, the specific force
      swinging beyond the white noise): not at rest (the Allan deviation of a moving record
      measures the motion);
    * a mean rate beyond 3000 × the Earth rate (12.6 °/s): no gyro bias is that large, a MEMS
      bias in deg/s is;
    * a white noise above :data:`MAX_PLAUSIBLE_ARW_DEG_PER_SQRT_H`: a MEMS gyro's noise in
      deg/s;
    * a mean rate 45-70 × the Earth rate with a quiet gyro: the Earth rate in deg/s, if the gyro
      is navigation or tactical grade (a MEMS bias can land there too: the message says so).

    (Accelerometers in g are refused by :func:`check_imu_units`.)
    """
    path = path or imu.source or "IMU data"
    if len(imu) < 3:
        return
    moving = motion_of(imu)
    if moving:
        warn(f"{path}: not at rest: {moving}; an Allan or latitude analysis of a moving record "
             "measures the motion, not the sensor")
        return
    ratio = earth_rate_ratio(imu)
    arw = np.degrees(rest_noise_density(imu.omega_ib_b, imu.dt)) * 60.0
    if ratio > 3000.0:
        warn(f"{path}: the mean gyro rate at rest is {ratio:.4g} × the Earth rate, more than "
             "any gyro bias: the gyros look like deg/s, the file needs rad/s")
    elif arw > MAX_PLAUSIBLE_ARW_DEG_PER_SQRT_H:
        warn(f"{path}: gyro white noise {arw:.3g} °/√h is beyond any gyro's: the rates look "
             "like deg/s, the file needs rad/s")
    elif 45.0 < ratio < 70.0:
        warn(f"{path}: the mean gyro rate at rest is {ratio:.3g} × the Earth rate (57.3 × in "
             "deg/s): if the gyros are navigation or tactical grade the file is in deg/s and "
             "needs rad/s (a MEMS gyro's bias can also be that large)")


def report_gaps(imu: ImuData, max_bridge_samples: int = MAX_BRIDGE_SAMPLES) -> ImuData:
    """Bridge the short gaps of a record and warn, one line each (at most three, then a count),
    about the longer ones, which end a segment; returns the bridged record."""
    imu = bridge_gaps(imu, max_bridge_samples)
    gaps = imu_gaps(imu, max_bridge_samples + 1)
    src = imu.source or "IMU data"
    for g in gaps[:3]:
        warn(f"{src}: {g.describe()}")
    if len(gaps) > 3:
        warn(f"{src}: {len(gaps) - 3} more IMU gaps, {sum(g.duration for g in gaps[3:]):.4g} s "
             "in all")
    return imu


def _time_unit_guess(dt: float) -> str:
    """The unit a time column of median step ``dt`` (read as seconds) is most likely in: the one
    that makes the rate a sensor's (1 Hz to 10 kHz)."""
    for unit, k in (("milliseconds", 1e3), ("microseconds", 1e6), ("nanoseconds", 1e9)):
        if 1e-4 <= dt / k <= 1.0:
            return unit
    return "milliseconds"


def check_imu_rate(imu: ImuData, what: str, *, min_duration_s: float = 0.0,
                   max_dt_s: float | None = None, warn_dt_s: float | None = None,
                   path=None) -> None:
    """Plausibility of a record's length and sample interval for a command, one line each.

    Refuses a record shorter than ``min_duration_s`` or sampled more coarsely than
    ``max_dt_s`` (:class:`InputError`); warns above ``warn_dt_s``, and for intervals below
    0.1 ms (a time column in hours or days?).
    """
    path = path or imu.source or "IMU data"
    n = len(imu)
    span = float(imu.t[-1] - imu.t[0]) if n > 1 else 0.0
    if n < 2 or span < min_duration_s:
        raise InputError(path, f"has {n} samples over {span:.4g} s: {what} needs at least "
                         f"{min_duration_s:g} s of IMU data")
    dt = imu.dt
    if max_dt_s is not None and dt > max_dt_s:
        raise InputError(path, f"median sample interval {dt:.4g} s ({1 / dt:.3g} Hz) is too coarse "
                         f"for {what} (at most {max_dt_s:g} s); is the time column in "
                         f"{_time_unit_guess(dt)}?", column="t")
    if warn_dt_s is not None and dt > warn_dt_s:
        warn(f"{path}: median sample interval {dt:.4g} s ({1 / dt:.3g} Hz) is coarse for {what}; "
             f"expect larger errors than at {1 / warn_dt_s:.3g} Hz or more")
    if dt < 1e-4:
        warn(f"{path}: median sample interval {dt:.3g} s ({1 / dt:.3g} Hz): is the time column "
             "in hours or days instead of seconds?")
