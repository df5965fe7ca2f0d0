"""Sensor error models: gyro and accelerometer, magnetometer, GNSS (issue 3; DESIGN §5, §7).

Every model draws its random constants (turn-on bias, scale factor, misalignment) and its noise
from a ``numpy.random.Generator`` passed in, so that the same seed gives the same data.

Inertial errors, per axis (IEEE Std 952 / 1293 noise terms)::

    ω̃ = (I + S + M) ω + b0 + b_GM(t) + b_RRW(t) + n_ARW,          same form for f

* ``b0`` turn-on bias, ``b_GM`` first-order Gauss-Markov bias instability with correlation
  time τ, ``b_RRW`` rate random walk, ``n_ARW`` white noise (angle / velocity random walk);
* ``S`` scale-factor errors (diagonal), ``M`` axis misalignment and non-orthogonality
  (off-diagonal, small angles);
* quantisation of the angle / velocity increments (the residual is carried, as in a real
  pulse-counting sensor).

Bias instability ``B`` is the datasheet figure, defined by the Allan-deviation floor
``σ_A,min = B·sqrt(2 ln2/π) ≈ 0.664 B`` (IEEE 952 flicker floor). A Gauss-Markov process of
stationary σ_GM has its Allan-deviation peak ``0.617 σ_GM`` at ``T ≈ 1.89 τ``; the model sets
``σ_GM = 0.664 B / 0.617`` so that :mod:`selfnav.allan` reads ``B`` back.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from selfnav import attitude as att
from selfnav.earth import radii
from selfnav.errors import SelfnavError
from selfnav.types import GnssData
from selfnav.units import DEG, DEG_PER_H, DEG_PER_SQRT_H, G0, MPS_PER_SQRT_H, PPM, UG


#: Allan-deviation floor of flicker bias instability, in units of B (IEEE 952, Table C.1).
FLICKER_FLOOR = float(np.sqrt(2.0 * np.log(2.0) / np.pi))


def gm_allan_peak() -> float:
    """Peak of the Allan deviation of a unit first-order Gauss-Markov process (σ = 1, any τ).

    ``σ_A²(T) = (2τ/T)[1 - τ/(2T)(3 - 4e^{-T/τ} + e^{-2T/τ})]`` (IEEE 952 C.1.7 with
    ``q_c = 2σ²/τ``); maximum 0.617 at ``T/τ ≈ 1.89``.
    """
    x = np.linspace(0.2, 10.0, 20001)
    v = (2.0 / x) * (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x))
    return float(np.sqrt(v.max()))


GM_ALLAN_PEAK = gm_allan_peak()


def _vec3(v):
    return np.broadcast_to(np.asarray(v, dtype=float), (3,)).copy()


@dataclass
class SensorTriad:
    """Error specification of one three-axis sensor (gyro: rad, s; accelerometer: m, s).

    All values are 1σ per axis (scalar or (3,)) unless said otherwise.

    Attributes
    ----------
    bias : turn-on bias σ (rad/s or m/s²), drawn once per run
    bias_instability : datasheet bias instability ``B`` (Allan floor / 0.664)
    bias_tau : correlation time of the Gauss-Markov bias, s
    white : noise density, ARW rad/√s or VRW (m/s)/√s
    random_walk : rate random walk, rad/s/√s (or m/s²/√s)
    scale_factor : scale-factor error σ, fraction (ppm·1e-6)
    misalignment : axis misalignment / non-orthogonality σ, rad (each off-diagonal element)
    quantum : increment quantum, rad or m/s (0: none)
    """

    bias: object = 0.0
    bias_instability: object = 0.0
    bias_tau: float = 100.0
    white: object = 0.0
    random_walk: object = 0.0
    scale_factor: object = 0.0
    misalignment: object = 0.0
    quantum: float = 0.0

    def realize(self, rng) -> dict:
        """Draw the run constants: ``b0`` (3,), ``T = I + S + M`` (3, 3)."""
        b0 = _vec3(self.bias) * rng.normal(size=3)
        sf = _vec3(self.scale_factor) * rng.normal(size=3)
        mis = np.asarray(self.misalignment, dtype=float) * rng.normal(size=(3, 3))
        np.fill_diagonal(mis, 0.0)
        return {"bias": b0, "matrix": np.eye(3) + np.diag(sf) + mis}

    def apply(self, dt, x, rng, consts=None):
        """Corrupt a true rate series ``x`` (N, 3) sampled every ``dt`` s; returns ``(x̃, consts)``.

        ``x`` is the mean rate over each interval (increment / dt); quantisation acts on the
        increments ``x̃·dt``.
        """
        n = len(x)
        c = self.realize(rng) if consts is None else consts
        y = x @ c["matrix"].T + c["bias"]
        bi = _vec3(self.bias_instability)
        if np.any(bi > 0):
            sig = bi * FLICKER_FLOOR / GM_ALLAN_PEAK
            a = np.exp(-dt / self.bias_tau)
            w = rng.normal(size=(n, 3)) * sig * np.sqrt(1.0 - a * a)
            zi = (a * sig * rng.normal(size=3))[None, :]  # stationary start
            gm = _ar1(a, w, zi)
            y = y + gm
            c["gauss_markov"] = gm
        rw = _vec3(self.random_walk)
        if np.any(rw > 0):
            c["random_walk"] = np.cumsum(rng.normal(size=(n, 3)) * rw * np.sqrt(dt), axis=0)
            y = y + c["random_walk"]
        wh = _vec3(self.white)
        if np.any(wh > 0):
            y = y + rng.normal(size=(n, 3)) * wh / np.sqrt(dt)
        if self.quantum > 0:
            q = self.quantum
            cum = np.floor(np.cumsum(y * dt, axis=0) / q + rng.uniform(size=3)) * q
            y = np.diff(np.vstack([np.zeros((1, 3)), cum]), axis=0) / dt
        return y, c


@dataclass
class ImuErrorModel:
    """Gyro and accelerometer error model of one IMU (see the module docstring).

    Attributes
    ----------
    gyro, accel : SensorTriad
    name : str
        Grade or part name, written into simulated files.
    """

    gyro: SensorTriad = field(default_factory=SensorTriad)
    accel: SensorTriad = field(default_factory=SensorTriad)
    name: str = "custom"

    def apply(self, t, omega_ib_b, f_ib_b, rng, *, return_errors=False):
        """Corrupt true rates (mean over each sample interval) with this model.

        Parameters
        ----------
        t : (N,) s, uniformly sampled (the end of each interval)
        omega_ib_b : (N, 3) rad/s
        f_ib_b : (N, 3) m/s²
        rng : numpy Generator or seed
        return_errors : bool
            Also return the drawn constants and processes (for tests and error budgets).

        Returns
        -------
        omega, f : (N, 3) measured rates [, errors dict]
        """
        rng = np.random.default_rng(rng)
        t = np.asarray(t, dtype=float)
        d = np.diff(t)
        dt = float(np.mean(d)) if len(d) else 1.0
        if len(d) and np.max(np.abs(d - dt)) > 1e-6 * dt + 1e-9:
            raise SelfnavError("ImuErrorModel.apply needs uniformly sampled data")
        w, cg = self.gyro.apply(dt, np.asarray(omega_ib_b, dtype=float), rng)
        f, ca = self.accel.apply(dt, np.asarray(f_ib_b, dtype=float), rng)
        if return_errors:
            return w, f, {"gyro": cg, "accel": ca}
        return w, f

    def apply_increments(self, t, dtheta, dv, rng, **kw):
        """:meth:`apply` for increments ``Δθ``, ``Δv`` over intervals ending at ``t``."""
        dt = float(np.mean(np.diff(t))) if len(t) > 1 else 1.0
        out = self.apply(t, np.asarray(dtheta) / dt, np.asarray(dv) / dt, rng, **kw)
        return (out[0] * dt, out[1] * dt) + tuple(out[2:])

    def scaled(self, k: float) -> "ImuErrorModel":
        """All error magnitudes multiplied by ``k`` (0 gives a perfect IMU)."""
        def sc(tr):
            return dataclasses.replace(
                tr, **{f: np.asarray(getattr(tr, f)) * k for f in (
                    "bias", "bias_instability", "white", "random_walk", "scale_factor",
                    "misalignment")}, quantum=tr.quantum * (k > 0))
        return ImuErrorModel(sc(self.gyro), sc(self.accel), f"{self.name} x{k:g}")


# Grade presets. Numbers are the public datasheet values named beside them (1σ or typical as
# the datasheet states); values a datasheet does not give are marked "assumed" with the reason.
GRADES = {
    # Honeywell HG9900 IMU datasheet (ring-laser gyro, navigation grade): gyro bias stability
    # 0.003 °/h, ARW 0.002 °/√h, scale factor 5 ppm; accel bias 25 µg, scale factor 100 ppm.
    # Assumed: VRW 0.0003 m/s/√h (not in the sheet), GM τ 3600 s, misalignment 2 µrad (5''),
    # turn-on biases equal to the stability figures, RLG quantum 0.2'' per pulse (typical).
    "navigation": ImuErrorModel(
        SensorTriad(bias=0.003 * DEG_PER_H, bias_instability=0.003 * DEG_PER_H, bias_tau=3600.0,
                    white=0.002 * DEG_PER_SQRT_H, scale_factor=5 * PPM, misalignment=2e-6,
                    quantum=0.2 / 3600 * DEG),
        SensorTriad(bias=25 * UG, bias_instability=10 * UG, bias_tau=3600.0,
                    white=0.0003 * MPS_PER_SQRT_H, scale_factor=100 * PPM, misalignment=5e-6),
        "navigation (RLG, HG9900)"),
    # KVH 1750 IMU datasheet (fibre-optic gyro, tactical grade): gyro bias instability
    # 0.05 °/h, ARW 0.012 °/√h, bias offset 2 °/h, scale factor 50 ppm (1σ); accel (10 g):
    # bias instability 0.05 mg, VRW 0.12 mg/√Hz (= 0.0706 m/s/√h), bias 1 mg, SF 100 ppm.
    # Assumed: GM τ 300 s, misalignment 0.1 mrad.
    "tactical": ImuErrorModel(
        SensorTriad(bias=2.0 * DEG_PER_H, bias_instability=0.05 * DEG_PER_H, bias_tau=300.0,
                    white=0.012 * DEG_PER_SQRT_H, scale_factor=50 * PPM, misalignment=1e-4),
        SensorTriad(bias=1000 * UG, bias_instability=50 * UG, bias_tau=300.0,
                    white=0.12e-3 * G0, scale_factor=100 * PPM, misalignment=1e-4),
        "tactical (FOG, KVH 1750)"),
    # Analog Devices ADIS16465-1 datasheet (industrial MEMS, the OB_GINS demo IMU): gyro in-run
    # bias stability 2 °/h, ARW 0.15 °/√h, axis misalignment 0.05° (0.87 mrad); accel in-run
    # bias stability 3.6 µg, VRW 0.012 m/s/√h. Assumed (residuals after the factory
    # calibration, not in the sheet): turn-on bias 0.05 °/s and 2 mg, scale factor 0.1 %,
    # GM τ 100 s, rate random walk 1 °/h/√h.
    "industrial": ImuErrorModel(
        SensorTriad(bias=0.05 * DEG, bias_instability=2.0 * DEG_PER_H, bias_tau=100.0,
                    white=0.15 * DEG_PER_SQRT_H, random_walk=1.0 * DEG_PER_H / 60.0,
                    scale_factor=1000 * PPM, misalignment=0.87e-3),
        SensorTriad(bias=2000 * UG, bias_instability=3.6 * UG, bias_tau=100.0,
                    white=0.012 * MPS_PER_SQRT_H, scale_factor=1000 * PPM, misalignment=0.6e-3),
        "industrial MEMS (ADIS16465)"),
    # Bosch BMI160 datasheet (consumer MEMS): gyro output noise 0.007 °/s/√Hz, zero-rate
    # offset ±3 °/s (σ 1 °/s assumed), sensitivity tolerance ±1 %, cross-axis 1 %; accel
    # noise 180 µg/√Hz, zero-g offset ±40 mg (σ 20 mg assumed), cross-axis 1 %, 16-bit output
    # (2000 °/s range: 0.061 °/s LSB; 4 g: 0.122 mg LSB). Not in the sheet, assumed from
    # published Allan plots of such parts: bias instability 10 °/h and 50 µg, τ 30 s.
    "consumer": ImuErrorModel(
        SensorTriad(bias=1.0 * DEG, bias_instability=10 * DEG_PER_H, bias_tau=30.0,
                    white=0.007 * DEG, scale_factor=0.01, misalignment=0.01,
                    quantum=0.0),
        SensorTriad(bias=0.020 * G0, bias_instability=50 * UG, bias_tau=30.0,
                    white=180 * UG, scale_factor=0.01, misalignment=0.01),
        "consumer MEMS (BMI160)"),
}


#: The one sensor-grade vocabulary of the package (best first). ``perfect`` (no errors) is for
#: the simulator; ``auto`` (noise measured from the data) for the navigator.
GRADE_NAMES = tuple(GRADES)


def grade_key(name: str) -> str:
    """Normalised grade name (lower case, stripped)."""
    return str(name).lower().strip()


def imu_grade(name: str) -> ImuErrorModel:
    """The preset error model of a grade: navigation, tactical, industrial, consumer, perfect."""
    key = grade_key(name)
    if key == "perfect":
        return GRADES["navigation"].scaled(0.0)
    if key not in GRADES:
        raise SelfnavError(f"unknown IMU grade '{name}' (use {', '.join(GRADES)} or perfect)")
    return GRADES[key]


# ---------------------------------------------------------------- magnetometer

# IGRF-13 epoch 2020 first-degree Gauss coefficients, nT (the fallback tilted dipole).
_G10, _G11, _H11 = -29404.8, -1450.9, 4652.5
_R_REF = 6371200.0


def earth_field_n(lat, lon, h=0.0, date=None, model: str = "auto"):
    """Earth magnetic field in ENU, nT, shape ``(..., 3)``.

    ``model="igrf"`` (and ``"auto"``) is IGRF-14 shipped with the package
    (:func:`selfnav.igrf.igrf_enu`, at ``date``, default 2025-01-01); ``"dipole"`` the IGRF-13
    (2020) tilted dipole, kept for comparison: it is wrong by tens of degrees in declination in
    places (−17.6° at Kotka where IGRF gives +11.0°).
    """
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    h = np.asarray(h, dtype=float)
    if model in ("auto", "igrf"):
        from selfnav.igrf import igrf_enu

        return igrf_enu(lat, lon, h, date)
    if model != "dipole":
        raise SelfnavError(f"unknown magnetic field model '{model}' (igrf, dipole, auto)")
    th = np.pi / 2 - lat
    r = (_R_REF + h) / _R_REF
    k = r ** -3
    gl = _G11 * np.cos(lon) + _H11 * np.sin(lon)
    br = 2 * k * (_G10 * np.cos(th) + gl * np.sin(th))
    bth = k * (_G10 * np.sin(th) - gl * np.cos(th))
    blam = k * (_G11 * np.sin(lon) - _H11 * np.cos(lon))
    return np.stack(np.broadcast_arrays(blam, -bth, br), -1)


def declination_inclination(b_n):
    """Declination (east of true North) and inclination (down positive), rad, of an ENU field."""
    b_n = np.asarray(b_n, dtype=float)
    dec = np.arctan2(b_n[..., 0], b_n[..., 1])
    inc = np.arctan2(-b_n[..., 2], np.hypot(b_n[..., 0], b_n[..., 1]))
    return dec, inc


@dataclass
class MagnetometerModel:
    """Three-axis magnetometer: ``m = W C_n^b B_n + b_hard + noise`` (nT).

    Attributes
    ----------
    hard_iron : (3,) nT, constant offset (vehicle permanent magnetisation)
    soft_iron : (3, 3) ``W``, identity for none (induced magnetisation, sensitivities)
    noise : nT, white, per axis
    field_model : "auto", "igrf" or "dipole" (:func:`earth_field_n`)
    """

    hard_iron: object = (0.0, 0.0, 0.0)
    soft_iron: object = field(default_factory=lambda: np.eye(3))
    noise: float = 0.0
    field_model: str = "auto"
    date: object = None

    @classmethod
    def typical_car(cls, rng) -> "MagnetometerModel":
        """A car-mounted consumer magnetometer: 500 nT hard iron, 2 % soft iron, 100 nT noise."""
        rng = np.random.default_rng(rng)
        a = 0.02 * rng.normal(size=(3, 3))
        return cls(hard_iron=500.0 * rng.normal(size=3), soft_iron=np.eye(3) + 0.5 * (a + a.T),
                   noise=100.0)

    def measure(self, lat, lon, h, C_nb, rng):
        """Magnetometer readings (N, 3) nT along a trajectory."""
        rng = np.random.default_rng(rng)
        lat, lon, h = (np.atleast_1d(np.asarray(x, dtype=float)) for x in (lat, lon, h))
        b_n = earth_field_n(np.mean(lat), np.mean(lon), np.mean(h), self.date, self.field_model)
        if np.ptp(lat) + np.ptp(lon) > 1e-3:  # more than ~6 km: follow the field (2000 knots)
            k = np.unique(np.linspace(0, len(lat) - 1, 2000).astype(int))
            bk = earth_field_n(lat[k], lon[k], h[k], self.date, self.field_model)
            i = np.arange(len(lat))
            b_n = np.column_stack([np.interp(i, k, bk[:, j]) for j in range(3)])
        b_b = np.einsum("nij,nj->ni", C_nb, np.broadcast_to(b_n, (len(C_nb), 3)))
        m = b_b @ np.asarray(self.soft_iron, dtype=float).T + np.asarray(self.hard_iron)
        return m + self.noise * rng.normal(size=m.shape)


def magnetic_heading(mag_b, roll, pitch, declination=0.0):
    """Tilt-compensated heading from a magnetometer, rad in [0, 2π) — seed 004's ``K^H``.

    With ``C_n^b = R_y(roll) R_x(pitch) R_z(-H)`` (DESIGN §2), levelling the reading,
    ``m_h = R_x(pitch)^T R_y(roll)^T m_b = R_z(-H) B_n``, gives ``m_h = |B_h|(sin(D-H), cos(D-H))``,
    so ``H = D + atan2(-m_hx, m_hy)``. ``declination = 0`` returns the magnetic heading.
    """
    m = np.asarray(mag_b, dtype=float)
    Rt = np.swapaxes(att.frame_rotation(1, roll) @ att.frame_rotation(0, pitch), -1, -2)
    mh = np.einsum("...ij,...j->...i", Rt, m)
    return np.mod(np.arctan2(-mh[..., 0], mh[..., 1]) + declination, 2 * np.pi)


def mean_heading(heading, k: int):
    """Seed 004 (12): mean of ``k`` consecutive headings, as a circular mean (wrap-safe)."""
    h = np.asarray(heading, dtype=float)
    n = len(h) // k
    s = np.sin(h[:n * k]).reshape(n, k).mean(1)
    c = np.cos(h[:n * k]).reshape(n, k).mean(1)
    return np.mod(np.arctan2(s, c), 2 * np.pi)


# ---------------------------------------------------------------- GNSS

@dataclass
class OutlierWindow:
    """An unflagged GNSS outlier episode (seed 004: up to 5 min at 200 m σ).

    kind : "white" (independent per fix), "gm" (first-order Gauss-Markov: correlated but rough,
        ~18 m steps between 4 Hz fixes at 200 m, 60 s), "drift" (smooth second-order
        Gauss-Markov from zero: a receiver or a spoofer sliding away, :func:`drift_errors`) or
        "drift-jump" (the same from its steady state: a jump, then the drift)
    """

    start: float
    duration: float
    sigma: float = 200.0
    kind: str = "white"
    tau: float = 60.0

    @property
    def end(self) -> float:
        return self.start + self.duration


def drift_errors(n, dt, sigma, tau, rng, *, start="zero"):
    """A smoothly drifting 2-D error: second-order Gauss–Markov, critically damped.

    ``ë = −2β ė − β² e + w`` with β = 1/τ and the white-noise density set for a steady-state σ
    (``q = 4β³σ²``, Gelb Table 3.1-1); its rate has σ·β (3.3 m/s for 200 m and 60 s).
    ``start="zero"`` begins at no error and no rate; ``"stationary"`` draws both from the
    steady state.
    """
    rng = np.random.default_rng(rng)
    b = 1.0 / tau
    q = 4.0 * b**3 * sigma**2
    e = np.zeros((n, 2))
    v = np.zeros(2)
    if start == "stationary":
        e[0] = rng.normal(size=2) * sigma
        v = rng.normal(size=2) * sigma * b
    w = rng.normal(size=(n, 2)) * np.sqrt(q * dt)
    for k in range(1, n):
        v = v + (-2.0 * b * v - b * b * e[k - 1]) * dt + w[k]
        e[k] = e[k - 1] + v * dt
    return e


def _ar1(a, w, zi):
    """``y_k = a·y_{k−1} + w_k`` along axis 0, ``zi`` the filter state before the first sample
    (``scipy.signal.lfilter``; imported here, not with the module: ``scipy.signal`` takes ~2 s
    to import and only the simulators draw noise with it)."""
    from scipy.signal import lfilter

    return lfilter([1.0], [1.0, -a], w, axis=0, zi=zi)[0]


def outlier_errors(kind, n, dt, sigma, tau, rng):
    """``n`` horizontal outlier errors (E, N metres) at interval ``dt`` of an
    :class:`OutlierWindow` kind: white, gm (first-order Gauss–Markov from its steady state),
    drift / drift-jump (:func:`drift_errors` from zero / its steady state), drag
    (:func:`drag_errors`)."""
    if kind == "gm":
        a = np.exp(-dt / tau)
        z = rng.normal(size=(n, 2)) * sigma * np.sqrt(1 - a * a)
        return _ar1(a, z, (a * sigma * rng.normal(size=2))[None])
    if kind == "white":
        return rng.normal(size=(n, 2)) * sigma
    if kind in ("drift", "drift-jump"):
        return drift_errors(n, dt, sigma, tau, rng, start="zero" if kind == "drift" else "stationary")
    if kind == "drag":
        return drag_errors(n, dt, rng)
    raise SelfnavError(f"unknown outlier kind '{kind}' (white, gm, drift, drift-jump or drag)")


#: the range of a spoofer's drag rate, m/s (:func:`drag_errors`)
DRAG_RATES = (0.5, 3.0)


def drag_errors(n, dt, rng, rate=None):
    """A spoofer's drag: a linear ramp from zero in one direction at ``rate`` m/s (drawn
    uniformly in :data:`DRAG_RATES` when None; the direction uniformly), ``n`` errors at
    interval ``dt``. It is switched off at the window's end (the caller stops adding it)."""
    rate = float(rng.uniform(*DRAG_RATES)) if rate is None else float(rate)
    a = float(rng.uniform(0.0, 2.0 * np.pi))
    s = rate * dt * np.arange(1, n + 1)
    return np.column_stack([s * np.sin(a), s * np.cos(a)])


