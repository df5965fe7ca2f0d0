"""Loosely coupled INS/GNSS error-state Kalman filter, RTS smoother and outlier defence (DESIGN §5, §7).

The nominal state is carried by the strapdown mechanization (:class:`selfnav.ins.strapdown.Strapdown`,
seed 004 fast loop); the filter estimates its errors

    δx = [δr (ENU, m), δv (ENU, m/s), ψ (rad), δb_g (rad/s), δb_a (m/s²)]        (15 states)
         [+ δs_g, δs_a (scale factors, 6)] [+ δμ (IMU pitch and yaw to the vehicle, 2)]

with ``δ(·) = estimated − true`` and the attitude error ``C̃_b^n = (I − [ψ]) C_b^n``. Error
dynamics (psi-angle form, Groves ch. 14, simplified to what a MEMS or tactical IMU needs)::

    δṙ = δv,                       plus  δv̇_U += (2g/R) δr_U (the unstable vertical channel)
    δv̇ = f^n × ψ − (2ω_ie + ω_en) × δv − C_b^n δb_a
    ψ̇ = −ω_in × ψ + C_b^n δb_g
    δḃ = −δb/τ + w                 (τ = ∞ by default: a turn-on constant plus a random walk
                                    whose density matches the bias instability)

Aiding: GNSS position with lever arm, GNSS velocity, non-holonomic constraint (a car does not
slide sideways or jump), zero-velocity updates when the IMU is still, magnetometer heading.

The non-holonomic constraint holds in the *vehicle* frame at a point that does not slip
sideways (the rear-axle centre), not at the IMU: ``v_v = C_vb (C_bn^T v^n + ω_b × l_nhc)``
with ``C_vb = exp([μ×])``, μ = (pitch, 0, yaw) of the IMU relative to the vehicle (small angles,
positive nose-up and to the left). Unmodelled, a 0.5° mounting pitch makes the NHC tilt the INS
by 0.5° while GNSS is out (a g·0.5° = 0.09 m/s² along-track error), and a 1.5 m lever turns
a 0.5 rad/s parking turn into 0.75 m/s of "side slip"; ``mount_states`` estimates μ,
``nhc_lever_b`` gives the lever.

**Outliers nothing flags** (seed 004: up to 5 min at 200 m σ; DESIGN §7). A χ² innovation gate
alone fails: while it rejects, P grows, and after a minute or two every outlier passes. selfnav
keeps the gate and adds a window test that P cannot weaken: consecutive fixes must agree with
each other *through the INS displacement* (short-term INS displacement is accurate to
centimetres even when its absolute position has drifted). After a run of rejections the filter
is in *suspect* mode: it dead-reckons (INS + vehicle constraints) and re-acquires only when a
window of fixes is internally consistent at the nominal σ and its common offset is consistent
with the dead-reckoning uncertainty. At start-up the same test (with a bounded-acceleration
motion model instead of the INS) chooses the first trusted fixes.
"""
from __future__ import annotations

import numpy as np

from selfnav import attitude as att
from selfnav.attitude import rotvec_to_dcm3, skew3
from selfnav.earth import OMEGA_EARTH, WGS84, enu_offset, normal_gravity, radii
from selfnav.ins.config import CHI2_1_999, CHI2_2_999, CHI2_3_999, FilterConfig
from selfnav.ins.strapdown import Strapdown
from selfnav.types import Trajectory

NX = 15
IR, IV, IP, IBG, IBA = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)
ISG, ISA = slice(15, 18), slice(18, 21)   # scale-factor errors (option)


