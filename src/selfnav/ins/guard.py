"""Dead-reckoning hypotheses kept alongside the INS/GNSS filter (issue 4, DESIGN §7).

The filter's own tests (χ² gate, window test) compare each fix with an INS that those same fixes
keep correcting. An error that *drifts smoothly* — a receiver that slides away over tens of
seconds, a spoofer dragging the solution off — passes both: every fix is a little off, the filter
follows, its velocity follows, and the displacement between fixes agrees with the (dragged)
INS. Measured on drive_0708 before this module: a 200 m σ second-order Gauss–Markov drift
(τ 60 s) for 3 minutes pulled the filter 150–400 m off and left it lost afterwards.

The defence is a solution the fixes cannot touch: *shadows*, copies of the filter branched every
``dr_branch`` seconds while GNSS is trusted, then carried by the IMU with the vehicle constraints
(NHC, ZUPT) only. A shadow's covariance grows honestly with its age, so it tells how far the
truth can be from it. Each fix is tested against every shadow older than ``dr_min_age``:

    ν = z − h(x_shadow),   ν^T (H P_shadow H^T + R)^{-1} ν  ≤  χ²₂(0.9999)     (horizontal)

A fix that a shadow rejects is rejected. When the filter then goes suspect (dead reckoning), it
is reset to the oldest shadow it has moved away from (in position or velocity; the younger
shadows, branched from the dragged filter, are dropped), or else its covariance is widened by
its difference from the youngest shadow. While suspect, shadows are neither branched nor
retired, and a run of fixes is taken back only when it is within the dead reckoning's
uncertainty *and* its offset from the dead reckoning stops moving (:func:`track_agrees`) — a
smooth drift is self-consistent, but it moves at its own speed (:mod:`selfnav.ins.navigator`).

The shadows are cheaper than the filter: they are propagated and constrained once per
``dr_step`` (the NHC then weighs as much per second as the filter's five-per-second updates
with correlated errors would).
"""
from __future__ import annotations

import copy
import dataclasses

import numpy as np

from selfnav.earth import enu_offset
from selfnav.ins.config import CHI2_2_999, CHI2_2_9999, chi2_999

#: χ² (2 dof) of a fix-to-fix link
CHI2_2_999_LINK = CHI2_2_999
#: median absolute deviation to σ for a normal distribution
MAD_TO_SIGMA = 1.4826
from selfnav.ins.ekf import IR, IV


def clone_filter(flt):
    """An independent copy of an :class:`~selfnav.ins.ekf.InsGnssFilter` (state, P, biases)."""
    out = copy.copy(flt)
    out.ins = copy.deepcopy(flt.ins)
    for name in ("P", "bg", "ba", "sg", "sa", "mu", "_f_n", "_w_b", "_f_b"):
        setattr(out, name, np.array(getattr(flt, name), dtype=float, copy=True))
    out._Phi_acc = np.eye(flt.nx)
    return out


def _difference(sh, flt):
    """Position (ENU m) and velocity of ``flt`` less those of shadow ``sh``."""
    d = enu_offset(sh.ins.lat, sh.ins.lon, sh.ins.h, flt.ins.lat, flt.ins.lon, flt.ins.h)
    return d, flt.ins.velocity_n - sh.ins.velocity_n