def random_outlier_windows(t0, t1, count, rng, *, max_duration=300.0, sigma=200.0,
                           kinds=("white", "gm"), startup=False, min_duration=None):
    """``count`` non-overlapping outlier windows placed uniformly in ``[t0, t1]``.

    Durations are uniform in ``[min_duration, max_duration]`` (``min_duration`` None: 20 % of
    ``max_duration``; both at most half the span); the kind is drawn from ``kinds``.

    ``startup=True`` puts the first window at ``t0`` (the receiver is wrong from power-on).
    """
    rng = np.random.default_rng(rng)
    max_duration = min(float(max_duration), 0.5 * (t1 - t0))
    lo = 0.2 * max_duration if min_duration is None else min(float(min_duration), max_duration)
    out = []
    for k in range(count):
        for _ in range(1000):
            d = float(rng.uniform(lo, max_duration)) if min_duration is not None \
                else float(rng.uniform(0.2, 1.0) * max_duration)
            s = t0 if (startup and k == 0) else float(rng.uniform(t0, max(t0, t1 - d)))
            if all(s >= w.end or s + d <= w.start for w in out):
                break
        else:
            break
        out.append(OutlierWindow(s, d, sigma, str(kinds[int(rng.integers(len(kinds)))])))
    return sorted(out, key=lambda w: w.start)