class InsGnssFilter:
    """Error-state EKF on top of a strapdown INS, with streaming ``predict``/``update_*`` calls.

    Most users call :func:`run_filter`; this class is the streaming interface (feed IMU blocks
    and fixes as they arrive).
    """

    def __init__(self, cfg: FilterConfig, t0, lat, lon, h, velocity_n, C_nb, *, ellipsoid=WGS84):
        self.cfg = cfg
        self.ins = Strapdown(lat, lon, h, velocity_n, C_nb, t=t0, ellipsoid=ellipsoid,
                             vertical=cfg.vertical)
        self.nx = 21 if cfg.states.scale_factors else NX
        self.imt = slice(self.nx, self.nx + 2) if cfg.states.mount_states else None
        self.nx += 2 if cfg.states.mount_states else 0
        self.bg = np.zeros(3)
        self.ba = np.zeros(3)
        self.sg = np.zeros(3)
        self.sa = np.zeros(3)
        self.mu = np.array(cfg.states.mount_rad, dtype=float)   # IMU pitch, yaw relative to the vehicle
        P = np.zeros((self.nx, self.nx))
        P[IR, IR] = np.eye(3) * cfg.init.pos_sigma**2
        P[IV, IV] = np.eye(3) * cfg.init.vel_sigma**2
        P[IP, IP] = np.diag(np.square(cfg.init.att_sigma))
        P[IBG, IBG] = np.eye(3) * cfg.imu.gyro_bias_sigma**2
        P[IBA, IBA] = np.eye(3) * cfg.imu.accel_bias_sigma**2
        if cfg.states.scale_factors:
            P[ISG, ISG] = np.eye(3) * cfg.imu.gyro_sf_sigma**2
            P[ISA, ISA] = np.eye(3) * cfg.imu.accel_sf_sigma**2
        if cfg.states.mount_states:
            P[self.imt, self.imt] = np.eye(2) * cfg.states.mount_sigma**2
        self.P = P
        self._f_n = np.array([0.0, 0.0, 9.8])
        self._w_b = np.zeros(3)
        self._f_b = np.array([0.0, 0.0, 9.8])
        self._Phi_acc = np.eye(self.nx)  # transition since the last stored epoch (smoother)
        self._n_corr = 0
        self._I = np.eye(self.nx)
        self._I3 = np.eye(3)

    # ------------------------------------------------------------------ model
    def _F(self, f_n, dt):
        cfg = self.cfg
        lat, h = self.ins.lat, self.ins.h
        v = self.ins.velocity_n
        rm, rn = radii(lat, h)
        w_ie = np.array([0.0, OMEGA_EARTH * np.cos(lat), OMEGA_EARTH * np.sin(lat)])
        w_en = np.array([-v[1] / rm, v[0] / rn, v[0] * np.tan(lat) / rn])
        C_bn = self.ins.C_nb.T
        F = np.zeros((self.nx, self.nx))
        F[0, 3] = F[1, 4] = F[2, 5] = 1.0
        F[IV, IP] = skew3(f_n)
        F[IV, IV] = -skew3(2 * w_ie + w_en)
        F[IV, IBA] = -C_bn
        g = float(normal_gravity(lat, h))
        F[5, 2] = 2.0 * g / (np.sqrt(rm * rn))
        F[IP, IP] = -skew3(w_ie + w_en)
        F[IP, IBG] = C_bn
        if np.isfinite(cfg.imu.gyro_bias_tau):
            F[IBG, IBG] = -self._I3 / cfg.imu.gyro_bias_tau
        if np.isfinite(cfg.imu.accel_bias_tau):
            F[IBA, IBA] = -self._I3 / cfg.imu.accel_bias_tau
        if cfg.states.scale_factors:
            # corrected rate (ω̃ − b)/(1 + s): its error is −(δb + diag(ω) δs)
            F[IP, ISG] = C_bn * self._w_b[None, :]
            F[IV, ISA] = -C_bn * self._f_b[None, :]
        return F

    def _Q(self, dt):
        cfg = self.cfg
        q = np.zeros(self.nx)
        q[IV] = cfg.imu.vrw**2
        q[IP] = cfg.imu.arw**2
        q[IBG] = 2 * cfg.imu.gyro_bias_instability**2 / cfg.imu.instability_tau
        q[IBA] = 2 * cfg.imu.accel_bias_instability**2 / cfg.imu.instability_tau
        return np.diag(q * dt)

    # ------------------------------------------------------------------ propagation
    def predict(self, t, dtheta, dv):
        """Mechanize a block of IMU increments (bias-corrected) and propagate the covariance.

        Returns the block's :class:`~selfnav.types.Trajectory`.
        """
        t = np.asarray(t, dtype=float)
        if len(t) == 0:
            return None
        dt = np.diff(np.concatenate([[self.ins.t], t]))
        dth = (dtheta - self.bg * dt[:, None]) / (1.0 + self.sg)
        dvb = (dv - self.ba * dt[:, None]) / (1.0 + self.sa)
        tr = self.ins.run(t, dth, dvb)
        T = float(t[-1] - (t[0] - dt[0]))
        f_b = dvb.sum(0) / T
        self._f_b = f_b
        self._f_n = tr.C_nb[-1].T @ f_b
        self._w_b = dth.sum(0) / T
        nsub = max(1, int(np.ceil(T / self.cfg.cov_step)))
        F = self._F(self._f_n, T)
        h = T / nsub
        Phi = self._I + F * h + 0.5 * (F @ F) * h * h
        Q = self._Q(h)
        for _ in range(nsub):
            self.P = Phi @ self.P @ Phi.T + Q
            self._Phi_acc = Phi @ self._Phi_acc
        return tr

    # ------------------------------------------------------------------ updates
    def _correct(self, dx):
        ins = self.ins
        lat, h = ins.lat, ins.h
        rm, rn = radii(lat, h)
        C_bn = rotvec_to_dcm3(dx[IP]) @ ins.C_nb.T
        self._n_corr += 1
        if self._n_corr % 100 == 0:  # rotations keep it orthonormal; clean rounding now and then
            C_bn = att.orthonormalize(C_bn)
        ins.set_state(lat=lat - dx[1] / rm, lon=ins.lon - dx[0] / (rn * np.cos(lat)),
                      h=h - dx[2], velocity_n=ins.velocity_n - dx[IV], C_nb=C_bn.T, check=False)
        self.bg -= dx[IBG]  # δb = estimated − true
        self.ba -= dx[IBA]
        if self.cfg.states.scale_factors:
            self.sg -= dx[ISG]
            self.sa -= dx[ISA]
        if self.imt is not None:
            self.mu -= dx[self.imt]

    def _kalman(self, r, H, R):
        S = H @ self.P @ H.T + R
        K = np.linalg.solve(S, H @ self.P).T
        dx = K @ r
        IKH = self._I - K @ H
        self.P = IKH @ self.P @ IKH.T + K @ R @ K.T
        self._correct(dx)
        return dx

    def position_residual(self, lat, lon, h):
        """``h(x̃) − z`` in ENU metres and its H for a GNSS fix at the antenna."""
        ins = self.ins
        C_bn = ins.C_nb.T
        l_n = C_bn @ self.cfg.gnss.lever_arm_b
        z = enu_offset(ins.lat, ins.lon, ins.h, lat, lon, h)
        r = l_n - z
        H = np.zeros((3, self.nx))
        H[:, IR] = np.eye(3)
        H[:, IP] = skew3(l_n)
        return r, H

    def update_position(self, lat, lon, h, sigma_h, sigma_v, *, gate=None):
        """GNSS position update with χ² gating; returns ``(accepted, nis, residual)``."""
        r, H = self.position_residual(lat, lon, h)
        R = np.diag([sigma_h**2, sigma_h**2, sigma_v**2])
        S = H @ self.P @ H.T + R
        nis = float(r @ np.linalg.solve(S, r))
        if gate is not None and nis > gate:
            return False, nis, r
        self._kalman(r, H, R)
        return True, nis, r

    def update_velocity(self, velocity_n, sigma):
        H = np.zeros((3, self.nx))
        H[:, IV] = np.eye(3)
        r = self.ins.velocity_n - np.asarray(velocity_n)
        R = np.eye(3) * sigma**2
        S = H @ self.P @ H.T + R
        if float(r @ np.linalg.solve(S, r)) > CHI2_3_999:
            return np.zeros(self.nx)
        return self._kalman(r, H, R)

    def update_nhc(self):
        """Non-holonomic constraint: the vehicle's lateral and vertical velocity are zero.

        At the point ``nhc_lever_b`` (rear-axle centre) and in the vehicle frame rotated from
        the IMU's by the mounting angles μ (estimated with ``mount_states``)::

            v_v = exp([μ×]) (C_nb v^n + ω_b × l),    z = (v_v,R, v_v,U) = 0
            ∂v_v/∂δv = C_vb C_nb,  ∂v_v/∂ψ = −C_vb C_nb [v^n×],  ∂v_v/∂δμ = −[v_v×] (cols x, z)
        """
        C_nb = self.ins.C_nb
        v = self.ins.velocity_n
        vv = C_nb @ v
        C_vn = C_nb
        lever = self.cfg.vehicle.nhc_lever_b
        if lever[0] or lever[1] or lever[2]:
            vv = vv + skew3(self._w_b) @ lever
        if self.imt is not None or self.mu[0] or self.mu[1]:
            C_vb = rotvec_to_dcm3(np.array([self.mu[0], 0.0, self.mu[1]]))
            C_vn = C_vb @ C_nb
            vv = C_vb @ vv
        H = np.zeros((2, self.nx))
        H[:, IV] = C_vn[[0, 2]]
        H[:, IP] = -C_vn[[0, 2]] @ skew3(v)
        if self.imt is not None:
            H[:, self.imt] = -skew3(vv)[[0, 2]][:, [0, 2]]
        cfg = self.cfg
        s_up = cfg.vehicle.nhc_sigma if cfg.vehicle.nhc_sigma_up is None else cfg.vehicle.nhc_sigma_up
        R = np.diag([cfg.vehicle.nhc_sigma**2, s_up**2])
        return self._kalman(vv[[0, 2]], H, R)

    def update_road(self, normal_n, offset, sigma, heading=None, sigma_heading=None):
        """Road constraint: the vehicle is on the road centre line (and heads along it).

        Parameters
        ----------
        normal_n : (2,) unit horizontal normal of the road at the foot point, ENU
        offset : float
            Signed distance of the INS position from the centre line along ``normal_n``, m.
        sigma : float
            σ of the true offset (half a lane, or the road's width), m.
        heading, sigma_heading : float, optional
            Road direction of travel (rad, clockwise from North) and its σ.

        Returns the error-state correction (gated at χ² 0.999).
        """
        rows, res, var = [], [], []
        h = np.zeros(self.nx)
        h[0:2] = normal_n
        rows.append(h)
        res.append(offset)
        var.append(sigma**2)
        if heading is not None:
            _, _, hdg = att.euler_from_dcm_nb(self.ins.C_nb)
            h2 = np.zeros(self.nx)
            h2[8] = 1.0
            rows.append(h2)
            res.append(float(np.angle(np.exp(1j * (hdg - heading)))))
            var.append(sigma_heading**2)
        H = np.array(rows)
        r = np.array(res)
        R = np.diag(var)
        S = H @ self.P @ H.T + R
        if float(r @ np.linalg.solve(S, r)) > (CHI2_2_999 if len(r) == 2 else CHI2_1_999):
            return np.zeros(self.nx)
        return self._kalman(r, H, R)

    def update_zupt(self):
        H = np.zeros((3, self.nx))
        H[:, IV] = np.eye(3)
        return self._kalman(self.ins.velocity_n, H, np.eye(3) * self.cfg.vehicle.zupt_sigma**2)

    def update_heading(self, heading, sigma):
        """True heading (rad), e.g. magnetic heading plus declination (seed 004 (12))."""
        _, _, hdg = att.euler_from_dcm_nb(self.ins.C_nb)
        r = np.array([np.angle(np.exp(1j * (hdg - heading)))])
        H = np.zeros((1, self.nx))
        H[0, 8] = 1.0  # ψ_U raises the computed heading (C̃ = (I − [ψ]) C)
        S = H @ self.P @ H.T + sigma**2
        if float(r @ r / S[0, 0]) > CHI2_1_999:
            return np.zeros(self.nx)
        return self._kalman(r, H, np.array([[sigma**2]]))

    def take_transition(self):
        Phi = self._Phi_acc
        self._Phi_acc = np.eye(self.nx)
        return Phi


