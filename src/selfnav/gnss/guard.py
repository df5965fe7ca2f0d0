"""Never worse than the odometry alone: a bank of drift hypotheses against GNSS errors that
every satellite shares (a spoofer's drag, a geometry-consistent drift), for the tightly coupled
filter (:mod:`selfnav.gnss.tight`; issue 23: "the per-satellite path must join the
fault-hypothesis bank" — the IMU navigator's bank is issue 19's).

A drift that moves every pseudorange as a moved receiver would is invisible to any per-satellite
test: the mixture finds nothing delayed and the filter follows. What tells it apart is the
odometry: a drift is fixed in the East–North frame, while the odometry's own errors (heading,
scale) turn with the car. Every ``every`` seconds the guard starts a **drift branch**: a copy of
the filter whose pseudoranges are computed at ``p + d``, with a common offset ``d`` (zero at the
branch's start) growing at a rate ``ḋ`` (prior σ ``drift_sigma``, random walk ``drift_rw``)::

    ρ_i = |r_i − (p + d)| + …,      ḋ̇ = w                                                   (1)

Both the filter (hypothesis "no drift") and the branches run every update; a branch keeps the
sum of its epochs' log-likelihoods minus the filter's, divided by the variance inflation of
errors correlated over epochs (the likelihoods treat them as independent)::

    Λ = Σ (ℓ_branch − ℓ_filter) / inflation  >  gate                                       (2)

(a generalised likelihood ratio with 2 extra parameters; the gate is far in the χ²₂ tail).
Then the guard **holds** that branch: the output is its ``p`` — the odometry's track, shaped by
the satellites but not placed by them — while the filter runs on. The hold ends when the held
branch's drift ``(d, ḋ)`` is back to zero within its σ (χ²₄ 0.95) for ``resume_after`` seconds.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class GuardConfig:
    every: float = 15.0              # s between branches
    span: float = 150.0              # s a branch is tried
    min_age: float = 20.0            # s before a branch may win
    gate: float = 15.0               # (2), log-likelihood units
    drift_sigma: float = 1.0         # m/s, prior σ of the drift rate
    drift_rw: float = 0.01           # m/s/√s
    resume_gate: float = 9.49        # χ²₄ 0.95 of (d, ḋ) = 0
    resume_after: float = 10.0       # s


class DriftGuard:
    """The drift branches and the hold of the module docstring. ``step(t, steps, filt, obs,
    mixture, inflation)`` after the filter's epoch returns what to output (``filt`` or the held
    branch)."""

    def __init__(self, cfg: GuardConfig | None = None):
        self.cfg = cfg or GuardConfig()
        self.branches = []            # [born, filter, Λ]
        self.held = None
        self.next_spawn = None
        self.quiet_since = None
        self.episodes = []            # {"start_s", "end_s", "branch_s", "llr"}
        self.max_llr = 0.0            # the largest Λ any branch reached (a margin to the gate)

    def _advance(self, b, steps, obs, mixture, inflation):
        for v, w, dt in steps:
            b.predict(v, w, dt)
        b.update(*obs, mixture, inflation=inflation)
        return b.log_likelihood

    def step(self, t, steps, filt, obs, mixture, inflation):
        cfg = self.cfg
        keep = []
        for br in self.branches:
            if t - br[0] > cfg.span:
                continue
            br[2] += (self._advance(br[1], steps, obs, mixture, inflation)
                      - filt.log_likelihood) / max(inflation, 1.0)
            keep.append(br)
            if t - br[0] >= cfg.min_age:
                self.max_llr = max(self.max_llr, br[2])
        self.branches = keep
        if self.held is None:
            win = [br for br in self.branches if t - br[0] >= cfg.min_age and br[2] > cfg.gate]
            if win:
                born, b, llr = max(win, key=lambda br: br[2])
                self.held = b
                self.quiet_since = None
                self.episodes.append({"start_s": float(t), "end_s": None,
                                      "branch_s": float(born), "llr": float(llr)})
                self.branches = []
        else:
            self._advance(self.held, steps, obs, mixture, inflation)
            nd = self.held.nd
            d = self.held.x[nd:nd + 4]
            S = self.held.P_report[nd:nd + 4, nd:nd + 4]
            if float(d @ np.linalg.solve(S, d)) <= cfg.resume_gate:
                self.quiet_since = t if self.quiet_since is None else self.quiet_since
                if t - self.quiet_since >= cfg.resume_after:
                    self.episodes[-1]["end_s"] = float(t)
                    self.held = None
                    self.next_spawn = t
            else:
                self.quiet_since = None
        if self.held is None and (self.next_spawn is None or t >= self.next_spawn):
            self.branches.append([t, filt.branch(cfg.drift_sigma), 0.0])
            self.next_spawn = t + cfg.every
        return filt if self.held is None else self.held