@dataclass
class OdometerModel:
    """Wheel speed (odometer) of a car: forward speed at the rear axle, with a scale-factor
    error (tyre radius, pressure, wear), white noise and quantisation.

    ``speed = q·round((1 + k)·v / q + n)``, ``k ~ N(0, scale_factor_sigma²)`` drawn once per
    drive, ``n`` white with σ ``noise_mps / q``; never negative (a wheel-speed sensor without a
    direction signal). ``rate_hz`` samples per second, each the speed at its time stamp.
    """

    scale_factor_sigma: float = 0.005
    quantum_mps: float = 0.01
    noise_mps: float = 0.0
    rate_hz: float = 10.0

    def simulate(self, t, speed, rng):
        """Samples ``(t_out, speed_out, k)`` of a true forward speed ``speed`` (m/s) at ``t``."""
        rng = np.random.default_rng(rng)
        if not 0.0 < self.rate_hz <= 1000.0:
            raise SelfnavError(f"odometer rate {self.rate_hz} Hz outside (0, 1000]")
        dt = 1.0 / self.rate_hz
        t_out = np.arange(np.ceil(t[0] / dt) * dt, t[-1] + 1e-9, dt)
        k = float(rng.normal() * self.scale_factor_sigma)
        v = (1.0 + k) * np.interp(t_out, t, speed) + rng.normal(size=len(t_out)) * self.noise_mps
        if self.quantum_mps > 0:
            v = np.round(v / self.quantum_mps) * self.quantum_mps
        return t_out, np.maximum(v, 0.0), k


