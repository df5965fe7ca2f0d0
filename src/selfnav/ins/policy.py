"""The navigator's one vocabulary: what it did with each fix, what state it is in, and the
gates those decisions use (DESIGN §9; issue 18).

Every place that reports a fix decision — the solution rows, ``--fix-log``, the JSON summary,
the statistics and the command line — uses :class:`FixStatus`; every row and
:class:`~selfnav.ins.navigator.NavState` uses :class:`NavStatus`. The gates are quantiles
of χ² at a false-alarm probability the configuration states
(:class:`selfnav.ins.config.Integrity`), not literals.
"""
from __future__ import annotations

import enum
import functools
from dataclasses import dataclass

from selfnav.quantiles import chi2_isf, norm_isf


class FixStatus(str, enum.Enum):
    """What the navigator did with a GNSS fix."""

    #: fused with its σ (position, and velocity where the fix has one and it agreed)
    USED = "used"
    #: fused in part (horizontal or height only) or with its σ inflated (a poor-quality fix)
    DEGRADED = "degraded"
    #: not fused: inconsistent with the navigator (an outlier at the gate)
    REJECTED = "rejected"
    #: not fused: within the gate, but a fault episode is open and the run of fixes it belongs
    #: to has not yet shown that the GNSS is healthy again
    SUSPECT = "suspect"
    #: not fused: the navigator is still aligning (the fix went to the start-up stage)
    ALIGNING = "aligning"
    #: waiting for the IMU to reach the fix's time (its decision comes with a later NavState)
    PENDING = "pending"

    def __str__(self) -> str:     # the CSV / JSON spelling
        return self.value

    @property
    def fused(self) -> bool:
        return self in (FixStatus.USED, FixStatus.DEGRADED)


class NavStatus(str, enum.Enum):
    """The navigator's state at an output row."""

    #: not started: buffering IMU samples and fixes for the start-up (no position yet)
    ALIGNING = "aligning"
    #: a fix was fused within the hold time
    GNSS = "gnss"
    #: no fix fused within the hold time (an outage, or fixes rejected one by one)
    DEAD_RECKONING = "dead-reckoning"
    #: a fault episode is open: the fixes and the inertial solution disagree
    SUSPECT = "suspect"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class FixDecision:
    """The navigator's decision on one fix (returned by ``Navigator.add_fix``).

    Attributes
    ----------
    t : float
        The fix's time, s.
    status : FixStatus
    reason : str
        Why, in words (empty when used as is).
    nis : float
        Normalised innovation squared of the horizontal position against the navigator (NaN
        when not tested).
    """

    t: float
    status: FixStatus
    reason: str = ""
    nis: float = float("nan")

    @property
    def fused(self) -> bool:
        return self.status.fused


@functools.lru_cache(maxsize=256)
def chi2_gate(dof: int, p_false_alarm: float) -> float:
    """The χ²(dof) quantile a consistent measurement exceeds with probability
    ``p_false_alarm``."""
    return float(chi2_isf(p_false_alarm, dof))


@functools.lru_cache(maxsize=64)
def normal_quantile(p: float) -> float:
    """The two-sided normal factor: ``P(|x| > k σ) = p``."""
    return float(norm_isf(0.5 * p))


__all__ = ["FixStatus", "NavStatus", "FixDecision", "chi2_gate", "normal_quantile"]
