"""selfnav: navigation that does not trust, or does not have, satellite signals.

Modules follow DESIGN.md: ``earth`` and ``attitude`` (§2), ``latitude`` (§3, seed 000),
``io`` (§6) and the command line in ``selfnav.cli``.
"""
__version__ = "0.1.0"
