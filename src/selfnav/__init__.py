"""selfnav: navigation that does not trust, or does not have, satellite signals.

Conventions (DESIGN §2), everywhere in the package:

* **Units**: SI and radians inside; degrees only at the edges, and every such name says so
  (``lat_deg``, ``heading_deg``).
* **Frames**: navigation frame ENU (East, North, Up); body frame RFU (Right, Forward, Up).
  ``C_nb`` rotates navigation-frame vectors into the body frame (``v_b = C_nb @ v_n``); its
  second row is the forward axis in ENU. Names carry their frames (``velocity_n``,
  ``omega_ib_b``, ``f_ib_b``).
* **IMU rows** hold the mean rate and specific force over the interval *ending* at ``t``.
* **Time**: float64 seconds, strictly increasing, one time base per run.

The Python API (each also a ``selfnav`` command):

>>> import selfnav
>>> imu = selfnav.read_imu("imu.csv")                      # doctest: +SKIP
>>> gnss = selfnav.read_gnss("gnss.csv")                   # doctest: +SKIP
>>> sol = selfnav.navigate(imu, gnss, roads=None)          # doctest: +SKIP
>>> sol.to_csv("sol.csv")                                  # doctest: +SKIP
>>> selfnav.evaluate("truth.csv", sol)["horizontal_rms_m"] # doctest: +SKIP

``Navigator`` is the real-time INS/GNSS(/map) navigator (``add_imu``, ``add_fix``: causal;
``navigate`` is the batch loop over it); ``read_imu, read_gnss, read_roads, read_solution,
read_attitude`` read files;
``estimate_latitude`` (seed 000), ``navigate_moving`` and ``MovingBaseNavigator`` (seeds
002/003), ``navigate`` (EKF or seed 004, with or without roads), ``match`` (GNSS-only map
matching; ``read_fleet``, ``match_fleet`` and ``match_files`` for fleets of tracks) and
``evaluate`` run the methods; ``estimate_attitude`` (an AHRS, :class:`Ahrs`) and
``compare_attitude`` give attitude from gyros, accelerometers and a magnetometer; ``simulate`` makes data with known truth.
"""

__version__ = "0.2.0"

# The API is loaded on first use (PEP 562), so that ``import selfnav`` and the command line start
# fast; ``from selfnav import navigate`` works as usual.
_API = {
    "read_imu": "selfnav.api", "read_imu_positions": "selfnav.api", "read_gnss": "selfnav.api",
    "read_roads": "selfnav.api", "read_solution": "selfnav.api", "read_attitude": "selfnav.api",
    "estimate_latitude": "selfnav.api", "navigate": "selfnav.api", "match": "selfnav.api",
    "match_fleet": "selfnav.api", "match_files": "selfnav.api", "read_fleet": "selfnav.api",
    "evaluate": "selfnav.api", "filter_config": "selfnav.api", "Solution": "selfnav.api",
    "allan_noise": "selfnav.api", "latitude_requirements": "selfnav.api",
    "latitude_error_budget": "selfnav.api", "evaluate_report": "selfnav.api",
    "map_coverage": "selfnav.api", "check_map_covers": "selfnav.api", "imu_gaps": "selfnav.api",
    "simulate_files": "selfnav.api", "run_montecarlo": "selfnav.api",
    "read_baro": "selfnav.api", "estimate_attitude": "selfnav.api",
    "compare_attitude": "selfnav.api", "read_reference_attitude": "selfnav.api",
    "Ahrs": "selfnav.ins.ahrs",
    "Navigator": "selfnav.ins.navigator", "NavState": "selfnav.ins.navigator",
    "FixDecision": "selfnav.ins.policy", "FixStatus": "selfnav.ins.policy",
    "NavStatus": "selfnav.ins.policy",
    "simulate": "selfnav.sim.scenarios", "MovingBaseNavigator": "selfnav.moving",
    "navigate_moving": "selfnav.moving_driver",
    "ImuData": "selfnav.types", "GnssData": "selfnav.types", "Trajectory": "selfnav.types",
    "AttitudeData": "selfnav.types",
    "spp": "selfnav.api", "read_gnss_raw": "selfnav.api",
}

__all__ = ["__version__", *_API]


def __getattr__(name):
    if name in _API:
        import importlib

        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'selfnav' has no attribute '{name}'")


def __dir__():
    return sorted(set(globals()) | set(_API))
