"""Road-constrained particle matcher driven by the INS (issue 5: beyond seed 004).

GNSS-only map matchers fail inside long outlier windows (DESIGN §7): only the inertial prediction
— travelled distance and heading against the road heading — holds the right road. This module
keeps a cloud of hypotheses (particles) *on the directed road graph*; each is a directed segment
and an offset along it. Per step:

* **predict** — every particle travels the INS distance ``ΔS`` (seed 004 (13)) with a relative
  and an absolute error; at the end of a segment it takes a successor chosen at random with a
  probability that falls with the angle between the successor's direction and the vehicle
  heading (junctions); rarely it turns round onto the opposite direction (U-turns, dead ends);
* **weigh by heading** — ``N(road heading − vehicle heading; σ_K)`` with a floor (corner arcs,
  magnetometer errors). A corner is where the along-track error is pinned: a particle that
  turns too early or too late disagrees with the heading;
* **weigh by GNSS** — only while GNSS looks healthy (:meth:`RoadParticles.gnss_health`:
  fix-to-fix steps against the travel), with a robust two-component likelihood, nominal ``σ``
  and outlier ``σ_out`` (seed 004: 10 m and 200 m) mixed with prior ``ε``: an unflagged 200 m
  fix is explained by the broad component almost equally at every particle, so it neither pulls
  the cloud along nor off the road. Each particle also carries its own INS speed error;
* **resample** (systematic) when the effective sample size drops below half;
* **re-seed** when GNSS is healthy again (fix-to-fix steps consistent with the nominal σ) and
  consistently far from the estimate: part of the cloud is re-drawn on the roads around the
  fixes (lost track, a wrong branch at start-up, a missed U-turn).

The estimate is the densest cluster (weight within ``cluster_radius``), its weighted mean snapped
onto the best particle's segment: a position on the centre line, the road heading, and a spread.

Used three ways: inside the seed 004 slow loop as its identification step (``--method seed
--matcher mht``, :mod:`selfnav.seed004`), as the ``road_aid`` of the EKF (``--method ekf
--map``, :class:`selfnav.roads.aid.EkfRoadAid`: cross-track, road-heading and corner-arc
constraints and a level-road prior), and stand-alone.

Headings are clockwise from grid North of the map's local projection; the meridian convergence
(below 0.02° over the shipped maps) is neglected.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from selfnav.roads.graph import RoadGraph

TWO_PI = 2.0 * np.pi


def wrap(a):
    """Angle to (−π, π]."""
    return (np.asarray(a) + np.pi) % TWO_PI - np.pi


def successor_table(graph: RoadGraph):
    """CSR successors of each directed segment: ``succ[off[s]:off[s+1]]`` leave ``seg_v[s]``.

    The opposite direction of the same road (the twin) is left out unless it is the only way on
    (a dead end). Returns ``(off, succ)``.
    """
    order = np.argsort(graph.seg_u, kind="stable")
    starts = np.searchsorted(graph.seg_u[order], np.arange(graph.n_nodes + 1))
    off = [0]
    succ = []
    for s in range(graph.n_segments):
        v = graph.seg_v[s]
        out = order[starts[v]:starts[v + 1]]
        keep = out[out != graph.seg_twin[s]]
        if len(keep) == 0:
            keep = out
        succ.extend(keep.tolist())
        off.append(len(succ))
    return np.asarray(off, np.int64), np.asarray(succ, np.int64)


@njit(cache=True)
def move_particles(seg, along, dist, seg_len, seg_heading, seg_twin, off, succ, heading, sig_turn,
          p_uturn, rnd_u, rnd):  # pragma: no cover - numba
    """Advance particles along the graph in place (see the module docstring)."""
    n = len(seg)
    for i in range(n):
        s = seg[i]
        if rnd_u[i] < p_uturn and seg_twin[s] >= 0:
            along[i] = seg_len[s] - along[i]
            s = seg_twin[s]
        a = along[i] + dist[i]
        if a < 0.0:
            a = 0.0
        hops = 0
        while a > seg_len[s] and hops < 50:
            a -= seg_len[s]
            k0, k1 = off[s], off[s + 1]
            if k1 == k0:
                a = seg_len[s]
                break
            tot = 0.0
            for k in range(k0, k1):
                d = seg_heading[succ[k]] - heading
                d = (d + np.pi) % (2 * np.pi) - np.pi
                tot += np.exp(-0.5 * (d / sig_turn) ** 2) + 1e-3
            r = rnd[i, hops % rnd.shape[1]] * tot
            acc = 0.0
            nxt = succ[k1 - 1]
            for k in range(k0, k1):
                d = seg_heading[succ[k]] - heading
                d = (d + np.pi) % (2 * np.pi) - np.pi
                acc += np.exp(-0.5 * (d / sig_turn) ** 2) + 1e-3
                if r <= acc:
                    nxt = succ[k]
                    break
            s = nxt
            hops += 1
        seg[i] = s
        along[i] = a


@njit(cache=True)
def densest_cells(cell, w):  # pragma: no cover - numba
    """Particles in the 3 × 3 cells around the cell whose 3 × 3 neighbourhood holds the most
    weight (the lowest such cell on ties)."""
    n = len(w)
    key = cell[:, 0] * 1_000_003 + cell[:, 1]
    order = np.argsort(key)
    ukey = np.empty(n, np.int64)
    cw = np.zeros(n)
    m = 0
    for k in range(n):
        q = key[order[k]]
        if m == 0 or ukey[m - 1] != q:
            ukey[m] = q
            m += 1
        cw[m - 1] += w[order[k]]
    ukey, cw = ukey[:m], cw[:m]
    best, j_best = -1.0, 0
    for j in range(m):
        d = 0.0
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                q = ukey[j] + dx * 1_000_003 + dy
                i = np.searchsorted(ukey, q)
                if i < m and ukey[i] == q:
                    d += cw[i]
        if d > best:
            best, j_best = d, j
    i0 = order[np.searchsorted(key[order], ukey[j_best])]
    out = np.empty(n, np.bool_)
    for j in range(n):
        out[j] = (abs(cell[i0, 0] - cell[j, 0]) <= 1 and abs(cell[i0, 1] - cell[j, 1]) <= 1)
    return out


@njit(cache=True)
def heaviest(seg, w):  # pragma: no cover - numba
    """The value of ``seg`` with the most summed weight (the smallest on ties)."""
    order = np.argsort(seg)
    best, best_w = seg[order[0]], -1.0
    k = 0
    while k < len(order):
        s, acc = seg[order[k]], 0.0
        while k < len(order) and seg[order[k]] == s:
            acc += w[order[k]]
            k += 1
        if acc > best_w:
            best, best_w = s, acc
    return int(best)


@dataclass
class MatcherConfig:
    """Noise model of :class:`RoadParticles` (SI units, radians)."""

    n: int = 400
    sigma_gnss: float = 10.0          # nominal GNSS σ per axis, m (seed 004: 10 m)
    sigma_outlier: float = 200.0      # outlier σ, m (seed 004: 200 m)
    outlier_prob: float = 0.3         # prior share of outliers in the robust likelihood
    travel_rel: float = 0.01          # relative error of the INS travel per step
    travel_abs: float = 0.3           # absolute error of the INS travel, m/√s
    speed_sigma: float = 1.0          # initial σ of each particle's INS speed error, m/s
    speed_rw: float = 0.05            # its random walk, m/s/√s
    sigma_heading: float = np.radians(20.0)
    heading_floor: float = 0.02       # likelihood floor (corner arcs, magnetometer errors)
    sigma_turn: float = np.radians(35.0)  # junction branch choice
    p_uturn: float = 2e-3             # per particle and step
    cluster_radius: float = 20.0
    seed_radius: float = 40.0         # roads within this of a fix when (re-)seeding, m
    reseed_window: int = 8            # fixes judged for re-seeding
    health_window: int = 5            # fix-to-fix steps judged for GNSS health
    reseed_far: float = 15.0          # mean fix offset from the estimate that means lost, m
    reseed_share: float = 0.5         # share of the cloud re-drawn


class RoadParticles:
    """The particle cloud on the road graph (module docstring).

    Parameters
    ----------
    graph : RoadGraph
    cfg : MatcherConfig
    seed : int, optional
        Random stream.
    """

    def __init__(self, graph: RoadGraph, cfg: MatcherConfig | None = None, seed=None):
        self.g = graph
        self.cfg = cfg or MatcherConfig()
        self.rng = np.random.default_rng(seed)
        self.off, self.succ = successor_table(graph)
        self.seg = np.zeros(0, np.int64)
        self.along = np.zeros(0)
        self.logw = np.zeros(0)
        self.dv = np.zeros(0)
        self._resid = []          # recent (fix − estimate) offsets, for re-seeding
        self._disp = np.zeros(2)  # INS displacement since the last fix (from predict), m
        self._prev_fix = None
        self._steps = []          # recent |fix step − INS displacement|, m
        self.healthy = False
        self.used_fixes = 0
        self.reseeds = 0
        self.last = None

    # ------------------------------------------------------------------ seeding
    def _draw_on_roads(self, xy, radius, n, heading=None):
        """``n`` points uniform on the parts of the roads inside the disc (weighted by the
        agreement of their direction with ``heading`` when given)."""
        g = self.g
        import shapely

        from selfnav.roads.graph import project_points_to_segments

        xy = np.asarray(xy, float)
        si = np.asarray(g.tree.query(shapely.points(xy), predicate="dwithin",
                                     distance=radius), np.int64)
        if len(si) == 0:
            si = g.candidates(np.atleast_2d(xy), radius, k=4, per_way=False).seg
            radius = float(radius) + float(np.min(g.candidates(np.atleast_2d(xy), radius, k=1,
                                                               per_way=False).dist)) + 1.0
        a, b = g.xy[g.seg_u[si]], g.xy[g.seg_v[si]]
        s0, cross, _, _ = project_points_to_segments(np.broadcast_to(xy, a.shape), a, b)
        # the unclipped foot and the half-chord of the disc along each segment
        u = (b - a) / np.maximum(g.seg_len[si], 1e-9)[:, None]
        s_foot = np.sum((xy - a) * u, axis=1)
        hc = np.sqrt(np.maximum(radius**2 - cross**2, 0.0))
        lo = np.clip(s_foot - hc, 0.0, g.seg_len[si])
        hi = np.clip(s_foot + hc, 0.0, g.seg_len[si])
        p = np.maximum(hi - lo, 1e-3)
        if heading is not None:
            dh = np.abs(wrap(g.seg_heading[si] - heading))
            p = p * (np.exp(-0.5 * (dh / np.radians(45.0)) ** 2) + 1e-3)
        k = self.rng.choice(len(si), size=n, p=p / p.sum())
        along = lo[k] + self.rng.uniform(0.0, 1.0, n) * (hi[k] - lo[k])
        return si[k].copy(), along

    def seed(self, xy, radius=None, heading=None):
        """(Re)start the cloud on the roads within ``radius`` of ``xy`` (local m)."""
        r = self.cfg.seed_radius if radius is None else radius
        self.seg, self.along = self._draw_on_roads(np.asarray(xy, float), r, self.cfg.n, heading)
        self.dv = self.cfg.speed_sigma * self.rng.normal(size=self.cfg.n)
        self.logw = np.zeros(self.cfg.n)
        self._resid = []

    @property
    def initialized(self) -> bool:
        return len(self.seg) > 0

    # ---------------------------------------------------------------- prediction
    def predict(self, ds, heading, dt=1.0):
        """Travel ``ds`` m (INS, seed (13)) over ``dt`` s with the vehicle heading ``heading``.

        Each particle also carries its own error of the INS speed (a random walk), so that a
        biased INS speed is a hypothesis the GNSS and the corners can select, not a drift.
        """
        c = self.cfg
        n = len(self.seg)
        self.dv += c.speed_rw * np.sqrt(max(dt, 0.0)) * self.rng.normal(size=n)
        moving = ds > 0.05 * dt
        dist = ds * (1.0 + c.travel_rel * self.rng.normal(size=n)) \
            + c.travel_abs * np.sqrt(max(dt, 0.0)) * self.rng.normal(size=n) \
            - (self.dv * dt if moving else 0.0)
        move_particles(self.seg, self.along, dist, self.g.seg_len, self.g.seg_heading, self.g.seg_twin,
              self.off, self.succ, float(heading), c.sigma_turn, c.p_uturn,
              self.rng.uniform(size=n), self.rng.uniform(size=(n, 4)))
        # the displacement for the GNSS health test follows the road once the cloud has an
        # estimate (the map-corrected course, seed (12)); the vehicle heading may be poor
        h_disp = heading if self.last is None or self.last["share"] < 0.8 else self.last["heading"]
        self._disp += ds * np.array([np.sin(h_disp), np.cos(h_disp)])
        # heading errors are correlated over seconds: at step dt the log-likelihood is
        # tempered by min(dt, 1 s), so a 5 Hz caller does not count one error five times
        self.weigh_heading(heading, min(max(dt, 0.0), 1.0))

    def weigh_heading(self, heading, power=1.0):
        c = self.cfg
        d = wrap(self.g.seg_heading[self.seg] - heading)
        self.logw += power * np.log(np.exp(-0.5 * (d / c.sigma_heading) ** 2) + c.heading_floor)
        self._normalize()

    # ------------------------------------------------------------------- update
    def positions(self):
        return self.g.segment_points(self.seg, self.along)

    def likelihood_gnss(self, xy, sigma=None):
        """Robust GNSS likelihood of every particle (module docstring)."""
        c = self.cfg
        s = c.sigma_gnss if sigma is None else float(sigma)
        d2 = np.sum((self.positions() - xy) ** 2, axis=1)
        nom = np.exp(-0.5 * d2 / s**2) / s**2
        out = np.exp(-0.5 * d2 / c.sigma_outlier**2) / c.sigma_outlier**2
        return (1.0 - c.outlier_prob) * nom + c.outlier_prob * out

    def gnss_health(self, xy, sigma=None) -> bool:
        """Is GNSS healthy? Fix-to-fix steps minus the INS displacement over the last
        ``health_window`` fixes: median below 1.5·√2·σ·1.18 (the Rayleigh median) and the
        newest below 3·√2·σ. White 200 m outliers and drifting ones (tens of metres per
        second) fail it; nominal fixes pass about 95 % of the time."""
        c = self.cfg
        s = c.sigma_gnss if sigma is None else float(sigma)
        if self._prev_fix is not None:
            self._steps.append(float(np.hypot(*(xy - self._prev_fix - self._disp))))
            self._steps = self._steps[-c.health_window:]
        self._prev_fix = np.array(xy, float)
        self._disp = np.zeros(2)
        if len(self._steps) < c.health_window:
            return False
        r = np.sqrt(2.0) * s
        return bool(np.median(self._steps) < 1.5 * 1.18 * r and self._steps[-1] < 3.0 * r)

    def reset_health(self, healthy_history: bool = False):
        """Start the GNSS health test again (after a fix that must not count): with
        ``healthy_history`` the window is pre-filled with nominal steps (a start that follows
        a run of fixes already judged healthy), else the next ``health_window`` fixes decide."""
        self._prev_fix = None
        self._steps = [0.0] * (self.cfg.health_window - 1) if healthy_history else []
        self.healthy = False

    def update_gnss(self, xy, sigma=None):
        """Weigh by one GNSS fix (local m) when GNSS is healthy (:meth:`gnss_health`, the
        robust likelihood then guards the rest); re-seed when lost (module docstring).
        Returns whether the fix was used."""
        xy = np.asarray(xy, float)
        self.healthy = self.gnss_health(xy, sigma)
        if not self.healthy:
            self._resid = []
            return False
        self.weigh_gnss(xy, sigma)
        return True

    def weigh_gnss(self, xy, sigma=None):
        """Weigh by a fix already judged healthy (robust likelihood), re-seed if lost,
        resample."""
        xy = np.asarray(xy, float)
        self._disp = np.zeros(2)
        self.logw += np.log(self.likelihood_gnss(xy, sigma) + 1e-300)
        self._normalize()
        self._maybe_reseed(xy, sigma)
        self._maybe_resample()
        self.used_fixes += 1

    def _normalize(self):
        self.logw -= self.logw.max()

    def weights(self):
        w = np.exp(self.logw - self.logw.max())
        return w / w.sum()

    def _maybe_resample(self):
        w = self.weights()
        if 1.0 / np.sum(w * w) < 0.5 * len(w):
            n = len(w)
            u = (self.rng.uniform() + np.arange(n)) / n
            idx = np.minimum(np.searchsorted(np.cumsum(w), u), n - 1)
            self.seg, self.along = self.seg[idx].copy(), self.along[idx].copy()
            self.dv = self.dv[idx].copy()
            self.logw = np.zeros(n)

    def _maybe_reseed(self, xy, sigma):
        c = self.cfg
        s = c.sigma_gnss if sigma is None else float(sigma)
        est = self.estimate()
        self._resid.append(xy - est["xy"])
        self._resid = self._resid[-c.reseed_window:]
        if len(self._resid) < c.reseed_window:
            return
        r = np.asarray(self._resid)
        step = np.hypot(*np.diff(r, axis=0).T)
        healthy = np.median(step) < 1.8 * s * np.sqrt(2.0) and np.max(step) < 5.0 * s
        far = np.hypot(*r.mean(axis=0)) > max(c.reseed_far, 1.5 * s)
        if healthy and far:
            n = len(self.seg)
            k = int(c.reseed_share * n)
            idx = self.rng.choice(n, size=k, replace=False)
            seg, along = self._draw_on_roads(xy, max(c.seed_radius, 3.0 * s), k,
                                             est["heading"])
            self.seg[idx], self.along[idx] = seg, along
            self.dv[idx] = c.speed_sigma * self.rng.normal(size=k)
            self.logw[idx] = np.median(self.logw)
            # the new draws are then judged by the next fixes like every other particle
            self._resid = []
            self.reseeds += 1

    # ----------------------------------------------------------------- estimate
    def estimate(self) -> dict:
        """The densest cluster: position on the road, segment, road heading, spread, share."""
        c = self.cfg
        w = self.weights()
        p = self.positions()
        # density of weight on a grid of cluster_radius cells, summed over 3 × 3 neighbours
        R = c.cluster_radius
        cell = np.floor(p / R).astype(np.int64)
        near = densest_cells(cell, w)
        centre_xy = (w[near] @ p[near]) / w[near].sum()
        m = np.sum((p - centre_xy) ** 2, axis=1) < R**2
        if not m.any():
            m = near
        wm = w[m] / w[m].sum()
        mean = wm @ p[m]
        # snap onto the best segment among the cluster's (the most weight; the lowest index
        # among equals)
        best = heaviest(self.seg[m], wm)
        a = self.g.xy[self.g.seg_u[best]]
        u = self.g.xy[self.g.seg_v[best]] - a
        L = max(self.g.seg_len[best], 1e-9)
        along = float(np.clip((mean - a) @ u / L, 0.0, L))
        foot = a + u / L * along
        spread = float(np.sqrt(wm @ np.sum((p[m] - mean) ** 2, axis=1)))
        self.last = {"xy": foot, "seg": best, "along": along,
                     "heading": float(self.g.seg_heading[best]), "spread": spread,
                     "share": float(w[m].sum())}
        return self.last

