"""Configuration of the INS/GNSS filter, grouped by what it describes (DESIGN §5, §7, §10).

:class:`FilterConfig` holds one group per concern, each a dataclass whose every threshold is a
named, documented field:

==================  ===========================================================================
``imu``             :class:`ImuNoise` — the IMU noise model (from a sensor grade, or measured)
``states``          :class:`StateOptions` — optional error states beyond the 15 of the core
``init``            :class:`Initialisation` — the initial σ and the in-motion alignment
``gnss``            :class:`GnssAiding` — lever arm, σ floor, GNSS velocity
``vehicle``         :class:`VehicleConstraints` — non-holonomic constraint and zero-velocity updates
``outliers``        :class:`OutlierDefence` — χ² gate, window test, suspect mode
``shadows``         :class:`ShadowGuard` — shadow dead reckoning against drifting GNSS
==================  ===========================================================================

The noise of a grade is *derived* from the one sensor vocabulary of :mod:`selfnav.sensors`
(``navigation, tactical, industrial, consumer``): the filter believes what the simulator
draws. :meth:`FilterConfig.for_grade` accepts field overrides by their (unique) names, e.g.
``FilterConfig.for_grade("industrial", nhc_sigma=0.1)``.
"""
from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from selfnav import sensors
from selfnav.errors import SelfnavError
from selfnav.units import DEG

CHI2_3_999 = 16.266
CHI2_2_999 = 13.816
CHI2_1_999 = 10.828
CHI2_2_9999 = 18.421


@functools.lru_cache(maxsize=128)
def chi2_999(dof: int) -> float:
    """0.999 quantile of χ²(dof) (cached)."""
    return float(chi2.ppf(0.999, dof))


@dataclass
class ImuNoise:
    """IMU noise model of the filter (SI units, 1σ per axis).

    Attributes
    ----------
    arw : gyro white noise (angle random walk), rad/√s
    vrw : accelerometer white noise (velocity random walk), (m/s)/√s
    gyro_bias_sigma, accel_bias_sigma : initial bias σ (turn-on bias), rad/s and m/s²
    gyro_bias_tau, accel_bias_tau : bias correlation time, s (inf: a random constant plus the
        random walk below)
    gyro_bias_instability, accel_bias_instability : steady σ of the in-run bias variation,
        rad/s and m/s²; enters as a random walk of density ``2 B² / instability_tau``
    instability_tau : correlation time of that variation, s
    gyro_sf_sigma, accel_sf_sigma : scale-factor σ (fraction), with ``states.scale_factors``
    grade : where the numbers came from (a grade name, "measured", ...)
    adapt : adapt the process-noise scale online from trusted fixes
        (:class:`selfnav.ins.calibrate.NoiseAdapter`)
    """

    arw: float = 0.15 * DEG / 60.0
    vrw: float = 2e-4
    gyro_bias_sigma: float = 0.05 * DEG
    accel_bias_sigma: float = 0.02
    gyro_bias_tau: float = np.inf
    accel_bias_tau: float = np.inf
    gyro_bias_instability: float = 2.0 * DEG / 3600.0
    accel_bias_instability: float = 1e-4
    instability_tau: float = 100.0
    gyro_sf_sigma: float = 0.01
    accel_sf_sigma: float = 0.01
    grade: str = "industrial"
    adapt: bool = True

    @classmethod
    def from_model(cls, model: "sensors.ImuErrorModel", grade: str = "") -> "ImuNoise":
        """The filter's noise for a simulator error model (:data:`selfnav.sensors.GRADES`).

        White noise and turn-on biases carry over; the bias instability ``B`` becomes the
        steady σ of the filter's bias variation, with the model's correlation time; the
        rate random walk (if any) is folded into it over that time.
        """
        g, a = model.gyro, model.accel

        def v(x):
            return float(np.max(np.asarray(x, dtype=float)))

        tau = float(g.bias_tau)
        bi_g = np.hypot(v(g.bias_instability), v(g.random_walk) * np.sqrt(tau))
        bi_a = np.hypot(v(a.bias_instability), v(a.random_walk) * np.sqrt(tau))
        return cls(arw=v(g.white), vrw=v(a.white), gyro_bias_sigma=max(v(g.bias), bi_g),
                   accel_bias_sigma=max(v(a.bias), bi_a), gyro_bias_instability=bi_g,
                   accel_bias_instability=bi_a, instability_tau=tau,
                   gyro_sf_sigma=max(v(g.scale_factor), 1e-6),
                   accel_sf_sigma=max(v(a.scale_factor), 1e-6), grade=grade or model.name)

    def scaled(self, k: float) -> "ImuNoise":
        """Every noise and bias σ multiplied by ``k`` (the correlation times kept)."""
        return dataclasses.replace(
            self, arw=self.arw * k, vrw=self.vrw * k, gyro_bias_sigma=self.gyro_bias_sigma * k,
            accel_bias_sigma=self.accel_bias_sigma * k,
            gyro_bias_instability=self.gyro_bias_instability * k,
            accel_bias_instability=self.accel_bias_instability * k,
            grade=f"{self.grade} x{k:g}")


