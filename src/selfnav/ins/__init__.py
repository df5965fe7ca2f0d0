"""The inertial navigator, one stage a module (DESIGN §5, §7, §9)::

    strapdown  →  align  →  ekf  →  guard  →  navigator
    (mechanization, (initial   (error-state  (outlier defence:  (streaming and batch runs,
     seed 004 fast   state)     filter, RTS   window test,       fix bookkeeping)
     loop)                      smoother)     shadow DR)

with :mod:`selfnav.ins.config` holding the grouped configuration every stage reads. Each module
imports only those to its left (and ``config``).
"""
from selfnav.ins.config import FilterConfig
from selfnav.ins.ekf import InsGnssFilter
from selfnav.ins.navigator import (FilterResult, StreamingNavigator, concatenate_results,
                                  fixes_sigma,
                                  init_from_gnss, output_trajectory, run_filter)

__all__ = ["FilterConfig", "InsGnssFilter", "FilterResult", "StreamingNavigator",
           "init_from_gnss", "run_filter", "output_trajectory", "fixes_sigma",
           "concatenate_results"]