class DeadReckoningGuard:
    """Shadow dead-reckoning filters and the drift test (see the module docstring).

    Parameters
    ----------
    cfg : FilterConfig
        Uses ``dr_branch`` (s between shadows), ``dr_max_age`` (s a shadow lives while GNSS is
        trusted), ``dr_min_age`` (s before a shadow tests fixes), ``dr_step`` (s between shadow
        updates) and ``dr_gate`` (χ², 2 dof).
    """

    def __init__(self, cfg):
        self.cfg = cfg
        self.shadows = []          # [t_branch, filter], oldest first
        self.last_chi2 = []        # the last fix's χ² against each mature shadow
        self._buf = []             # IMU blocks since the last shadow step
        self._t_step = -np.inf
        self.alarms = 0

    # ------------------------------------------------------------------ life cycle
    def maintain(self, t, flt, trusted: bool, suspect: bool):
        """Branch a shadow from ``flt`` every ``dr_branch`` s while trusted and retire those
        older than ``dr_max_age``. In suspect mode nothing is branched nor retired: the old
        shadows are the clean references a drift that comes and goes must be judged against."""
        cfg = self.cfg
        if suspect:
            return
        # a shadow of an unconverged filter (just after the in-motion alignment) would
        # dead-reckon worse than its covariance says: branch only once the attitude is known
        converged = float(np.max(np.diag(flt.P)[6:9])) < cfg.shadows.branch_att_sigma**2
        if trusted and converged:
            if not self.shadows or t - self.shadows[-1][0] >= cfg.shadows.branch_every - 1e-9:
                self._flush()
                sh = clone_filter(flt)
                # one covariance step per shadow step: a dead-reckoning σ needs no finer grid
                sh.cfg = dataclasses.replace(flt.cfg, cov_step=max(cfg.cov_step, cfg.shadows.step))
                self.shadows.append([t, sh])
            while len(self.shadows) > 1 and t - self.shadows[0][0] > cfg.shadows.max_age:
                self.shadows.pop(0)

    def predict(self, t, dtheta, dv, still):
        """Store an IMU block; the shadows are moved once per ``dr_step``."""
        if not self.shadows:
            return
        self._buf.append((t, dtheta, dv, still))
        if t[-1] - self._t_step >= self.cfg.shadows.step - 1e-9:
            self._flush()

    def _flush(self):
        if not self._buf:
            return
        t = np.concatenate([b[0] for b in self._buf])
        dth = np.concatenate([b[1] for b in self._buf])
        dv = np.concatenate([b[2] for b in self._buf])
        still = all(b[3] for b in self._buf)
        self._buf = []
        self._t_step = float(t[-1])
        for _, sh in self.shadows:
            if sh.ins.t >= t[-1]:
                continue
            k = t > sh.ins.t
            sh.predict(t[k], dth[k], dv[k])
            if still and self.cfg.vehicle.zupt:
                sh.update_zupt()
            elif self.cfg.vehicle.nhc:
                sh.update_nhc()
            sh.take_transition()

    # ------------------------------------------------------------------ tests
    def mature(self, t):
        """The ``[t_branch, filter]`` entries old enough to test, oldest first."""
        return [e for e in self.shadows if t - e[0] >= self.cfg.shadows.min_age]

    def shadows_mature(self, t):
        """The number of shadows old enough to test fixes."""
        return len(self.mature(t))

    def rejects(self, t, lat, lon, h, sigma_h, scale=1.0):
        """The oldest mature shadow (its entry) that rejects the fix (horizontal χ²), or None.

        ``scale`` inflates the shadows' σ (``sigma_scale``: an EKF's dead-reckoning
        covariance is optimistic after the alignment, and a false alarm costs a reset).
        The fix's χ² (2 dof, σ not inflated) against every mature shadow is kept in
        :attr:`last_chi2` for the noise calibration.
        """
        self._flush()
        self.last_chi2 = []
        found = None
        R = np.eye(2) * sigma_h**2
        for e in self.mature(t):
            r, H = e[1].position_residual(lat, lon, h)
            HPH = (H[:2] @ e[1].P @ H[:2].T)
            d = r[:2]
            self.last_chi2.append(float(d @ np.linalg.solve(HPH + R, d)))
            if found is None and float(d @ np.linalg.solve(HPH * scale**2 + R, d)) > \
                    self.cfg.shadows.shadow_gate:
                found = e
        return found

    def dragged(self, t, flt, scale=1.0):
        """The oldest mature shadow from which ``flt`` has moved farther than the two
        covariances allow, in horizontal position or velocity (χ², ``scale`` on the shadow's
        σ), or None. The velocity is the sharper test: a drift followed for a few seconds
        bends the velocity by its rate (σ 3 m/s at 200 m, 60 s) against a shadow's 0.1–1 m/s."""
        self._flush()
        for e in self.mature(t):
            sh = e[1]
            d, dv = _difference(sh, flt)
            for r, idx in ((d[:2], slice(0, 2)), (dv[:2], slice(3, 5))):
                S = sh.P[idx, idx] * scale**2 + flt.P[idx, idx]
                if float(r @ np.linalg.solve(S, r)) > self.cfg.shadows.shadow_gate:
                    return e
        return None

    def widen(self, t, flt):
        """Cover a drag that began before any test saw it: on entering suspect mode, add the
        squared position and velocity differences to the youngest mature shadow to ``flt.P``.

        A smooth drift is followed for a few seconds before a fix is rejected; the velocity the
        filter then carries into the dead reckoning is off by up to the drift's rate, which its
        covariance does not know — and an optimistic covariance never re-acquires."""
        self._flush()
        mature = self.mature(t)
        if not mature:
            return None
        d, dv = _difference(mature[-1][1], flt)
        add = np.zeros_like(flt.P)
        add[IR, IR] = np.diag(d * d)
        add[IV, IV] = np.diag(dv * dv)
        flt.P += add
        return add

    def reset_to(self, entry, flt):
        """Put a shadow's state into ``flt``; drop the younger (dragged) shadows.

        Returns False when the shadow has meanwhile been retired."""
        i = next((j for j, e in enumerate(self.shadows) if e is entry), None)
        if i is None:
            return False
        self._flush()
        sh = entry[1]
        flt.ins.set_state(lat=sh.ins.lat, lon=sh.ins.lon, h=sh.ins.h,
                          velocity_n=sh.ins.velocity_n, C_nb=sh.ins.C_nb, check=False)
        flt.ins.t = sh.ins.t
        flt.P = sh.P.copy()
        for name in ("bg", "ba", "sg", "sa", "mu"):
            setattr(flt, name, getattr(sh, name).copy())
        del self.shadows[i + 1:]
        self.alarms += 1
        return True


