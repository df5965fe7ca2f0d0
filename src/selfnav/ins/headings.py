"""A start less sure of its heading than the filter's linear range: a Gaussian sum over the
heading (DESIGN §10; issues 18, 20).

The error-state EKF is linear in the attitude error ``ψ``; a heading error of 10–20° — what
a course from 10 m fixes at 5 m/s gives, or a start at rest with no heading at all — is
outside that range: the first acceleration rotated by the wrong heading leaves a velocity error
its second-order terms do not model, and the gyro biases and scale factors absorb what the
first-order model cannot explain (simulated consumer drives: 16° of heading at σ 10°, after a
minute 10° at σ 2.5° with the z gyro bias 5σ off). A filter that confident of a wrong state
defeats the fault bank: its dead-reckoning envelopes are branched off a wrong state.

So the start is split along its heading, as a Gaussian is split into a sum of narrower ones
(Alspach & Sorenson 1972; PX4's EKF-GSF yaw estimator does the same for a drone's yaw): ``K``
hypotheses at heading offsets ``δ_k``, spaced so that each is ``split_sigma`` wide (σ, inside
the linear range), each a full filter conditioned on its offset::

    x_k = x + P[:, ψ_U] δ_k / σ²,   P_k = P − (1 − σ_k² / σ²) P[:, ψ_U] P[ψ_U, :] / σ²

(the states correlated with the heading — the velocity of a start taken from the course —
move with it), with prior weights ``N(δ_k; 0, σ² − σ_k²)``. With ``yaw_bias_split_sigma``
set (0.5 °/s by default) each heading hypothesis is split the same way along the z gyro's bias
(a consumer part's 1 °/s at a start in motion leaves the linear range within seconds). Every
IMU sample, constraint and fix goes to every hypothesis; each fix multiplies a hypothesis'
weight by its likelihood (robust: its normalised innovation counts at most up to the gate, so
one outlier cannot eliminate the right hypothesis). Hypotheses below ``1 / prune_ratio`` of the best are dropped;
when the best holds ``resolved_weight`` of the weight — or after ``max_s`` — the sum collapses
to it, its covariance opened by the others' spread (moment matching about it: the σ stays
honest). Until then every row reports the best hypothesis with the covariance of the whole
sum about it.
"""
from __future__ import annotations

import math

import numpy as np

from selfnav.earth import enu_offset
from selfnav.ins.ekf import IBA, IBG, IP, IR, IV, output_covariance

_IPSI = 8            # ψ_U in the error state
_IBZ = IBG.start + 2  # the z gyro's bias


def state_difference(a, b) -> np.ndarray:
    """Error-state difference ``a − b`` of two filters of the same layout (``a`` taken as
    the estimate, ``b`` as the truth): ENU position, velocity, ``ψ`` with
    ``C_a = (I − [ψ×]) C_b`` (small angles), and every sensor and installation state."""
    dx = np.zeros(a.nx)
    sa, sb = a.ins, b.ins
    dx[IR] = enu_offset(sb.lat, sb.lon, sb.h, sa.lat, sa.lon, sa.h)
    dx[IV] = sa.velocity_n - sb.velocity_n
    A = np.eye(3) - sa.C_nb.T @ sb.C_nb
    dx[IP] = 0.5 * np.array([A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1]])
    dx[IBG] = a.bg - b.bg
    dx[IBA] = a.ba - b.ba
    lay = a.layout
    for sl, x, y in ((lay.sg, a.sg, b.sg), (lay.sa, a.sa, b.sa), (lay.mg, a.mg, b.mg),
                     (lay.ma, a.ma, b.ma), (lay.mu, a.mu, b.mu),
                     (lay.lever, a.lever_b, b.lever_b)):
        if sl is not None:
            dx[sl] = x - y
    for sl, x, y in ((lay.toff, a.time_offset, b.time_offset),
                     (lay.tdrift, a.clock_drift, b.clock_drift),
                     (lay.vlag, a.velocity_lag, b.velocity_lag),
                     (lay.odo, a.odo_scale, b.odo_scale)):
        if sl is not None:
            dx[sl.start] = x - y
    return dx


