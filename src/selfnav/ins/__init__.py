"""The inertial navigator, one stage a module (DESIGN §5, §7, §9)::

    strapdown → ekf + measurements → startup → hypotheses (+ policy) → navigator
    (mechanization,  (error-state     (causal     (the fault bank:       (the causal loop:
     seed 004 fast    filter, RTS,     start)      references, episodes,  Navigator.add_imu,
     loop)            the aids)                    protection level)      add_fix, rows)

with :mod:`selfnav.ins.config` holding the grouped configuration every stage reads and
:mod:`selfnav.ins.calibrate` the noise and timing from the data. Each module imports only those
to its left (and ``config``).
"""
from selfnav.ins.config import FilterConfig, navigator_config
from selfnav.ins.ekf import InsGnssFilter
from selfnav.ins.navigator import DEFAULT_OUT_RATE_HZ, NavigatorResult, Navigator, NavState, feed
from selfnav.ins.policy import FixDecision, FixStatus, NavStatus

__all__ = ["FilterConfig", "navigator_config", "InsGnssFilter", "Navigator", "NavState",
           "NavigatorResult", "FixDecision", "FixStatus", "NavStatus", "DEFAULT_OUT_RATE_HZ", "feed"]
