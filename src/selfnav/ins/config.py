"""Configuration of the INS/GNSS filter, grouped by what it describes (DESIGN §5, §7, §10).

:class:`FilterConfig` holds one group per concern, each a dataclass whose every threshold is a
named, documented field:

==================  ===========================================================================
``imu``             :class:`ImuNoise` — the IMU noise model (from a sensor grade, or measured)
``states``          :class:`StateOptions` — optional error states beyond the 15 of the core
``init``            :class:`Initialisation` — the initial σ and the in-motion alignment
``gnss``            :class:`GnssAiding` — lever arm, σ floor, GNSS velocity
``vehicle``         :class:`VehicleConstraints` — non-holonomic constraint and zero-velocity updates
``integrity``       :class:`Integrity` — the fault-hypothesis bank: gates, references, runs
``adaptation``      :class:`NoiseAdaptation` — the online noise scale and vibration factor
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

from selfnav import sensors
from selfnav.errors import SelfnavError
from selfnav.quantiles import chi2_ppf
from selfnav.units import DEG

CHI2_2_999 = 13.816


@functools.lru_cache(maxsize=128)
def chi2_999(dof: int) -> float:
    """0.999 quantile of χ²(dof) (cached)."""
    return float(chi2_ppf(0.999, dof))


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
    gyro_mis_sigma, accel_mis_sigma : axis misalignment / non-orthogonality σ of each
        off-diagonal element (rad), with ``states.misalignment``
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
    gyro_mis_sigma: float = 1e-3
    accel_mis_sigma: float = 1e-3
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
                   accel_sf_sigma=max(v(a.scale_factor), 1e-6),
                   gyro_mis_sigma=max(v(g.misalignment), 1e-7),
                   accel_mis_sigma=max(v(a.misalignment), 1e-7), grade=grade or model.name)

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
    misalignment : gyro and accelerometer axis misalignment, the off-diagonal elements (+12)
    mount_states : the IMU's pitch and yaw relative to the vehicle, seen by the NHC (+2)
    mount_rad : known (initial) mounting pitch and yaw, rad
    mount_sigma : their initial σ, rad
    mount_rw : their random walk, rad/√s (a mount that settles)
    lever_arm : the IMU → antenna lever arm (+3), from ``gnss.lever_arm_b``
    lever_arm_sigma : its initial σ per axis, m
    lever_arm_rw : its random walk, m/√s
    time_offset : the IMU time offset (+1), s: what to add to the IMU stamps for GNSS time
    time_offset_sigma : its initial σ, s
    time_offset_rw : its random walk, s/√s
    clock_drift : the rate of the time offset (+1, with ``time_offset``), s/s: an IMU stamped
        by its own counter drifts against GNSS time (drive_0708: −240 ppm, 0.09 s over its
        9 minutes)
    clock_drift_sigma : its initial σ, s/s (fact: a cheap counter's oscillator)
    clock_drift_rw : its random walk, s/s/√s
    time_offset_check_s : s between re-estimates of the time offset from the past
        (:meth:`selfnav.ins.Navigator._check_time_offset`)
    time_offset_window_s : s of the past each re-estimate uses
    time_offset_settled_s : no re-estimate once the state's σ is below this, s
    time_offset_coarse_s : the re-estimate moves the state only beyond this, s (its accuracy)
    installation_bound : policy: the time offset, clock drift, lever arm, velocity lag and
        odometer scale are held within this many of their prior σ of their prior value — beyond
        it a state is not the installation's but a fault the fixes carry (a drift along the
        road became a clock drift of 58 % and a lever arm of 558 m, simulated drive
        6129180605438802640); None: unbounded
    velocity_lag : estimate the lag of the GNSS velocity behind its positions (+1), s, where
        the fixes carry a velocity
    velocity_lag_sigma : its initial σ, s (a post-processor's interval velocity: half a
        fix interval)
    velocity_lag_rw : its random walk, s/√s
    odometer : the odometer's scale-factor error (+1), with an odometer input
    odometer_scale_sigma : its initial σ (fraction: tyre radius, pressure, wear)
    odometer_scale_rw : its random walk, 1/√s
    receiver_clock : the GNSS receiver's clock bias and drift (+2, m and m/s), for
        pseudorange and Doppler updates (tight coupling, :mod:`selfnav.ins.tight`)
    receiver_clock_sigma, receiver_drift_sigma : their initial σ, m and m/s (after a
        least-squares start)
    receiver_clock_rw, receiver_drift_rw : their random walks, m/√s and m/s/√s (fact: a
        receiver's TCXO, Groves 2013 §9.4.2: phase and frequency noise densities of
        0.01 m²/s and 0.04 m²/s³)
    inter_system : the receiver's clock offsets of up to four further constellations against
        the reference one (+4, m; with ``receiver_clock``)
    inter_system_sigma : their initial σ, m (after a least-squares start)
    inter_system_rw : their random walk, m/√s (fact: hardware delays drift with temperature)
    """

    scale_factors: bool = False
    misalignment: bool = False
    mount_states: bool = False
    mount_rad: tuple = (0.0, 0.0)
    mount_sigma: float = 2.0 * DEG
    mount_rw: float = 0.0
    lever_arm: bool = False
    lever_arm_sigma: float = 0.5
    lever_arm_rw: float = 0.0
    time_offset: bool = False
    time_offset_sigma: float = 0.3
    time_offset_rw: float = 1e-5
    clock_drift: bool = True
    clock_drift_sigma: float = 5e-4
    clock_drift_rw: float = 1e-7
    time_offset_check_s: float = 30.0
    time_offset_window_s: float = 300.0
    time_offset_settled_s: float = 0.002
    time_offset_coarse_s: float = 0.1
    installation_bound: float | None = 5.0
    velocity_lag: bool = True
    velocity_lag_sigma: float = 0.2
    velocity_lag_rw: float = 1e-5
    odometer: bool = False
    odometer_scale_sigma: float = 0.02
    odometer_scale_rw: float = 1e-5
    receiver_clock: bool = False
    receiver_clock_sigma: float = 30.0
    receiver_drift_sigma: float = 1.0
    receiver_clock_rw: float = 0.1
    receiver_drift_rw: float = 0.2
    inter_system: bool = False
    inter_system_sigma: float = 30.0
    inter_system_rw: float = 0.01


