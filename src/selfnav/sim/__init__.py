"""Trajectories and exact sensor data (issue 3): static, multi-position, ship, aircraft, car.

Simulated data is always labelled as such in the files it writes.
"""