def _split_axis(P, i, split_sigma, max_hypotheses, span, *, wrap):
    """Offsets ``δ_k`` splitting state ``i`` of covariance ``P`` over ``±span`` into
    hypotheses about ``split_sigma`` wide, and their σ: ``([(δ_k, log prior weight)], σ_k)``
    (module docstring). At most ``max_hypotheses``: then spread over the span, each as wide
    as half the spacing (the gaps stay covered); ``wrap``: an angle (at most the circle)."""
    s2 = float(P[i, i])
    sig = math.sqrt(s2)
    spacing = 2.0 * split_sigma
    n_full = int(math.ceil(span / spacing))
    n = min(n_full, (max_hypotheses - 1) // 2)
    if n < n_full:
        spacing = span / (n + 0.5)
    if wrap and 2 * n * spacing > 2.0 * math.pi:
        spacing = 2.0 * math.pi / (2 * n + 1)
    if not n:
        sub = sig
    elif n < n_full:
        sub = 0.5 * spacing
    else:
        sub = min(split_sigma, 0.5 * spacing)
    deltas = np.arange(-n, n + 1) * spacing
    return [(float(d), -0.5 * d * d / max(s2 - sub * sub, 1e-12)) for d in deltas], sub


def _conditioned(flt, i, d, sub):
    """A copy of ``flt`` conditioned on "state ``i`` is off by ``d``" with σ ``sub``: the
    states correlated with it move with it (error-state convention: the correction removes
    ``dx``)."""
    P = flt.P
    s2 = float(P[i, i])
    col = P[:, i].copy()
    f = flt.copy()
    f._correct(-col * (d / s2))
    f.P = P - (1.0 - sub * sub / s2) / s2 * np.outer(col, col)
    f.P = 0.5 * (f.P + f.P.T)
    return f


class HeadingHypotheses:
    """The Gaussian sum over the heading of a start (module docstring).

    Parameters
    ----------
    flt : InsGnssFilter
        The start, its heading σ ``√P[ψ_U, ψ_U]`` wider than ``split_sigma``.
    split_sigma : float
        σ of each hypothesis' heading, rad (the EKF's linear range).
    max_hypotheses : int
        At most this many (a start with no heading at all: the whole circle).
    """

    def __init__(self, flt, *, split_sigma: float, max_hypotheses: int, prune_ratio: float,
                 resolved_weight: float, max_s: float, gate: float,
                 bias_split_sigma: float | None = None, bias_split_max: int = 1):
        # the heading first, over at most the whole circle; then, in each, the yaw-rate bias
        # (a consumer gyro's 1 °/s turns the heading out of the linear range within seconds)
        heads, sub = _split_axis(flt.P, _IPSI, split_sigma, max_hypotheses,
                                 min(3.0 * math.sqrt(float(flt.P[_IPSI, _IPSI])), math.pi),
                                 wrap=True)
        self.filters, logw, deltas, bias_deltas = [], [], [], []
        for d, lw in heads:
            fh = _conditioned(flt, _IPSI, d, sub)
            s_b = math.sqrt(max(float(fh.P[_IBZ, _IBZ]), 0.0))
            if bias_split_sigma is None or s_b <= 1.5 * bias_split_sigma:
                biases, sub_b = [(0.0, 0.0)], s_b
            else:
                biases, sub_b = _split_axis(fh.P, _IBZ, bias_split_sigma, bias_split_max,
                                            2.5 * s_b, wrap=False)
            for db, lwb in biases:
                f = _conditioned(fh, _IBZ, db, sub_b) if len(biases) > 1 else fh
                f.track_transition = flt.track_transition
                f.q_scale, f.bias_scale = flt.q_scale, flt.bias_scale
                self.filters.append(f)
                logw.append(lw + lwb)
                deltas.append(d)
                bias_deltas.append(db)
        self.logw = np.array(logw)
        self.deltas = np.array(deltas)
        self.bias_deltas = np.array(bias_deltas)
        #: evidence that is replaced, not accumulated (:meth:`set_evidence`): log-likelihood
        #: terms per hypothesis, by source
        self.evidence = {}
        self.acc = [[0.0, np.zeros(3), np.zeros(3)] for _ in self.filters]
        #: stable names of the hypotheses (a copy of the sum names them as the sum does)
        self.ids = np.arange(len(self.filters))
        self.split_sigma = sub
        self.prune_ratio = prune_ratio
        self.resolved_weight = resolved_weight
        self.max_s = max_s
        self.gate = gate
        self.t0 = flt.t_true
        self.spawned = len(self.filters)
        self._normalise()

    def join(self, f, weight: float, delta: float):
        """One more hypothesis ``f`` beside the sum, holding ``weight`` of the whole (the
        others scaled to the rest); ``delta`` its heading offset, rad, for the reports."""
        f.track_transition = self.filters[0].track_transition
        f.q_scale, f.bias_scale = self.filters[0].q_scale, self.filters[0].bias_scale
        self.filters.append(f)
        self.acc.append([0.0, np.zeros(3), np.zeros(3)])
        self.logw = np.append(self.logw + math.log1p(-weight), math.log(weight))
        self.deltas = np.append(self.deltas, delta)
        self.bias_deltas = np.append(self.bias_deltas, 0.0)
        self.ids = np.append(self.ids, int(self.ids.max()) + 1 if len(self.ids) else 0)
        self.evidence = {k: np.append(v, 0.0) for k, v in self.evidence.items()}
        self.spawned += 1
        self._normalise()

    # ------------------------------------------------------------------ bookkeeping
    def _normalise(self):
        self.logw = self.logw - np.max(self.logw)
        w = np.exp(self.logw)
        self.logw = self.logw - math.log(float(np.sum(w)))

    @property
    def weights(self) -> np.ndarray:
        return np.exp(self.logw)

    @property
    def best(self) -> int:
        return int(np.argmax(self.logw))

    def mechanize(self, t, dth, dv, dt, states: bool, best: int):
        """Every hypothesis over the IMU block; returns the best one's ``(Σ Δθ, Σ Δv)`` and,
        with ``states``, the sum's mean state at each sample (:meth:`mean_states`)."""
        out, allst = None, []
        for k, f in enumerate(self.filters):
            sth, sdv, st = f.mechanize(t, dth, dv, dt, states=states)
            a = self.acc[k]
            a[0] += float(dt.sum())
            a[1] = a[1] + sth
            a[2] = a[2] + sdv
            allst.append(st)
            if k == best:
                out = (sth, sdv)
        return out[0], out[1], (self.mean_states(allst, best) if states else None)

    def mean_states(self, allst, best: int):
        """The sum's mean ``(pos (N, 3) lat/lon/h, vel (N, 3), C_nb of the best)`` from every
        hypothesis' states: the rows follow the weights smoothly (reporting the best one
        alone jumps by metres when two hypotheses trade places)."""
        w = self.weights
        pos = sum(w[k] * st[0] for k, st in enumerate(allst))
        vel = sum(w[k] * st[1] for k, st in enumerate(allst))
        return pos, vel, allst[best][2]

    def mean_point(self):
        """``(lat, lon, h, velocity_n)`` of the sum's mean nominal state now."""
        w = self.weights
        p = sum(w[k] * np.array([f.ins.lat, f.ins.lon, f.ins.h])
                for k, f in enumerate(self.filters))
        v = sum(w[k] * f.ins.velocity_n for k, f in enumerate(self.filters))
        return p, v

    def propagate(self):
        for k, f in enumerate(self.filters):
            a = self.acc[k]
            if a[0] > 0:
                f.propagate(a[0], a[1], a[2])
            self.acc[k] = [0.0, np.zeros(3), np.zeros(3)]

    def on_fix(self, fuse, gate: float | None = None) -> list:
        """One fix (or any measurement) through every hypothesis: ``fuse(flt) -> (nis, det S,
        used)`` judges and fuses it in one filter (its normalised innovation and the
        determinant of its covariance); the weight is multiplied by the robust likelihood (the
        innovation counts at most up to ``gate``, default the fixes' 2-dof gate). Returns
        ``(nis, used)`` per hypothesis."""
        gate = self.gate if gate is None else gate
        res = []
        for k, f in enumerate(self.filters):
            nis, det, used = fuse(f)
            self.logw[k] += -0.5 * min(nis, gate) - 0.5 * math.log(max(det, 1e-300))
            res.append((nis, used))
        self._normalise()
        return res

    def set_evidence(self, key, loglik):
        """Weigh the hypotheses by ``loglik`` (one term each) *in place of* the last terms
        given under ``key``: a sensor whose error is a bias (an uncalibrated magnetometer:
        the same error at the same heading) says the same thing each time, and counted
        every time it would outweigh everything else."""
        loglik = np.asarray(loglik, dtype=float)
        self.logw = self.logw + loglik - self.evidence.get(key, 0.0)
        self.evidence[key] = loglik
        self._normalise()

    def prune(self):
        """Drop the hypotheses ``prune_ratio`` times less likely than the best."""
        keep = self.logw >= np.max(self.logw) - math.log(self.prune_ratio)
        if keep.all():
            return
        self._select(np.flatnonzero(keep))
        self._normalise()

    def _select(self, idx):
        self.filters = [self.filters[i] for i in idx]
        self.acc = [self.acc[i] for i in idx]
        self.logw = self.logw[idx]
        self.deltas = self.deltas[idx]
        self.bias_deltas = self.bias_deltas[idx]
        self.ids = self.ids[idx]
        self.evidence = {k: v[idx] for k, v in self.evidence.items()}

    def resolved(self, t) -> bool:
        """One hypothesis left, or holding ``resolved_weight``, or the others merged into it
        (:meth:`agree`), or ``max_s`` passed."""
        return (len(self.filters) == 1 or float(np.max(self.weights)) >= self.resolved_weight
                or self.agree() or t - self.t0 >= self.max_s)

    def agree(self) -> bool:
        """Have the hypotheses converged on one another? Each one's horizontal position,
        velocity and heading within the best one's 1σ ellipsoid (Mahalanobis distance ≤ 1):
        the fixes corrected every filter towards the same state, and the weights, equal
        likelihoods from then on, would never separate them."""
        k = self.best
        b = self.filters[k]
        idx = [0, 1, 3, 4, _IPSI]
        Pi = np.linalg.inv(b.P[np.ix_(idx, idx)])
        for j, f in enumerate(self.filters):
            if j != k:
                d = state_difference(f, b)[idx]
                if float(d @ Pi @ d) > 1.0:
                    return False
        return True

    # ------------------------------------------------------------------ the sum
    def spread(self, best: int) -> np.ndarray:
        """``Σ_k w_k d_k d_kᵀ`` with ``d_k`` the error-state difference of hypothesis ``k``
        from the best (the part of the sum's covariance about it the best does not carry)."""
        b = self.filters[best]
        w = self.weights
        C = np.zeros((b.nx, b.nx))
        for k, f in enumerate(self.filters):
            if k == best or w[k] < 1e-12:
                continue
            d = state_difference(f, b)
            C += w[k] * np.outer(d, d)
        return C

    def covariance_about(self, k: int) -> np.ndarray:
        """The whole sum's covariance about hypothesis ``k``: ``Σ_j w_j (P_j + d_j d_jᵀ)``,
        ``d_j`` hypothesis ``j``'s error-state difference from ``k``."""
        w = self.weights
        P = sum(w[j] * g.P for j, g in enumerate(self.filters)) + self.spread(k)
        return 0.5 * (P + P.T)

    def snapshot(self) -> "HeadingHypotheses":
        """An independent copy of the sum (every hypothesis' filter copied, the weights and
        the evidence kept), its covariances propagated to now: a fallback of the fault bank
        (:class:`selfnav.ins.hypotheses.SumFallback`)."""
        import copy as _copy

        self.propagate()
        out = _copy.copy(self)
        out.filters = []
        for f in self.filters:
            g = f.copy()            # (its noise scales come with it; not its smoother flag)
            g.track_transition = f.track_transition
            out.filters.append(g)
        out.logw = self.logw.copy()
        out.deltas = self.deltas.copy()
        out.bias_deltas = self.bias_deltas.copy()
        out.ids = self.ids.copy()
        out.evidence = {k: np.array(v, copy=True) for k, v in self.evidence.items()}
        out.acc = [[0.0, np.zeros(3), np.zeros(3)] for _ in self.filters]
        return out

    def collapse(self):
        """The best hypothesis, its covariance that of the whole sum about it."""
        k = self.best
        f = self.filters[k]
        f.P = self.covariance_about(k)
        return f

    def output_covariance(self) -> np.ndarray:
        """ENU covariance, under the whole sum, of its mean reported point: ``Σ w_k (H P_k Hᵀ
        + d_k d_kᵀ)`` with ``d_k`` hypothesis ``k``'s point from the mean."""
        w = self.weights
        pts = np.array([_output_point(f) for f in self.filters])
        m = w @ pts
        C = np.zeros((3, 3))
        for k, f in enumerate(self.filters):
            if w[k] < 1e-12:
                continue
            C += w[k] * output_covariance(f.P, f.layout, f.ins.C_nb, f.ins.velocity_n, f.lever_b)
            d = enu_offset(m[0], m[1], m[2], *pts[k])
            C += w[k] * np.outer(d, d)
        return C

    def heading_offsets_deg(self) -> list:
        return [float(np.degrees(d)) for d in self.deltas]


def _output_point(f):
    """(lat, lon, h) of a filter's reported point (the antenna when the lever arm is
    estimated)."""
    from selfnav.earth import offset_to_geodetic

    s = f.ins
    if f.layout.lever is None:
        return s.lat, s.lon, s.h
    lat, lon, h = offset_to_geodetic(s.lat, s.lon, s.h, s.C_nb.T @ f.lever_b)
    return float(lat), float(lon), float(h)


def split_heading(flt, cfg):
    """:class:`HeadingHypotheses` for ``flt`` when its heading σ is beyond the configured
    linear range (``cfg.init.heading_split_sigma``), or its yaw-rate bias σ beyond
    ``cfg.init.yaw_bias_split_sigma``, else None."""
    ini = cfg.init
    if ini.heading_split_sigma is None:
        return None
    s = math.sqrt(max(float(flt.P[_IPSI, _IPSI]), 0.0))
    s_b = math.sqrt(max(float(flt.P[_IBZ, _IBZ]), 0.0))
    wide_b = ini.yaw_bias_split_sigma is not None and s_b > 1.5 * ini.yaw_bias_split_sigma
    if s <= 1.5 * ini.heading_split_sigma and not wide_b:
        return None
    return heading_hypotheses(flt, cfg)


def heading_hypotheses(flt, cfg, *, split: bool = True):
    """:class:`HeadingHypotheses` for ``flt`` as configured; ``split=False``: ``flt`` alone,
    the first of a sum :meth:`HeadingHypotheses.join` adds others to."""
    from selfnav.ins.policy import chi2_gate

    ini = cfg.init
    return HeadingHypotheses(flt, split_sigma=ini.heading_split_sigma,
                             max_hypotheses=ini.heading_split_max if split else 1,
                             prune_ratio=ini.heading_prune_ratio,
                             resolved_weight=ini.heading_resolved_weight,
                             max_s=ini.heading_resolve_max_s,
                             gate=chi2_gate(2, cfg.integrity.p_false_alarm),
                             bias_split_sigma=ini.yaw_bias_split_sigma if split else None,
                             bias_split_max=ini.yaw_bias_split_max)


__all__ = ["HeadingHypotheses", "heading_hypotheses", "split_heading", "state_difference"]