@dataclass
class Initialisation:
    """Initial uncertainty and the in-motion alignment from GNSS (:mod:`selfnav.ins.align`).

    Attributes
    ----------
    pos_sigma, vel_sigma : m, m/s (when no alignment sets them)
    att_sigma : roll, pitch, heading σ, rad
    min_speed : the GNSS course gives the heading above this speed, m/s
    max_accel : bounded-acceleration motion model of the start-up consistency test, m/s²
    window : fewest fixes in the in-motion alignment's window
    reinit_speed : a restart from the fixes (the INS lost) needs this speed for the course,
        m/s
    healthy_window : fixes in the run that must look healthy before the start
    given_pos_sigma, given_vel_sigma, given_att_sigma : σ of a state given by another
        navigator or a survey (``--init``): m, m/s, (roll, pitch, heading) rad
    heading_split_sigma : the filter's linear range for the heading (σ, rad): a start less
        sure of its heading is split into hypotheses this wide, a Gaussian sum the fixes
        resolve (:mod:`selfnav.ins.headings`; None: never split) — a policy of the estimator
    heading_split_max : the most hypotheses (a start with no heading: the whole circle)
    yaw_bias_split_sigma : the filter's linear range for the z gyro's bias (σ, rad/s): a start
        less sure of it (a consumer gyro's 1 °/s, moving, no stop to measure it) is split,
        within each heading hypothesis, into hypotheses this wide — a policy of the estimator.
        0.5 °/s (stop 52; off before): a 0.7 °/s error at σ 0.35 °/s left a simulated consumer
        start 26° off after a minute, 0.35 °/s converged; a 2.16 °/s yaw bias took every
        heading hypothesis 25–31° off at σ 8° within 15 s (short consumer drive 32). At
        0.35 °/s (stop 46) a tuning drive ran 244 m off where a Gauss–Markov window began
        while the sum was unresolved; at 0.5 °/s the seven offsets are 1 °/s apart (±3 °/s,
        against ±2.1 °/s), each 0.5 °/s wide (docs/ekf.md has the campaigns); None: no split
    yaw_bias_split_max : the most yaw-bias hypotheses per heading hypothesis
    heading_prune_ratio : a hypothesis this many times less likely than the best is dropped
    heading_resolved_weight : the sum collapses to its best hypothesis once it holds this
        share of the weight
    heading_resolve_max_s : … or after this many seconds (the covariance then covers the
        others)
    any_start : how a start that needs no speed and no straight line
        (:mod:`selfnav.ins.anystart`) is used — ``"now"``: at once (a walker, a robot, a boat,
        a drone start at rest or slow); ``"fallback"``: only when the car's start has found no
        straight run after ``any_start_motion_s`` of motion (a car in slow traffic); a policy
    any_start_motion_s : s of motion the fixes show before the fallback start (a car leaving
        a parking place creeps for up to half a minute before its straight run: drive_0708
        creeps 18 s at ~1 m/s)
    any_start_speed : the fallback start only while the fixes' speed is below this, m/s (a
        walker, a robot, a boat, a hovering drone; a car slower than its own start needs may
        still be a car accelerating: it waits)
    any_window_s : s of fixes the start's position and velocity are fitted over
    course_window_s : … or up to this many s of fixes on a straight line, for the course
    course_heading : the platform moves along its body's forward axis (a fact of the
        platform: a multirotor does not), so the course gives its heading
    course_heading_sigma : σ of a vehicle's heading about the course it is taken from (a
        fact of the vehicle: its slip angle and the IMU's yaw on it), rad — beyond this the
        heading's error is the course's, one error with the velocity's cross-track part
        (:func:`selfnav.ins.course.course_heading_covariance`)
    """

    pos_sigma: float = 10.0
    vel_sigma: float = 0.5
    att_sigma: tuple = (2.0 * DEG, 2.0 * DEG, 10.0 * DEG)
    min_speed: float = 5.0
    max_accel: float = 5.0
    window: int = 6
    healthy_window: int = 20
    reinit_speed: float = 2.0
    given_pos_sigma: float = 1.0
    given_vel_sigma: float = 0.1
    given_att_sigma: tuple = (1.0 * DEG, 1.0 * DEG, 3.0 * DEG)
    any_start: str = "fallback"
    any_start_motion_s: float = 30.0
    any_start_speed: float = 2.5
    any_window_s: float = 4.0
    course_window_s: float = 20.0
    course_heading: bool = True
    course_heading_sigma: float = 4.0 * DEG
    heading_split_sigma: float | None = 3.0 * DEG
    heading_split_max: int = 31
    yaw_bias_split_sigma: float | None = 0.5 * DEG
    yaw_bias_split_max: int = 7
    heading_prune_ratio: float = 1e4
    heading_resolved_weight: float = 0.99
    heading_resolve_max_s: float = 120.0


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
    platform : the platform profile these constraints came from (:data:`PLATFORMS`; ``auto``:
        a car's, with :data:`SLOW_PLATFORM`'s constraints when the start shows no car)
    user_set : the settings the caller gave by name, which the slow-platform fallback keeps
    nhc : a car does not slide sideways or jump
    nhc_sigma : m/s, lateral (and vertical) velocity at the NHC point
    nhc_sigma_up : m/s, vertical if it differs from lateral
    nhc_lever_b : IMU → the point that does not slip (rear-axle centre), body RFU, m
    zupt : zero-velocity updates while the IMU is still
    zupt_sigma : m/s
    zupt_speed : the INS speed must be below this, m/s …
    zupt_speed_sigmas : … or, in a still run entered from braking, below this many velocity σ
        (0: off; a car's: 2) …
    zupt_speed_cap : … and below this, m/s (a constant cruise is still to an IMU: a 5.7 m/s
        cruise whose INS speed sat within 2σ of zero right after a start was clamped to rest)
    zupt_brake_accel : the mean forward acceleration over the 2 s before a still run that
        makes it a braking to rest, m/s² (below minus this) …
    zupt_brake_last_s : … and over the last this many seconds before it, for the widened
        speed bound of the zero-velocity update (a braking to rest lasts until the car stands)
    zupt_sigma_max : otherwise the zero-velocity update needs the INS's horizontal speed σ
        within this, m/s (None: any; a car's: 1 — an INS that does not know its speed to
        within ``zupt_speed`` does not know it is slow)
    grade_sigma : a level-road prior once a second, ``v_U = 0`` within ``grade_sigma·|v| +
        0.1`` m/s (a car's: 0.08, ordinary grades; None: off; the road aid gives its own
        with ``--map``): the pitch error a consumer gyro bias drives after a start in motion
        is hardly seen by the NHC (the INS's velocity pitches with it) or σ 15 m heights,
        and leaked gravity into the speed — 12° and 7 m/s in 6 s on docs/realtime.md's drive
    grade_corr_s : s over which a road's grade holds: each second's prior carries
        ``1/grade_corr_s`` of its information (at 1 s, drive_0708's real 2–4 % grades pulled
        the pitch through its outages: an outage end 1.3 → 8.2 m)
    zupt_accel_h : horizontal specific force below this, m/s²
    zupt_gyro : |ω| below this over the block, rad/s
    zupt_accel : std of |f| over the block below this, m/s²
    zaru : a zero angular-rate update on the gyro biases (the IMU turns with the Earth only)
        where the INS is slow (the ZUPT's speed gate) and the rates and specific force are
        still within what the filter knows of its biases and tilt: a consumer gyro's 0.5 °/s
        yaw bias, learnt wrong through a young start's turns, is measured at the first stop
        (a policy)
    zaru_steady_s : a zero rate judged still only through the bias-widened test needs the
        INS slow, the IMU so still and its rates one bias (within ``zupt_gyro``) for this long
        first, s (0: at once, a car's stop; the slow platform: 2 s — a boat in waves whose INS
        a fix had slowed for a second took a slow turn for a bias)
    zaru_sigma : rad/s, the least σ of one block's mean rate (the block's own scatter when
        larger: vibration, quantisation)
    aid_step : interval of NHC / ZUPT / road updates, s
    odometer_sigma : m/s, white error of one wheel-speed sample (quantisation, slip)
    odometer_step : s, the shortest interval between odometer updates (faster samples are
        thinned: the speed is smooth, each update costs an epoch)
    use_magnetometer : a heading update from the magnetometer where the IMU has one (off by
        default: a car's deviation — hard and soft iron — changes with the heading, so through
        the turns of a simulated drive the updates wrote it into the gyro bias and left the
        covariance 20× too confident in it; a dead reckoning from that state turned 1.2°/s)
    max_imu_gap_samples : an IMU step longer than this many sample intervals is a gap the
        INS does not bridge: the navigator starts again after it
    mag_step : s between magnetometer heading updates
    mag_heading_sigma : σ of a magnetometer heading without ``mag_calibrate`` (a car's body
        field, soft iron), rad
    mag_corr_s : s over which a calibrated heading's residual deviation is correlated: each
        reading's σ is inflated by ``√((1+ρ)/(1−ρ))``, ``ρ = exp(−mag_step / mag_corr_s)``
    speed_hold : through a GNSS outage, the pace the platform kept while the fixes were used
        (median of the INS's forward speed over ``speed_hold_window_s`` before the outage),
        a prior on the forward speed once a second while the IMU is not still — a walker or
        a rover keeps its pace; its σ is the spread of that speed (at least
        ``speed_hold_floor``, m/s), each second's prior inflated by ``(1+ρ)/(1−ρ)``,
        ``ρ = exp(−1 s / speed_hold_corr_s)``, for the pace's correlation in time
    speed_hold_window_s, speed_hold_corr_s, speed_hold_floor : see ``speed_hold``
    speed_hold_max_s : s after the last fix the pace is held for (a car that fell back to the
        slow platform's start in a city keeps no pace through a 4-minute outage)
    speed_hold_turn : rad/s, the pace is not held while the platform turns faster than this
        and faster than 95 % of the turn rates of the stretch it was learnt on
    mag_calibrate : the magnetometer's offset (hard iron, the soft iron's share of the
        vertical field) fitted from the turns (:class:`selfnav.ins.magcal.HardIronFit`), the
        heading's σ from that fit, and no update until the fit is trusted
    """

    platform: str = "auto"
    user_set: tuple = ()
    nhc: bool = True
    nhc_sigma: float = 0.3
    nhc_sigma_up: float | None = None
    nhc_lever_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    zupt: bool = True
    zupt_sigma: float = 0.02
    zupt_speed: float = 1.0
    zupt_speed_sigmas: float = 0.0
    zupt_speed_cap: float = 3.0
    zupt_brake_accel: float = 0.3
    zupt_brake_last_s: float = 0.4
    zupt_sigma_max: float | None = None
    grade_sigma: float | None = None
    grade_corr_s: float = 10.0
    zupt_accel_h: float = 0.1
    zupt_gyro: float = 1.0 * DEG
    zupt_accel: float = 0.15
    zaru: bool = True
    zaru_sigma: float = 0.01 * DEG
    zaru_steady_s: float = 0.0
    aid_step: float = 0.2
    odometer_sigma: float = 0.05
    odometer_step: float = 0.2
    use_magnetometer: bool = False
    max_imu_gap_samples: float = 6.0
    mag_step: float = 1.0
    mag_heading_sigma: float = 5.0 * DEG
    mag_calibrate: bool = True
    mag_corr_s: float = 10.0
    speed_hold: bool = False
    speed_hold_window_s: float = 20.0
    speed_hold_corr_s: float = 5.0
    speed_hold_floor: float = 0.05
    speed_hold_turn: float = 3.0 * DEG
    speed_hold_max_s: float = 30.0


@dataclass
class NoiseAdaptation:
    """The online process-noise scale ``λ`` (:class:`selfnav.ins.calibrate.NoiseAdapter`):
    policy choices of an estimator.

    Attributes
    ----------
    hi : largest ``λ``
    up_step : largest factor one fix may raise ``λ`` by
    decay : factor per trusted fix back towards 1
    memory : trusted fixes over which the main filter's normalised innovations are averaged
    trigger : mean normalised innovation per dimension above which ``λ`` rises
    clip : a single test counts for at most this many times its dimension
    reference_age_s : references up to this age witness the dead reckoning for ``λ``
    reference_memory_s : s over which their normalised χ² is averaged (κ̂)
    q_scale0 : ``λ`` at the start
    vibration : scale the process noise by the vibration the IMU feels, block by block, over
        the vibration at rest (:func:`selfnav.ins.calibrate.vibration_scale`)
    vibration_cap : the largest vibration factor
    reopen_windows : numbers of trusted fixes whose normalised innovations, summed, test the
        covariance itself: beyond the χ² gate of their ``2n`` dimensions (at
        ``integrity.p_false_alarm`` shared among the windows) the filter knows its state
        less well than it says (a start that left the tilt 5σ off) and ``P`` is scaled by
        their mean per dimension — one fading-memory step, at once, where ``λ`` would take
        minutes; the fault bank's health clock starts again. Only while no reference of
        the bank stands (with references, growing innovations are theirs to judge: a drag's
        first fixes reopened ``P`` and captured the filter) (() : never)
    reopen_cap : the largest factor one reopening scales ``P`` by
    """

    hi: float = 1e3
    up_step: float = 1.05
    decay: float = 0.99
    memory: int = 40
    trigger: float = 2.0
    clip: float = 25.0
    reference_age_s: float = 40.0
    reference_memory_s: float = 60.0
    q_scale0: float = 1.0
    vibration: bool = True
    vibration_cap: float = 100.0
    reopen_windows: tuple = (8, 16, 32)
    reopen_cap: float = 25.0


@dataclass
class Integrity:
    """The fault-hypothesis bank (:mod:`selfnav.ins.hypotheses`): how the navigator decides
    between the fixes and the inertial solution. Every field is a policy choice.

    Attributes
    ----------
    bank : the fault-hypothesis bank (False: the plain χ² gate of each fix alone, the baseline
        most fusion stacks run)
    p_false_alarm : probability that a consistent fix (or run) fails a gate; every χ² gate
        of a single fix is the quantile of this probability
    false_alarms_per_hour : expected false fault detections (a reset to dead reckoning) per
        hour of healthy GNSS: the references' gate is the quantile of this rate shared among
        the tests an hour holds
    integrity_risk : the risk a protection level stands for (two-sided normal factor)
    branch_every_s : s between dead-reckoning references while the GNSS is healthy
    branch_after_s : s of fixes fused without a break before a reference is branched (a
        filter just back from a long dead reckoning has not settled: its σ is not yet honest)
    max_age_s : s a reference lives while no episode is open (beyond a few minutes a MEMS
        dead reckoning's linearised σ stops covering it: on drive_0708 4-minute branches
        were 350 m off at a 65 m σ)
    min_age_s : s before a reference judges fixes
    reference_safety : the references' tests (and the innovation sums) take their χ² over
        this factor: an envelope must err on the safe side — a false alarm throws away a
        good solution for a dead reckoning (2: an envelope √2 wider than the covariance;
        consumer references 100 s old reached χ² 26 on clean simulated drives)
    reference_step_s : s between reference propagation steps (cost; the NHC then weighs as
        much per second as the filter's updates with their correlated errors)
    rejections_to_open : consecutive rejected fixes that open an episode
    run_s : s a run of fixes must span before it may end an episode
    run_min_fixes : fixes a run needs at least
    run_max_s : s of the most recent fixes a run keeps
    recovery_odds : the likelihood ratio by which healthy fixes must beat the fault's
        extrapolation to end an episode
    innovation_windows : numbers of recent fixes whose whitened innovations must sum to
        about zero (a drag passes each fix's gate but pulls every one the same way)
    velocity_span_s : s of a run's last fixes whose own velocity is given to the navigator
        when the run ends an episode
    onset_s : s of fixes after an episode opens that characterise the fault (a smooth fault
        is then extrapolated: the fixes are taken back when they no longer follow it)
    reinit_after_s : s of fixes that agree with each other and move with the INS but stand
        outside its envelope before the INS, not the GNSS, is taken as the faulty side; the
        span of fixes the navigator restarts from when the INS is lost; and the span of the
        tracks the road map judges (:meth:`selfnav.ins.hypotheses.FaultBank._map_look`)
    max_fault_s : the longest GNSS fault the navigator holds out against (seed 004: outliers
        for up to 5 minutes): fixes that agree with each other after an episode this long,
        with no reference left, restart the INS
    fault_white_sigmas : the white-outlier family of the run test
        (:mod:`selfnav.ins.runtest`): σ of the outliers, in fix σ (a fact of GNSS faults:
        multipath to a wrong lock, 3–100× the receiver's own noise)
    fault_min_m : the fault families scale with the fixes' σ but not below this, m (a fact:
        faults worth a dead reckoning are metres; below, an RTK fix's discrepancies are the
        navigator's own model — lever arm, timing — and 0.3 m "faults" kept clean RTK fixes
        out for minutes after a window on drive_0708)
    fault_gm_sigmas, fault_gm_s : the correlated family: σ (in fix σ) and correlation times,
        s, of errors that wander (multipath, a receiver's slow loss of lock)
    fault_ramp_mps : the ramp family: the rates of a drag, m/s (a spoofer's, a receiver
        pulled off), with an offset of ``fault_ramp_onset_s`` times that rate
    fault_ramp_onset_s : s of drag before a ramp is noticed (the offset it carries then)
    fault_ramp_change_s : the drift family (a smooth drag): s over which its rate changes (its
        acceleration σ is the rate over this) and the correlation time of its wander
    fault_mean_s : the mean length of a GNSS fault, s: the prior odds that a fault seen ``d`` s
        ago has ended are ``e^{d/T} − 1`` (runs the evidence cannot tell from health are taken
        back after ``T ln(1/α)``; seed 004's windows last 30 s to 5 minutes)
    map_fixes_llr : with a road map, the INS is lost when the map puts its recent track off
        the roads by ``ln(1/α)`` beyond its σ while the fixes' track lies on them by at least
        this log-likelihood ratio (against the same shape put elsewhere: a policy — 3, a fit
        that one copy in twenty matches; at 1 dragged fixes lying on a parallel road by chance
        restarted simulated drives onto them); and, the other way, the navigator goes back to
        a dead reckoning whose track the map puts on the roads by this much while the
        solution that took the fixes it puts off them by ``ln(1/α)``
    lost_m, lost_mps, lost_rad, lost_mps2 : the INS-lost hypothesis of the run test: how far
        the dead reckoning may be off beyond its covariance, m, m/s, rad of heading and m/s² of
        acceleration
    outage_s : s without a fix that count as an outage (status dead-reckoning)
    separation_floor_m : smallest σ of a separation between two solutions (numerics), m
    """

    bank: bool = True
    p_false_alarm: float = 1e-4
    false_alarms_per_hour: float = 0.1
    integrity_risk: float = 1e-5
    branch_every_s: float = 10.0
    branch_after_s: float = 30.0
    max_age_s: float = 160.0
    min_age_s: float = 2.0
    reference_safety: float = 2.0
    reference_step_s: float = 1.0
    rejections_to_open: int = 2
    run_s: float = 5.0
    run_min_fixes: int = 5
    run_max_s: float = 30.0
    onset_s: float = 3.0
    recovery_odds: float = 100.0
    innovation_windows: tuple = (4, 8, 16, 32)
    velocity_span_s: float = 2.0
    reinit_after_s: float = 20.0
    max_fault_s: float = 300.0
    fault_white_sigmas: tuple = (3.0, 10.0, 30.0, 100.0)
    fault_min_m: float = 1.0
    fault_gm_sigmas: tuple = (3.0, 10.0, 30.0)
    fault_gm_s: tuple = (2.0, 10.0, 30.0)
    fault_ramp_mps: tuple = (0.5, 3.0)
    fault_ramp_onset_s: float = 10.0
    fault_ramp_change_s: float = 10.0
    fault_mean_s: float = 120.0
    map_fixes_llr: float = 3.0
    lost_m: float = 1000.0
    lost_mps: float = 10.0
    lost_rad: float = 1.0
    lost_mps2: float = 1.0
    outage_s: float = 2.0
    separation_floor_m: float = 0.05


GROUPS = {"imu": ImuNoise, "states": StateOptions, "init": Initialisation, "gnss": GnssAiding,
          "vehicle": VehicleConstraints, "integrity": Integrity, "adaptation": NoiseAdaptation}


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
    "industrial": {"scale_factors": True, "misalignment": True},
    "consumer": {"scale_factors": True, "misalignment": True, "nhc_sigma": 0.5},
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
    integrity: Integrity = field(default_factory=Integrity)
    adaptation: NoiseAdaptation = field(default_factory=NoiseAdaptation)
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


#: Platform profiles (issue 20): the motion constraints and the start each platform allows,
#: as facts of the platform (does it slide sideways, stop, move along its nose; how far its
#: heading is from its course). A platform that moves along its nose keeps the sideways
#: constraint with a mounting-yaw state for its offset (a handheld unit, a rover's slip): on
#: simulated walkers and rovers it holds the heading up to 2 times closer than without
#: (benchmarks/platforms_start.py); not a boat, which yaws about its course in the waves.
#: ``auto`` is the car's, and :data:`SLOW_PLATFORM`'s when the start shows no car.
PLATFORMS = {
    "car": dict(nhc=True, zupt=True, zupt_speed_sigmas=2.0, zupt_sigma_max=1.0,
                grade_sigma=0.08, any_start="fallback", course_heading=True,
                course_heading_sigma=4.0 * DEG),
    # a walker holding the unit ahead: it moves along its nose, 0-10 deg off (a mount state)
    "pedestrian": dict(nhc=True, mount_states=True, mount_sigma=10.0 * DEG, zupt=True,
                       zupt_speed=0.1, any_start="now", course_heading=True,
                       course_heading_sigma=15.0 * DEG, use_magnetometer=True,
                       speed_hold=True),
    # skid-steer: slips in its turns, nearly on the spot
    "rover": dict(nhc=True, mount_states=True, mount_sigma=5.0 * DEG, zupt=True,
                  zupt_speed=0.1, any_start="now", course_heading=True,
                  course_heading_sigma=10.0 * DEG, use_magnetometer=True,
                  speed_hold=True),
    # yaws about its course in the waves (a ship's ±5° at 15 s is 0.5 m/s sideways at 6 m/s),
    # leeway, current; never still. The sideways constraint at σ 1 m/s (twice a ship's sway)
    # with a mounting-yaw state for the mean leeway: at the car's 0.5 m/s and no mount state
    # it took the simulated ship 700 m off; without it the heading was only what the turns
    # and the magnetometer showed (simulated boats 6-46° RMS, with it 1.2-5.5°)
    "boat": dict(nhc=True, nhc_sigma=1.0, mount_states=True, mount_sigma=15.0 * DEG,
                 zupt=False, any_start="now", course_heading=True,
                 course_heading_sigma=15.0 * DEG, use_magnetometer=True),
    # crab angle in wind, sideslip in turns: no sideways constraint
    "aircraft": dict(nhc=False, zupt=False, any_start="now", course_heading=True,
                     course_heading_sigma=20.0 * DEG),
    # a multirotor flies sideways
    # (its magnetometer sits among motors whose field follows their current: not used after
    # the start — on simulated drones the fixes hold the heading to 0.4-1.9° anyway)
    "drone": dict(nhc=False, zupt=True, zupt_speed=0.1, any_start="now", course_heading=False),
}
#: What ``auto`` becomes when the car's start finds no car (a platform moving slower than a
#: car's start needs, :meth:`selfnav.ins.startup.StartUp.try_start`): the sideways constraint
#: with a mounting-yaw state (it removed two diverging walker and rover starts, 313 m and 26 m),
#: zero-velocity updates only when the INS is nearly still, the course a loose heading.
SLOW_PLATFORM = dict(nhc=True, mount_states=True, mount_sigma=15.0 * DEG, zupt_speed=0.1,
                     zupt_speed_sigmas=0.0, zupt_sigma_max=None, zaru_steady_s=2.0,
                     grade_sigma=None, course_heading=True, course_heading_sigma=20.0 * DEG,
                     use_magnetometer=True, speed_hold=True)
PLATFORM_ALIASES = {"ship": "boat", "walker": "pedestrian", "multirotor": "drone"}
PLATFORM_NAMES = ("auto",) + tuple(PLATFORMS) + tuple(PLATFORM_ALIASES)


def platform_settings(platform: str) -> dict:
    """The configuration fields of a platform profile (:data:`PLATFORMS`)."""
    key = str(platform).lower().strip()
    key = PLATFORM_ALIASES.get(key, key)
    if key == "auto":
        return {**PLATFORMS["car"], "platform": "auto"}
    if key not in PLATFORMS:
        raise SelfnavError(f"unknown platform '{platform}' (use {', '.join(PLATFORM_NAMES)})")
    return {**PLATFORMS[key], "platform": key}


def navigator_config(grade: str = "auto", *, lever_arm_m=None, nhc_lever_m=None,
                     nhc: bool | None = None, imu_time_offset_s: float | None = None,
                     odometer: bool = False, platform: str = "auto",
                     **fields) -> FilterConfig:
    """The configuration :class:`selfnav.ins.Navigator` (and ``selfnav navigate``) starts from.

    ``grade="auto"`` is the consumer preset as the prior (the widest), to be raised to what
    the data shows; ``lever_arm_m`` (IMU → antenna, body RFU, m) not given: estimated (3
    states); ``imu_time_offset_s`` not given: estimated (a state with the prior σ
    ``time_offset_sigma``); ``nhc_lever_m``: IMU → the point where the non-holonomic
    constraint holds (rear axle); ``platform``: a profile of :data:`PLATFORMS` (its motion
    constraints and start), ``nhc`` given: overrides the profile's; ``fields`` override any
    field by name.
    """
    opts = dict(platform_settings(platform), odometer=odometer)
    if nhc is not None:
        opts["nhc"] = bool(nhc)
        if opts["platform"] == "auto":
            opts["platform"] = f"auto, NHC {'on' if nhc else 'off'}"   # the user's choice stands
    if lever_arm_m is not None:
        opts["lever_arm_b"] = np.asarray(lever_arm_m, dtype=float)
    else:
        opts["lever_arm"] = True
    if nhc_lever_m is not None:
        opts["nhc_lever_b"] = np.asarray(nhc_lever_m, dtype=float)
    opts["time_offset"] = imu_time_offset_s is None
    opts["user_set"] = tuple(fields) + (("nhc",) if nhc is not None else ())
    auto = str(grade).lower().strip() == "auto"
    cfg = FilterConfig.for_grade("consumer" if auto else grade, **{**opts, **fields})
    if auto:
        cfg.imu.grade = "auto (consumer prior)"
    return cfg