def _lever_arm_n(self):
    return self.ins.C_nb.T @ self.cfg.gnss.lever_arm_b


InsGnssFilter.lever_arm_n = _lever_arm_n


def pack_state(flt):
    s = flt.ins
    return np.concatenate([[s.lat, s.lon, s.h], s.velocity_n, s.C_nb.reshape(9), flt.bg, flt.ba,
                           flt.sg, flt.sa, flt.mu])


def unpack_states(t, states, Ps):
    C = states[:, 6:15].reshape(-1, 3, 3)
    traj = Trajectory(t, states[:, 0], states[:, 1], states[:, 2], states[:, 3:6], C,
                      source="selfnav ekf")
    sig = np.sqrt(np.maximum(np.diagonal(Ps, axis1=1, axis2=2), 0.0))
    return traj, sig, states[:, 15:18], states[:, 18:21], states[:, 27:29]


def apply_error(state, dx):
    """Remove an error-state estimate from a packed nominal state.

    The layout is told by the length of ``dx``: 15 (+6 scale factors) (+2 mounting angles).
    """
    lat, lon, h = state[0], state[1], state[2]
    rm, rn = radii(lat, h)
    out = state.copy()
    out[0] = lat - dx[1] / rm
    out[1] = lon - dx[0] / (rn * np.cos(lat))
    out[2] = h - dx[2]
    out[3:6] = state[3:6] - dx[IV]
    C_nb = state[6:15].reshape(3, 3)
    C_bn = att.rotvec_to_dcm(dx[IP]) @ C_nb.T
    out[6:15] = att.orthonormalize(C_bn).T.reshape(9)
    out[15:18] = state[15:18] - dx[IBG]
    out[18:21] = state[18:21] - dx[IBA]
    if len(dx) >= 21:
        out[21:24] = state[21:24] - dx[ISG]
        out[24:27] = state[24:27] - dx[ISA]
    if len(dx) in (NX + 2, 23):
        out[27:29] = state[27:29] - dx[-2:]
    return out


