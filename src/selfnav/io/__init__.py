"""Readers and writers: the native CSV schema of DESIGN §6 and real formats (PSINS, RTKLIB,
NMEA, KF-GINS, rtklibexplorer, smartLoc).

Every reader validates what it loads and raises :class:`selfnav.errors.InputError` with the file,
line or column and the likely cause. Time is float64 seconds, strictly increasing. Readers build
the containers of :mod:`selfnav.types` and never import an algorithm.
"""