@dataclass
class GnssFixes:
    """Simulated GNSS output and the truth about its errors.

    t, lat, lon (rad), h (m), sigma_m (the σ the receiver *reports*: the nominal one, also
    inside outlier windows, which are unflagged), velocity_n (N, 3) m/s, error_enu (N, 3) m,
    outlier (N,) bool, spike (N,) bool, windows (list of OutlierWindow), datum.
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    sigma_m: np.ndarray
    velocity_n: np.ndarray
    error_enu: np.ndarray
    outlier: np.ndarray
    spike: np.ndarray
    windows: list
    datum: str = "wgs84"

    def as_gnss(self, *, velocity: bool = False, source: str = "simulated") -> GnssData:
        """The fixes as a receiver file gives them (:class:`~selfnav.types.GnssData`): positions,
        the reported σ and, with ``velocity``, the velocity; none of the error truth."""
        return GnssData.from_arrays(self.t, self.lat, self.lon, self.h, self.sigma_m,
                                    self.velocity_n if velocity else None, source=source)


@dataclass
class GnssModel:
    """GNSS position/velocity receiver (seed 004 §1: PZ-90 fixes, σ 10 m, unflagged outliers).

    Attributes
    ----------
    rate_hz : output rate, 1-10 Hz
    sigma_h, sigma_v : horizontal (per axis) and vertical position σ, m (white)
    sigma_vel : velocity σ per axis, m/s
    outages : list of ``(t_start, t_end)``: no fixes
    outliers : list of :class:`OutlierWindow`
    spike_rate : probability of a multipath spike per fix; spike_sigma its horizontal σ, m
    datum : "wgs84", "pz90" or "sk42" (converted with :mod:`selfnav.datum`)
    sigma_corr_h, tau_corr : a slowly drifting horizontal error (the stand-alone receiver's
        atmosphere and orbit errors): :func:`drift_errors` of steady-state σ ``sigma_corr_h``
        (m, per axis) and time constant ``tau_corr`` (s), from its steady state; 0: none. The
        σ the receiver reports is then ``hypot(sigma_h, sigma_corr_h)``.
    """

    rate_hz: float = 1.0
    sigma_h: float = 10.0
    sigma_v: float = 15.0
    sigma_vel: float = 0.1
    outages: list = field(default_factory=list)
    outliers: list = field(default_factory=list)
    spike_rate: float = 0.0
    spike_sigma: float = 50.0
    datum: str = "wgs84"
    sigma_corr_h: float = 0.0
    tau_corr: float = 60.0

    def simulate(self, traj, rng) -> GnssFixes:
        """Fixes along a :class:`~selfnav.types.Trajectory` (interpolated)."""
        rng = np.random.default_rng(rng)
        if not 0.0 < self.rate_hz <= 100.0:
            raise SelfnavError(f"GNSS rate {self.rate_hz} Hz outside (0, 100]")
        dt = 1.0 / self.rate_hz
        t = np.arange(np.ceil(traj.t[0] / dt) * dt, traj.t[-1] + 1e-9, dt)
        keep = np.ones(len(t), bool)
        for a, b in self.outages:
            keep &= ~((t >= a) & (t < b))
        t = t[keep]
        n = len(t)
        lat = np.interp(t, traj.t, traj.lat)
        lon = np.interp(t, traj.t, np.unwrap(traj.lon))
        h = np.interp(t, traj.t, traj.h)
        vel = np.column_stack([np.interp(t, traj.t, traj.velocity_n[:, k]) for k in range(3)])
        err = rng.normal(size=(n, 3)) * np.array([self.sigma_h, self.sigma_h, self.sigma_v])
        outlier = np.zeros(n, bool)
        for w in self.outliers:
            m = (t >= w.start) & (t < w.end)
            outlier |= m
            k = int(m.sum())
            if not k:
                continue
            e = outlier_errors(w.kind, k, dt, w.sigma, w.tau, rng)
            err[m, :2] = e
        spike = rng.uniform(size=n) < self.spike_rate
        err[spike, :2] += rng.normal(size=(int(spike.sum()), 2)) * self.spike_sigma
        sig_rep = self.sigma_h
        if self.sigma_corr_h > 0 and n:
            # on the uniform grid (outages cut rows, not time), then at the fix times
            grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
            e = drift_errors(len(grid), dt, self.sigma_corr_h, self.tau_corr, rng,
                             start="stationary")
            idx = np.clip(np.round((t - t[0]) / dt).astype(int), 0, len(grid) - 1)
            err[:, :2] += e[idx]
            sig_rep = float(np.hypot(self.sigma_h, self.sigma_corr_h))
        R_phi, R_lam = radii(lat, h)
        lat_m = lat + err[:, 1] / R_phi
        lon_m = lon + err[:, 0] / (R_lam * np.cos(lat))
        h_m = h + err[:, 2]
        vel_m = vel + rng.normal(size=(n, 3)) * self.sigma_vel
        datum = self.datum.lower().replace("-", "").replace(".", "").replace("_", "")
        if datum not in ("wgs84",):
            try:
                from selfnav import datum as _datum
            except ImportError:
                raise SelfnavError("GNSS output in another datum needs selfnav.datum") from None
            lat_m, lon_m, h_m = _datum.convert(lat_m, lon_m, h_m, "wgs84", self.datum)
        return GnssFixes(t, lat_m, np.angle(np.exp(1j * lon_m)), h_m, np.full(n, sig_rep),
                         vel_m, err, outlier, spike, list(self.outliers), self.datum)


# ---------------------------------------------------------------- editing real GNSS

def with_outages(g: GnssData, every=120.0, length=30.0, first=90.0):
    """Remove ``length`` s of fixes every ``every`` s from ``first`` s on; returns
    ``(gnss, list of outage end times)``."""
    keep = np.ones(len(g.t), bool)
    ends = []
    for s in np.arange(g.t[0] + first, g.t[-1] - length, every):
        keep &= ~((g.t >= s) & (g.t < s + length))
        ends.append(float(s + length))
    return g.select(keep), ends


def with_outliers(g: GnssData, start, duration=180.0, sigma=200.0, kind="white", tau=60.0,
                  seed=0, *, velocity: str = "keep"):
    """Unflagged horizontal outliers in ``[start, start + duration)`` (:func:`outlier_errors`
    of ``kind``); the σ in the file is unchanged, so nothing flags them.

    ``velocity``: ``"keep"`` the file's velocity (a receiver whose Doppler is clean while its
    positions are not), ``"drop"`` every velocity (positions only), or ``"consistent"``: the
    velocity carries the outliers' own rate (a spoofer or a drift that fools both).
    """
    rng = np.random.default_rng(seed)
    out = g.copy()
    m = (g.t >= start) & (g.t < start + duration)
    k = int(m.sum())
    dt = float(np.median(np.diff(g.t)))
    e = outlier_errors(kind, k, dt, sigma, tau, rng)
    rm, rn = radii(g.lat[m])
    out.lat[m] = g.lat[m] + e[:, 1] / rm
    out.lon[m] = g.lon[m] + e[:, 0] / (rn * np.cos(g.lat[m]))
    if velocity == "drop":
        out.velocity_n = None
        out.sigma_vel_mps = None
    elif velocity == "consistent" and g.velocity_n is not None and k > 1:
        rate = np.gradient(e, g.t[m], axis=0)
        out.velocity_n[m, :2] = g.velocity_n[m, :2] + rate
    elif velocity not in ("keep", "consistent"):
        raise SelfnavError(f"velocity must be keep, drop or consistent, got '{velocity}'")
    return out