@dataclass
class StateOptions:
    """Optional error states beyond the core 15 (position, velocity, attitude, biases).

    Attributes
    ----------
    scale_factors : gyro and accelerometer scale factors (+6)
    mount_states : the IMU's pitch and yaw relative to the vehicle, seen by the NHC (+2)
    mount_rad : known (initial) mounting pitch and yaw, rad
    mount_sigma : their initial σ, rad
    mount_rw : their random walk, rad/√s (a mount that settles)
    lever_arm : the IMU → antenna lever arm (+3), from ``gnss.lever_arm_b``
    lever_arm_sigma : its initial σ per axis, m
    lever_arm_rw : its random walk, m/√s
    time_offset : the residual IMU time offset (+1), s, left by the data pre-pass
    time_offset_sigma : its initial σ, s
    time_offset_rw : its random walk, s/√s (clock drift)
    odometer : the odometer's scale-factor error (+1), with an odometer input
    odometer_scale_sigma : its initial σ (fraction: tyre radius, pressure, wear)
    odometer_scale_rw : its random walk, 1/√s
    """

    scale_factors: bool = False
    mount_states: bool = False
    mount_rad: tuple = (0.0, 0.0)
    mount_sigma: float = 2.0 * DEG
    mount_rw: float = 0.0
    lever_arm: bool = False
    lever_arm_sigma: float = 0.5
    lever_arm_rw: float = 0.0
    time_offset: bool = False
    time_offset_sigma: float = 0.05
    time_offset_rw: float = 1e-5
    odometer: bool = False
    odometer_scale_sigma: float = 0.02
    odometer_scale_rw: float = 1e-5


@dataclass
class Initialisation:
    """Initial uncertainty and the in-motion alignment from GNSS (:mod:`selfnav.ins.align`).

    Attributes
    ----------
    pos_sigma, vel_sigma : m, m/s (when no alignment sets them)
    att_sigma : roll, pitch, heading σ, rad
    min_speed : the GNSS course gives the heading above this speed, m/s
    max_accel : bounded-acceleration motion model of the start-up consistency test, m/s²
    given_pos_sigma, given_vel_sigma, given_att_sigma : σ of a state given by another
        navigator or a survey (``--init``): m, m/s, (roll, pitch, heading) rad
    """

    pos_sigma: float = 10.0
    vel_sigma: float = 0.5
    att_sigma: tuple = (2.0 * DEG, 2.0 * DEG, 10.0 * DEG)
    min_speed: float = 5.0
    max_accel: float = 5.0
    given_pos_sigma: float = 1.0
    given_vel_sigma: float = 0.1
    given_att_sigma: tuple = (1.0 * DEG, 1.0 * DEG, 3.0 * DEG)


@dataclass
class GnssAiding:
    """How GNSS fixes aid the INS.

    Attributes
    ----------
    lever_arm_b : IMU → antenna, body RFU, m
    sigma_h, sigma_v : override the file's σ (horizontal per axis, vertical), m; None: use it
    sigma_floor : the smallest σ believed (unmodelled timing, lever arm), m
    default_sigma : σ of a fix whose file gives none, m
    vertical_ratio : vertical σ over horizontal σ when the file gives only one
    use_velocity : use the file's GNSS velocity (ENU) where present
    velocity_sigma : its σ per axis, m/s
    """

    lever_arm_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sigma_h: float | None = None
    sigma_v: float | None = None
    sigma_floor: float = 0.1
    default_sigma: float = 5.0
    vertical_ratio: float = 1.5
    use_velocity: bool = True
    velocity_sigma: float = 0.1
    velocity_floor: float = 0.05