def rts_smooth(states, P_plus, P_minus, Phi, updates, breaks=None):
    """Rauch–Tung–Striebel smoother in error-state form over the stored epochs.

    Epoch k holds the corrected nominal state x̃⁺_k with covariance P⁺_k; ``Phi[k]`` carries the
    error from epoch k−1 to k, ``P_minus[k]`` is the covariance before epoch k's update and
    ``updates[k]`` the error estimate that update removed. With a reset after every update the
    filtered error of x̃⁺_k is zero, and the smoothed one is
    ``ε_k = A_k (updates[k+1] + ε_{k+1})``, ``A_k = P⁺_k Φ_{k+1}ᵀ (P⁻_{k+1})⁻¹`` (the error of
    the propagated state at k+1 is what its update removed plus what the smoother adds).

    ``breaks[k]``: epoch k's state was *replaced* (a reset to a dead-reckoning shadow,
    :mod:`selfnav.ins.guard`), not updated; nothing is carried back across it.
    """
    n = len(states)
    out = states.copy()
    Ps = P_plus.copy()
    nx = updates.shape[1]
    eps_next = np.zeros(nx)
    for k in range(n - 2, -1, -1):
        if breaks is not None and breaks[k + 1]:
            eps_next = np.zeros(nx)
            continue
        Pm = P_minus[k + 1]
        A = np.linalg.solve(Pm.T, (P_plus[k] @ Phi[k + 1].T).T).T
        eps = A @ (updates[k + 1] + eps_next)
        Ps[k] = P_plus[k] + A @ (Ps[k + 1] - Pm) @ A.T
        out[k] = apply_error(states[k], eps)
        eps_next = eps
    return out, Ps


__all__ = ["InsGnssFilter", "NX", "IR", "IV", "IP", "IBG", "IBA"]
