"""Readers and writers: the native CSV schema of DESIGN §6 and real formats (PSINS, ...).

Every reader validates what it loads and raises :class:`selfnav.errors.InputError` with the file,
line or column and the likely cause. Time is float64 seconds, strictly increasing.
"""
from selfnav.io.csvio import read_table, write_csv
from selfnav.io.imu import ImuData, read_imu, read_imu_positions
from selfnav.io.psins import read_psins_imu

__all__ = ["read_table", "write_csv", "ImuData", "read_imu", "read_imu_positions", "read_psins_imu"]