def track_agrees(t, innov_xy, sig, P_vv, max_fit_sigma=0.5, gate=CHI2_2_9999):
    """Do the fixes move like the dead reckoning? (re-acquisition test)

    ``innov_xy`` are fix − dead-reckoning offsets (ENU m) at times ``t`` over a run of mutually
    consistent fixes. For healthy fixes the offset is the dead reckoning's own error, which
    changes at its velocity error (covariance ``P_vv``, 2×2); a drifting receiver error moves
    at its own speed. The slope of a line fit must agree with zero within ``P_vv`` plus the
    fit's variance (χ², 2 dof), and the run must be long enough for a slope σ below
    ``max_fit_sigma`` (m/s) — shorter runs cannot tell a drift from a healthy receiver.
    """
    t = np.asarray(t, float)
    d = np.asarray(innov_xy, float)
    if len(t) < 4:
        return False
    tt = t - t.mean()
    A = np.column_stack([np.ones(len(t)), tt])
    coef, *_ = np.linalg.lstsq(A, d, rcond=None)
    res = d - A @ coef
    s2 = max(float(np.max(sig)) ** 2, float(np.mean(res * res)))
    var_fit = s2 / float(tt @ tt)
    if var_fit > max_fit_sigma**2:
        return False
    S = P_vv + np.eye(2) * var_fit
    return float(coef[1] @ np.linalg.solve(S, coef[1])) <= gate