@dataclass
class VehicleConstraints:
    """Non-holonomic constraint (NHC) and zero-velocity updates (ZUPT) of a wheeled vehicle.

    Attributes
    ----------
    nhc : a car does not slide sideways or jump
    nhc_sigma : m/s, lateral (and vertical) velocity at the NHC point
    nhc_sigma_up : m/s, vertical if it differs from lateral
    nhc_lever_b : IMU → the point that does not slip (rear-axle centre), body RFU, m
    zupt : zero-velocity updates while the IMU is still
    zupt_sigma : m/s
    zupt_speed : the INS speed must be below this, m/s …
    zupt_speed_sigmas : … or below this many velocity σ (0: off)
    zupt_accel_h : horizontal specific force below this, m/s²
    zupt_gyro : |ω| below this over the block, rad/s
    zupt_accel : std of |f| over the block below this, m/s²
    aid_step : interval of NHC / ZUPT / road updates, s
    odometer_sigma : m/s, white error of one wheel-speed sample (quantisation, slip)
    odometer_step : s, the shortest interval between odometer updates (faster samples are
        thinned: the speed is smooth, each update costs an epoch)
    """

    nhc: bool = True
    nhc_sigma: float = 0.3
    nhc_sigma_up: float | None = None
    nhc_lever_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    zupt: bool = True
    zupt_sigma: float = 0.02
    zupt_speed: float = 1.0
    zupt_speed_sigmas: float = 0.0
    zupt_accel_h: float = 0.1
    zupt_gyro: float = 1.0 * DEG
    zupt_accel: float = 0.15
    aid_step: float = 0.2
    odometer_sigma: float = 0.05
    odometer_step: float = 0.2


@dataclass
class OutlierDefence:
    """The defence against GNSS outliers nothing flags (DESIGN §7; :mod:`selfnav.ins.guard`).

    Attributes
    ----------
    robust : the window test, suspect mode and re-acquisition (False: only the χ² gate)
    gate : χ² gate on each fix (3 dof, 0.999)
    soft_gate : with ``robust``, fixes up to ``soft_gate × gate`` are used with R inflated …
    soft_gate_max_m : … when the horizontal innovation is below this, m …
    soft_gate_sigmas : … or below this many of the fix's σ
    window : fixes in the consistency window
    window_vel_floor : velocity σ added to the filter's when the window test allows for INS
        drift between fixes, m/s
    suspect_after : consecutive rejections before suspect mode
    degraded_window : s of suspect fixes judged for white noise (degraded mode)
    degraded_min : at least this many fixes
    degraded_min_ratio : a white-noise scale is used only above this many fix σ
    white_rho_max : lag-1 autocorrelation above which suspect fixes are not white
    white_ratio_min : the fix-to-fix scale must be at least this share of the scale about the
        median (equal for white noise, far smaller for a drift)
    reinit_after : s of fixes that fit one smooth track by themselves but not the INS
        displacement (the INS, not the fixes, is lost) before the INS is re-initialised
        from them
    reinit_span : s of fixes the re-initialisation fits
    """

    robust: bool = True
    gate: float = CHI2_3_999
    soft_gate: float = 10.0
    soft_gate_max_m: float = 3.0
    soft_gate_sigmas: float = 3.0
    window: int = 6
    window_vel_floor: float = 0.2
    suspect_after: int = 2
    degraded_window: float = 20.0
    degraded_min: int = 15
    degraded_min_ratio: float = 3.0
    white_rho_max: float = 0.3
    white_ratio_min: float = 0.8
    reinit_after: float = 20.0
    reinit_span: float = 10.0


