"""The EKF's road aid (issue 5, ``--method ekf --map``): :class:`EkfRoadAid`.

A :class:`~selfnav.roads.particles.RoadParticles` cloud driven by the INS tells which road line the
vehicle is on; this class turns it into constraints for
:meth:`selfnav.ins.ekf.InsGnssFilter.update_road` — cross-track and road heading on straight roads,
the driven arc through corners — and a level-road prior. docs/navigator.md has the
measurements.
"""
from __future__ import annotations

import numpy as np

from selfnav.roads.particles import TWO_PI, MatcherConfig, RoadParticles, wrap
from selfnav.roads.graph import RoadGraph


def _heading_of(C_nb):
    """True heading (rad, clockwise from North) of the forward axis of ``C_nb`` (DESIGN §2)."""
    fwd = C_nb[1]
    return float(np.arctan2(fwd[0], fwd[1]) % TWO_PI)


class EkfRoadAid:
    """``road_aid`` for :func:`selfnav.ins.run_filter` (``--method ekf --map``).

    At every aiding epoch the cloud travels the INS distance with the INS heading and takes the
    GNSS fixes that have arrived. Once per ``interval`` it returns a constraint for
    :meth:`InsGnssFilter.update_road` when the cloud is confident about the *line* the vehicle
    is on (≥ 0.8 of the weight within 2 m of it, heading within 20°: its spread *along* a
    straight road does not matter, a parallel road or another leg does) and the filter agrees
    across that line within ``max(agree_m, 3σ)`` (else one of the two is on another road):

    * on a straight road, cross-track and road heading;
    * within ``bend_zone`` m of a vertex turning > 20°: against the leg the INS heading matches
      while not turning; while turning, against **the arc** a car drives through the corner —
      the circle tangent to both legs with the radius being driven, ``R = v/ω`` (INS speed over
      the bias-corrected yaw rate, median over the turn after its first 0.4 s), normal towards
      the centre, within ``max(arc_agree_m, 2σ)``. The normal sweeps through the turn: a corner
      pins the along-track position too.

    ``grade_sigma`` adds a level-road prior ``v_U = 0`` (σ ``grade_sigma·|v| + 0.1`` m/s, once
    per ``interval``): the map has no heights, and without it the filter's pitch error, hardly
    observable from the NHC and σ 15 m GNSS heights, leaked gravity into the speed (1–2 m/s for
    tens of seconds on the simulated drives). σ 0.08 admits ordinary grades (8 %: 0.8 m/s at
    30 km/h); the simulated roads are level. ``None`` switches it off. docs/navigator.md has the
    measurements.

    Parameters
    ----------
    graph : RoadGraph
    gnss : GnssData (WGS-84)
    cfg : MatcherConfig
    sigma_cross : σ of the cross-track constraint, m (lane position and digitising error)
    sigma_arc : σ of the arc constraint, m (the radius estimate, the driver's line)
    sigma_heading : σ of the road-heading constraint, rad (None: no heading constraint)
    interval : s between constraints (the cloud's errors are correlated over seconds)
    agree_m, arc_agree_m : floors of the agreement tests, m
    bend_zone : distance from a bend's vertex within which the corner logic applies, m
    grade_sigma : σ of the road grade (level-road prior; None: off)
    seed : random stream
    """

    def __init__(self, graph: RoadGraph, gnss, cfg: MatcherConfig | None = None, *,
                 sigma_cross=1.0, sigma_arc=1.0, sigma_heading=np.radians(5.0), interval=1.0,
                 agree_m=10.0, arc_agree_m=4.0, bend_zone=25.0, grade_sigma=0.08, seed=0):
        self.g = graph
        self.pf = RoadParticles(graph, cfg, seed)
        x, y = graph.to_local(gnss.lat, gnss.lon)
        self.fix_t = np.asarray(gnss.t, float)
        self.fix_xy = np.column_stack([x, y])
        self.sig = (np.asarray(gnss.sigma_m, float) if gnss.sigma_m is not None
                    else np.full(len(gnss.t), self.pf.cfg.sigma_gnss))
        self.k = 0
        self.t_last = None
        self.sigma_cross = sigma_cross
        self.sigma_arc = sigma_arc
        self.sigma_heading = sigma_heading
        self.interval = interval
        self.agree_m = agree_m
        self.arc_agree_m = arc_agree_m
        self.bend_zone = bend_zone
        self.grade_sigma = grade_sigma
        self.t_grade = -np.inf
        self.t_constraint = -np.inf
        self.hdg_last = None
        self.rates = []        # recent (t, yaw rate)
        self.radii = []        # v/ω of the current turn
        self.seg_prev = -1     # the estimate's previous segment (the leg before a vertex)
        self.seg_cur = -1
        self.history = []      # (t, x, y, seg, spread, line share)
        self.corner = self._corner_nodes()
        self.counts = {"line": 0, "leg": 0, "arc": 0, "grade": 0}

    def _corner_nodes(self):
        """Per segment: does it end (start) in a bend of more than 20° on some way on?"""
        g, off, succ = self.g, self.pf.off, self.pf.succ
        src = np.repeat(np.arange(g.n_segments), np.diff(off))
        bend = np.abs(wrap(g.seg_heading[succ] - g.seg_heading[src])) > np.radians(20.0)
        end_bend = np.zeros(g.n_segments, bool)
        end_bend[src[bend]] = True
        start_bend = np.zeros(g.n_segments, bool)
        start_bend[succ[end_bend[src]]] = True
        return end_bend, start_bend

    # ------------------------------------------------------------------ geometry
    def _line(self, s):
        """Start point, direction and right normal of directed segment ``s``."""
        h = float(self.g.seg_heading[s])
        d = np.array([np.sin(h), np.cos(h)])
        return self.g.xy[self.g.seg_u[s]], d, np.array([d[1], -d[0]])

    def _line_weight(self, segs, w, pos):
        """Weight of the particles within 2 m of the line of any of ``segs`` and heading
        within 20° of it."""
        on = np.zeros(len(w), bool)
        for s in segs:
            a, _, n = self._line(s)
            on |= ((np.abs((pos - a) @ n) < 2.0)
                   & (np.abs(wrap(self.g.seg_heading[self.pf.seg] - self.g.seg_heading[s]))
                      < np.radians(20.0)))
        return float(w[on].sum())

    def _legs(self, est, turn_sign):
        """The corner the vehicle is at: ``(s_in, s_out)`` or None (module docstring)."""
        g, pf = self.g, self.pf
        s, L, al = est["seg"], g.seg_len[est["seg"]], est["along"]
        end_bend, start_bend = self.corner
        if end_bend[s] and L - al < self.bend_zone and (al >= L / 2 or not start_bend[s]):
            nxt = pf.succ[pf.off[s]:pf.off[s + 1]]
            turn = wrap(g.seg_heading[nxt] - g.seg_heading[s])
            ok = np.abs(turn) > np.radians(20.0)
            if turn_sign != 0:
                ok &= np.sign(turn) == turn_sign
            cand = nxt[ok]
            if len(cand) == 0:
                return None
            if len(cand) > 1:      # the branch the cloud's particles took
                w = pf.weights()
                cand = cand[[int(np.argmax([w[pf.seg == q].sum() for q in cand]))]]
            return int(s), int(cand[0])
        if start_bend[s] and al < self.bend_zone and self.seg_prev >= 0:
            q = self.seg_prev
            if (s in pf.succ[pf.off[q]:pf.off[q + 1]]
                    and abs(float(wrap(g.seg_heading[s] - g.seg_heading[q]))) > np.radians(20)):
                return int(q), int(s)
        return None

    def _arc(self, s_in, s_out, p, R):
        """Circle tangent to both legs with radius ``R``: ``(normal, offset)`` of ``p`` or
        None when ``p`` is not beside the arc."""
        g = self.g
        V = g.xy[g.seg_v[s_in]]
        _, d1, _ = self._line(s_in)
        _, d2, _ = self._line(s_out)
        th = float(wrap(g.seg_heading[s_out] - g.seg_heading[s_in]))
        b = d2 - d1
        b /= np.linalg.norm(b)
        C = V + b * R / np.cos(th / 2.0)
        u = p - C
        rho = float(np.linalg.norm(u))
        if rho < 1e-6:
            return None
        u /= rho
        # beside the arc: between the radii to the two tangent points (with 15° margin)
        t1 = V - d1 * R * np.tan(abs(th) / 2.0) - C
        t2 = V + d2 * R * np.tan(abs(th) / 2.0) - C
        a1 = np.arctan2(t1[0], t1[1])
        a2 = np.arctan2(t2[0], t2[1])
        a = np.arctan2(u[0], u[1])
        span = float(wrap(a2 - a1))
        pos = float(wrap(a - a1))
        m = np.radians(15.0)
        if not (min(0.0, span) - m <= pos <= max(0.0, span) + m):
            return None
        return u, rho - R

    # --------------------------------------------------------------------- call
    def _yaw_rate(self, flt, hdg, dt):
        """Yaw rate, rad/s clockwise: the filter's last propagation block (bias-corrected
        gyros); else heading differences (which also carry the filter's corrections)."""
        if hasattr(flt, "_w_b"):
            return -float((flt.ins.C_nb.T @ flt._w_b)[2])
        if self.hdg_last is None:
            return 0.0
        return float(wrap(hdg - self.hdg_last)) / max(dt, 1e-3)

    def _grade_prior(self, t, flt, v):
        """Level-road prior on the vertical velocity (class docstring)."""
        if self.grade_sigma is None or t - self.t_grade < self.interval - 1e-9:
            return
        self.t_grade = t
        H = np.zeros((1, flt.nx))
        H[0, 5] = 1.0
        s_v = self.grade_sigma * float(np.hypot(v[0], v[1])) + 0.1
        flt.kalman(np.array([float(v[2])]), H, np.array([[s_v * s_v]]))
        self.counts["grade"] += 1

    def __call__(self, t, flt):
        ins, pf = flt.ins, self.pf
        x, y = self.g.to_local(ins.lat, ins.lon)
        p_ins = np.array([float(x), float(y)])
        hdg = _heading_of(ins.C_nb)
        if not pf.initialized:
            pf.seed(p_ins, max(pf.cfg.seed_radius, 3.0 * float(np.sqrt(flt.P[0, 0] + flt.P[1, 1]))),
                    heading=hdg)
            self.t_last = t
            # the fixes before the start are behind it (taken at once they dragged the cloud
            # 1 km off, seen); the start follows a run of healthy fixes (robust_init)
            self.k = int(np.searchsorted(self.fix_t, t - 1.0, side="right"))
            pf._steps = [0.0] * (pf.cfg.health_window - 1)
        v = ins.velocity_n
        dt = t - self.t_last
        speed = float(np.hypot(v[0], v[1]))
        self.t_last = t
        rate = self._yaw_rate(flt, hdg, dt)
        self.hdg_last = hdg
        self.rates = [r for r in self.rates if r[0] > t - 0.6 - 1e-9] + [(t, rate)]
        w_rate = float(np.mean([r[1] for r in self.rates]))          # over the last 0.6 s
        turning = abs(w_rate) > np.radians(3.0)
        if turning and speed > 1.0 and abs(rate) > np.radians(1.0):
            self.radii.append(speed / abs(rate))
        elif not turning:
            self.radii = []
        pf.predict(speed * dt, hdg, dt)
        while self.k < len(self.fix_t) and self.fix_t[self.k] <= t:
            pf.update_gnss(self.fix_xy[self.k], self.sig[self.k])
            self.k += 1
        est = pf.estimate()
        if est["seg"] != self.seg_cur:
            self.seg_prev, self.seg_cur = self.seg_cur, est["seg"]
        self._grade_prior(t, flt, v)
        w, pos = pf.weights(), pf.positions()
        share = self._line_weight([est["seg"]], w, pos)
        legs = self._legs(est, int(np.sign(w_rate)) if turning else 0)
        if legs is not None:
            share = max(share, self._line_weight(legs, w, pos))
        self.history.append((t, *est["xy"], est["seg"], est["spread"], share))
        # the cloud's error is correlated over seconds: one constraint per ``interval``
        if share < 0.8 or t - self.t_constraint < self.interval - 1e-9:
            return None
        out = None
        P2 = flt.P[0:2, 0:2]
        if legs is None and not turning:
            a0, _, nrm = self._line(est["seg"])
            out = {"normal_n": nrm, "offset": float((p_ins - a0) @ nrm), "kind": "line",
                   "heading": float(self.g.seg_heading[est["seg"]])}
        elif legs is not None and not turning:
            # on one of the straight legs of a corner: the one the INS heading matches
            dh = [abs(float(wrap(self.g.seg_heading[q] - hdg))) for q in legs]
            q = legs[int(np.argmin(dh))]
            if min(dh) < max(np.radians(8.0), 3.0 * float(np.sqrt(max(flt.P[8, 8], 0.0)))):
                a0, _, nrm = self._line(q)
                out = {"normal_n": nrm, "offset": float((p_ins - a0) @ nrm), "kind": "leg",
                       "heading": float(self.g.seg_heading[q])}
        elif legs is not None:
            rr = np.asarray(self.radii[2:])          # the first 0.4 s is the turn's entry
            if len(rr) >= 3 and np.subtract(*np.percentile(rr, [75, 25])) < 0.3 * np.median(rr):
                arc = self._arc(*legs, p_ins, float(np.median(rr)))
                if arc is not None:
                    sig_a = float(np.sqrt(max(arc[0] @ P2 @ arc[0], 0.0)))
                    if abs(arc[1]) < max(self.arc_agree_m, 2.0 * sig_a):
                        out = {"normal_n": arc[0], "offset": arc[1], "kind": "arc"}
        if out is None:
            return None
        # the cloud and the filter disagree by more than the filter's own uncertainty allows:
        # one of them is on another road; constraining the filter then would make it two
        n = out["normal_n"]
        if abs(out["offset"]) > max(self.agree_m, 3.0 * float(np.sqrt(max(n @ P2 @ n, 0.0)))):
            return None
        self.t_constraint = t
        kind = out.pop("kind")
        self.counts[kind] += 1
        if kind == "arc":
            out["sigma"] = self.sigma_arc
            return out
        out["sigma"] = self.sigma_cross
        if self.sigma_heading is None:
            del out["heading"]
        else:
            out["sigma_heading"] = self.sigma_heading
        return out