class FixChain:
    """Do the fixes agree with each other through their own velocity? (GNSS only, no INS)

    "Decide who is wrong before acting" (DESIGN §10): a fix is *linked* to the previous one
    when the displacement between them matches the GNSS velocity integrated over the interval
    (trapezoid), both between consecutive fixes and over a window of ``window_s`` (which
    catches a slow drift the single step hides), at χ² 0.999. A fix is *anchored* when it is
    linked to a fix that was used or itself anchored: a chain of such fixes is evidence
    against an INS that rejects them, not against the fixes. A jump, white noise or a drift
    breaks the chain; a fix without velocity (or too imprecise for the test to mean anything)
    is never anchored, and a change of the receiver's quality flag (RTK fixed → float, …)
    breaks the chain: such switches come with jumps. Horizontal only.

    Parameters
    ----------
    window_s : the long link, s
    max_gap_s : a longer gap between fixes breaks the chain, s
    jerk : the trapezoid rule's error bound for the vehicle's changing acceleration, m/s³
    vel_bias : a slowly varying velocity error the long link allows for, m/s
    max_sigma : fixes less precise than this (m) are not tested
    """

    def __init__(self, window_s=5.0, max_gap_s=2.0, jerk=2.0, vel_bias=0.02, max_sigma=0.5,
                 gate=CHI2_2_999_LINK):
        self.window_s, self.max_gap_s, self.jerk, self.max_sigma = window_s, max_gap_s, jerk, max_sigma
        self.vel_bias = vel_bias
        self.gate = gate
        self.hist = []          # (t, p_EN (2,), v_EN (2,), σ_p, σ_v, anchored)
        self.breaks = 0
        self._quality = None

    def _test(self, a, b, span):
        dt = b[0] - a[0]
        # the velocity integral over the fixes in between (trapezoid), and its error
        pred = np.zeros(2)
        var_v = 0.0
        for x, y in zip(span[:-1], span[1:]):
            h = y[0] - x[0]
            pred += 0.5 * (x[2] + y[2]) * h
            var_v += 0.5 * (x[4] ** 2 + y[4] ** 2) * h * h + (self.jerk * h**3 / 12.0) ** 2
        d = b[1] - a[1] - pred
        var = a[3] ** 2 + b[3] ** 2 + var_v + (self.vel_bias * dt) ** 2
        return float(d @ d) / var <= self.gate and dt > 0

    def add(self, t, p_en, v_en, sigma_p, sigma_v, used_prev: bool, quality=None):
        """Add a fix; returns ``(linked, anchored)``. ``used_prev``: the previous fix was used;
        ``quality``: the receiver's flag (any scale; a change breaks the chain)."""
        if self.hist:
            last = self.hist[-1]
            self.hist[-1] = last[:5] + (last[5] or used_prev,)
        same_quality = quality is None or self._quality is None or quality == self._quality
        self._quality = quality
        ok = (v_en is not None and np.all(np.isfinite(v_en)) and sigma_p <= self.max_sigma
              and same_quality)
        rec = (float(t), np.asarray(p_en, float)[:2], None if v_en is None else np.asarray(v_en, float)[:2],
               float(sigma_p), float(sigma_v), False)
        linked = False
        if ok and self.hist and self.hist[-1][2] is not None and t - self.hist[-1][0] <= self.max_gap_s:
            prev = self.hist[-1]
            linked = self._test(prev, rec, [prev, rec])
            if linked:
                j = next((i for i in range(len(self.hist) - 1, -1, -1)
                          if t - self.hist[i][0] >= self.window_s), None)
                if j is not None:
                    span = self.hist[j:] + [rec]
                    gaps = all(y[0] - x[0] <= self.max_gap_s and x[2] is not None
                               for x, y in zip(span[:-1], span[1:]))
                    linked = gaps and self._test(self.hist[j], rec, span)
        anchored = linked and self.hist[-1][5]
        if not linked and self.hist:
            self.breaks += 1
        self.hist.append(rec[:5] + (anchored,))
        while self.hist and t - self.hist[0][0] > 2 * self.window_s + self.max_gap_s:
            self.hist.pop(0)
        return linked, anchored


def kinematic_consistent(t, p, sigma, max_accel=2.0, min_span=8.0):
    """Do fixes fit one smooth track by themselves? (GNSS only, no INS, no velocity)

    A quadratic in time (position, velocity, a constant acceleration) is fitted to the
    horizontal positions ``p`` (W, 2) at times ``t`` with σ ``sigma`` (W,); the track is
    consistent when the fit's χ² is within χ²(2(W−3), 0.999), the acceleration within
    ``max_accel`` plus its 3σ, and the run spans ``min_span`` s. White or rough
    outliers fail; clean fixes and a smooth drift pass (what separates those is the INS).
    """
    t = np.asarray(t, float)
    W = len(t)
    if W < 6 or t[-1] - t[0] < min_span:
        return False
    tt = t - t.mean()
    A = np.column_stack([np.ones(W), tt, 0.5 * tt * tt])
    w = 1.0 / np.asarray(sigma, float)
    coef, *_ = np.linalg.lstsq(A * w[:, None], np.asarray(p, float) * w[:, None], rcond=None)
    res = (np.asarray(p, float) - A @ coef) * w[:, None]
    if float(np.sum(res * res)) > chi2_999(2 * (W - 3)):
        return False
    cov = np.linalg.inv((A * w[:, None]).T @ (A * w[:, None]))
    return bool(np.hypot(*coef[2]) <= max_accel + 3.0 * np.sqrt(2.0 * cov[2, 2]))