@dataclass
class ShadowGuard:
    """Shadow dead reckoning against smoothly drifting GNSS (:class:`selfnav.ins.guard.DeadReckoningGuard`).

    Attributes
    ----------
    use_shadows : keep shadows (with ``outliers.robust``)
    branch_every : s between shadows
    max_age : s a shadow lives while GNSS is trusted
    min_age : s before a shadow tests fixes
    step : s between shadow updates
    branch_att_sigma : branch only when every attitude σ is below this, rad
    sigma_scale : shadow σ inflation (EKF dead reckoning is optimistic)
    shadow_gate : χ² (2 dof, 0.9999) of a fix against a shadow
    fit_sigma : m/s: re-acquire after a run this sure of its speed
    max_suspect : s after which any consistent run re-acquires
    reacq_run : s of fixes moving like the dead reckoning that re-acquire outside its σ
    """

    use_shadows: bool = True
    branch_every: float = 30.0
    max_age: float = 90.0
    min_age: float = 5.0
    step: float = 1.0
    branch_att_sigma: float = 0.5 * DEG
    sigma_scale: float = 2.0
    shadow_gate: float = CHI2_2_9999
    fit_sigma: float = 0.5
    max_suspect: float = 330.0
    reacq_run: float = 20.0


GROUPS = {"imu": ImuNoise, "states": StateOptions, "init": Initialisation, "gnss": GnssAiding,
          "vehicle": VehicleConstraints, "outliers": OutlierDefence, "shadows": ShadowGuard}


def _field_index():
    idx = {}
    for g, cls in GROUPS.items():
        for f in dataclasses.fields(cls):
            if f.name in idx:  # pragma: no cover - a programming error caught at import
                raise RuntimeError(f"field name {f.name} is in two config groups")
            idx[f.name] = g
    return idx


_FIELD_GROUP = _field_index()

#: Filter settings that go with a grade beyond its noise (the vehicle model of a consumer
#: part whose 1 °/s gyro biases leave the heading loose: at NHC σ 0.3 m/s it held a wrong
#: heading on a simulated stop-and-go drive; its 1 % scale factors are estimated).
GRADE_FILTER_SETTINGS = {
    "navigation": {},
    "tactical": {},
    "industrial": {},
    "consumer": {"scale_factors": True, "nhc_sigma": 0.5},
}


@dataclass
class FilterConfig:
    """Everything :class:`selfnav.ins.ekf.InsGnssFilter` and its navigator need (SI units).

    See the module docstring for the groups; :meth:`for_grade` builds one from a sensor grade.
    """

    imu: ImuNoise = field(default_factory=ImuNoise)
    states: StateOptions = field(default_factory=StateOptions)
    init: Initialisation = field(default_factory=Initialisation)
    gnss: GnssAiding = field(default_factory=GnssAiding)
    vehicle: VehicleConstraints = field(default_factory=VehicleConstraints)
    outliers: OutlierDefence = field(default_factory=OutlierDefence)
    shadows: ShadowGuard = field(default_factory=ShadowGuard)
    cov_step: float = 0.2          # covariance propagation sub-step, s
    vertical: str = "free"         # vertical channel of the mechanization

    def updated(self, **fields) -> "FilterConfig":
        """A copy with fields replaced by their names (each name is in one group only)."""
        out = dataclasses.replace(self, **{g: dataclasses.replace(getattr(self, g))
                                           for g in GROUPS})
        for name, value in fields.items():
            if name in GROUPS:
                setattr(out, name, value)
            elif name in ("cov_step", "vertical"):
                setattr(out, name, value)
            elif name in _FIELD_GROUP:
                setattr(getattr(out, _FIELD_GROUP[name]), name, value)
            else:
                raise SelfnavError(f"FilterConfig has no setting '{name}'")
        return out

    @classmethod
    def for_grade(cls, grade: str, **fields) -> "FilterConfig":
        """The filter for a sensor grade of :data:`selfnav.sensors.GRADES`, fields overridden.

        The noise is derived from the grade's error model (:meth:`ImuNoise.from_model`); the
        settings of :data:`GRADE_FILTER_SETTINGS` go with it.
        """
        key = sensors.grade_key(grade)
        if key not in sensors.GRADES:
            raise SelfnavError(f"unknown grade '{grade}' (use {', '.join(sensors.GRADE_NAMES)})")
        base = cls(imu=ImuNoise.from_model(sensors.GRADES[key], key))
        return base.updated(**{**GRADE_FILTER_SETTINGS[key], **fields})