__all__ = ["DeadReckoningGuard", "FixChain", "kinematic_consistent", "clone_filter", "track_agrees", "white_scale",
           "window_consistent"]


def white_scale(sus, out):
    """Robust per-axis scale of suspect innovations if they look white, else None.

    ``out`` is the :class:`~selfnav.ins.config.OutlierDefence` configuration. Innovations (fix
    minus INS) over the last ``degraded_window`` seconds, each axis detrended
    by a straight line (the dead-reckoning drift is slow). White errors: lag-1 autocorrelation
    near zero and the scale from fix-to-fix differences (÷√2) equal to the scale about the
    line. A drifting (Gauss–Markov) error is strongly autocorrelated: its fixes are not used.
    """
    if len(sus) < out.degraded_min:
        return None
    t = np.array([x[0] for x in sus])
    v = np.array([x[1][:2] for x in sus])
    A = np.column_stack([np.ones(len(t)), t - t.mean()])
    res = v - A @ np.linalg.lstsq(A, v, rcond=None)[0]
    rho = np.sum(res[1:] * res[:-1], axis=0) / np.maximum(np.sum(res * res, axis=0), 1e-300)
    s_diff = MAD_TO_SIGMA * np.median(np.abs(np.diff(res, axis=0))) / np.sqrt(2.0)
    s_level = MAD_TO_SIGMA * np.median(np.abs(res - np.median(res, axis=0)))
    if s_level <= 0 or np.max(rho) > out.white_rho_max or s_diff < out.white_ratio_min * s_level:
        return None
    return float(max(s_diff, s_level))


def window_consistent(buf, fixes, sv, trend=False, s_acc=0.0):
    """The fixes of the window share one offset from the INS displacement (χ², 0.999).

    ``d_i = z_i − (INS displacement)_i`` is the same for every fix of a healthy window (the INS
    drift over a few seconds is ``sv·Δt + ½ s_acc·Δt²``, ``s_acc`` the horizontal acceleration
    error the covariance allows: a levelling error, an accelerometer bias); the test is ``Σ |d_i − d̄|²/σ_i² ≤ χ²(3(W−1))``.
    Stronger than pairwise tests against errors that wander between fixes (Gauss–Markov
    outliers), and P cannot weaken it. ``trend=True`` fits an offset *and a rate* (the
    velocity error of a long dead reckoning, which its covariance may understate; the rate is
    then judged by :func:`selfnav.ins.guard.track_agrees`): ``χ²(3(W−2))``.

    ``buf`` holds ``(fix index, INS displacement at the fix)``; ``fixes[k]`` has ``t, lat,
    lon, h, sigma_h, sigma_v``.
    """
    if len(buf) < 2:
        return True
    k0, s0 = buf[0]
    f0 = fixes[k0]
    d, var = [], []
    tm = np.mean([fixes[k].t for k, _ in buf])
    for k, snap in buf:
        f = fixes[k]
        z = enu_offset(f0.lat, f0.lon, f0.h, f.lat, f.lon, f.h)
        d.append(z - (snap - s0))
        dt = f.t - tm
        drift2 = (sv * abs(dt) + 0.5 * s_acc * dt * dt) ** 2
        var.append([f.sigma_h ** 2 + drift2, f.sigma_h ** 2 + drift2, f.sigma_v ** 2 + drift2])
    d, var = np.array(d), np.array(var)
    w = 1.0 / var
    if trend and len(buf) > 2:
        t = np.array([fixes[k].t for k, _ in buf]) - tm
        A = np.column_stack([np.ones(len(t)), t])
        res = np.empty_like(d)
        for j in range(3):
            sw = np.sqrt(w[:, j])
            coef = np.linalg.lstsq(A * sw[:, None], d[:, j] * sw, rcond=None)[0]
            res[:, j] = d[:, j] - A @ coef
        return float(np.sum(res**2 * w)) <= chi2_999(3 * (len(buf) - 2))
    mean = np.sum(d * w, axis=0) / np.sum(w, axis=0)
    chi2 = float(np.sum((d - mean) ** 2 * w))
    return chi2 <= chi2_999(3 * (len(buf) - 1))
