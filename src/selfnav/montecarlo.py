"""Seeded Monte Carlo campaigns on Dask (DESIGN §1 item 4, §3 "show in a Monte Carlo...").

A campaign runs one registered **(scenario, method) pair** N times. Each run is a pure function
``run(seed, params) -> dict`` of an integer seed and a parameter dictionary: it simulates the
scenario with that seed, runs the method and returns flat scalars, among them

``error``
    the method's error in the pair's unit (estimate minus truth),
``sigma``
    the method's own predicted 1σ for that run, same unit,

and optionally ``bound`` (an analytic standard deviation, e.g. the Cramér–Rao bound). The
summary compares the scatter of the errors with the predicted sigmas: RMS error, RMS(error/σ)
(1 for a consistent method), the fraction of runs within 2σ (0.954 for Gaussian errors) and,
where a bound is given, RMS error / RMS bound (1 for an efficient estimator).

Run ``i`` of a campaign with master seed ``S`` gets the seed of NumPy's
``SeedSequence(S, spawn_key=(i,))`` (independent streams, and any single run can be repeated from
the ``seed`` column of the results). Runs are batched into chunks (one Dask task per chunk) to
amortise the scheduling overhead, executed on a local Dask cluster (processes, one thread each)
or on an existing scheduler, or in-process (``workers=0``: no Dask at all).

Registering a pair is one call::

    register_pair("moving-latitude", my_run, unit="deg", defaults={"duration_s": 600.0},
                  description="seed 002 observer on a simulated ship")
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from selfnav.cluster import local_cluster, make_client  # noqa: F401 (local_cluster re-exported)
from selfnav.cluster import results_as_completed
from selfnav.errors import SelfnavError


# ------------------------------------------------------------------------------------------------
# Registry
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Pair:
    """A (scenario, method) pair that :func:`run_montecarlo` can run.

    Attributes
    ----------
    name : str
        Key used on the command line.
    run : callable
        ``run(seed: int, params: dict) -> dict`` (module docstring). Must be importable (a
        module-level function) or picklable by cloudpickle for the Dask workers.
    unit : str
        Unit of ``error``/``sigma``/``bound``.
    defaults : dict
        Default parameters; the user's overrides must use the same keys.
    description : str
    summarize : callable, optional
        ``summarize(table) -> dict``: the pair's own summary of the per-run table (e.g.
        distributions), merged into the campaign's.
    """

    name: str
    run: Callable[[int, dict], dict]
    unit: str
    defaults: dict = field(default_factory=dict)
    description: str = ""
    summarize: Callable[[dict], dict] | None = None


REGISTRY: dict[str, Pair] = {}


def register_pair(name: str, run: Callable[[int, dict], dict], *, unit: str, defaults=None,
                  description: str = "", summarize=None) -> Pair:
    """Register a (scenario, method) pair under ``name``; returns it."""
    p = Pair(name, run, unit, dict(defaults or {}), description, summarize)
    REGISTRY[name] = p
    return p


def get_pair(name: str) -> Pair:
    try:
        return REGISTRY[name]
    except KeyError:
        raise SelfnavError(f"unknown Monte Carlo scenario '{name}' (registered: "
                           f"{', '.join(sorted(REGISTRY))})") from None


def resolve_params(pair: Pair, overrides: dict | None) -> dict:
    """Defaults updated with overrides, each cast to the default's type; unknown keys refused."""
    params = dict(pair.defaults)
    for k, v in (overrides or {}).items():
        if k not in params:
            raise SelfnavError(f"scenario '{pair.name}' has no parameter '{k}' (it has: "
                               f"{', '.join(params)})")
        try:
            params[k] = type(params[k])(v)
        except (TypeError, ValueError):
            raise SelfnavError(f"parameter '{k}': cannot read {v!r} as "
                               f"{type(params[k]).__name__}") from None
    return params


def run_seeds(master_seed: int, runs: int) -> np.ndarray:
    """Seed of each run: ``SeedSequence(master_seed, spawn_key=(i,))`` as a 63-bit integer."""
    out = np.empty(runs, dtype=np.int64)
    for i in range(runs):
        s = np.random.SeedSequence(master_seed, spawn_key=(i,)).generate_state(2, np.uint32)
        out[i] = (int(s[0]) << 31) ^ int(s[1])
    return out


# ------------------------------------------------------------------------------------------------
# The first pair: latitude of a static IMU (seed 000) at random latitude and orientation
# ------------------------------------------------------------------------------------------------
DEG_PER_SQRT_H = np.pi / 180.0 / 60.0  # 1 °/√h in rad/√s
STATIC_LATITUDE_DEFAULTS = {
    "duration_s": 60.0,
    "dt_s": 0.01,
    "arw_deg_per_sqrt_h": 0.01,        # navigation-grade FOG
    "vrw_m_per_s_per_sqrt_h": 0.03,
    "gyro_bias_deg_per_h": 0.0,        # magnitude, random direction per run
    "accel_bias_ug": 0.0,              # magnitude, random direction per run
    "max_lat_deg": 89.0,
    "method": "optimal",
}


def _random_direction(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def run_static_latitude(seed: int, params: dict) -> dict:
    """One static-latitude run: random latitude in ±max_lat_deg, uniformly random orientation.

    The attitude is uniform on SO(3) (heading and roll uniform, pitch = arcsin U(−1, 1)); white
    sensor noise of the given densities, and constant biases of the given magnitudes in random
    directions. The method is :func:`selfnav.latitude.estimate_latitude`; ``sigma`` is its own
    data-driven 1σ, ``bound`` the Cramér–Rao bound (:func:`selfnav.latitude.cramer_rao_bound`).
    Angles returned in degrees.
    """
    from selfnav.latitude import G_STD, cramer_rao_bound, estimate_latitude
    from selfnav.sim.static import static_imu

    rng = np.random.default_rng(seed)
    lat = np.radians(rng.uniform(-params["max_lat_deg"], params["max_lat_deg"]))
    heading = rng.uniform(0.0, 2 * np.pi)
    pitch = np.arcsin(rng.uniform(-1.0, 1.0))
    roll = rng.uniform(-np.pi, np.pi)
    arw = params["arw_deg_per_sqrt_h"] * DEG_PER_SQRT_H
    vrw = params["vrw_m_per_s_per_sqrt_h"] / 60.0
    bg = params["gyro_bias_deg_per_h"] * np.pi / 180.0 / 3600.0 * _random_direction(rng)
    ba = params["accel_bias_ug"] * 1e-6 * G_STD * _random_direction(rng)
    imu = static_imu(lat, params["duration_s"], params["dt_s"], roll=roll, pitch=pitch,
                     heading=heading, arw=arw, vrw=vrw, gyro_bias=bg, accel_bias=ba,
                     seed=int(rng.integers(2**63)))
    res = estimate_latitude(imu, method=params["method"])
    crb = float(cramer_rao_bound(arw, vrw, imu.t[-1] - imu.t[0] + params["dt_s"]))
    return {
        "lat_true_deg": np.degrees(lat),
        "lat_est_deg": np.degrees(res.latitude),
        "error": np.degrees(res.latitude - lat),
        "sigma": np.degrees(res.sigma),
        "sigma_noise": np.degrees(res.sigma_noise),
        "bound": np.degrees(crb),
        "heading_deg": np.degrees(heading),
        "pitch_deg": np.degrees(pitch),
        "roll_deg": np.degrees(roll),
    }


register_pair("static-latitude", run_static_latitude, unit="deg",
              defaults=STATIC_LATITUDE_DEFAULTS,
              description="seed 000 latitude from an IMU at rest; random latitude and attitude")


# ------------------------------------------------------------------------------------------------
# Execution
# ------------------------------------------------------------------------------------------------
def run_chunk(run: Callable, indices, seeds, params: dict) -> list[dict]:
    """Run a batch of seeds (one Dask task). Each row gets ``run`` (index) and ``seed``."""
    rows = []
    with warnings.catch_warnings():  # a run's notes are not the user's: the summary speaks
        warnings.simplefilter("ignore")
        for i, s in zip(indices, seeds):
            r = run(int(s), params)
            rows.append({"run": int(i), "seed": int(s), **r})
    return rows


def default_chunk_size(runs: int, workers: int) -> int:
    """About eight tasks per worker (load balance) but at most 100 runs per task."""
    return int(max(1, min(100, np.ceil(runs / (8 * max(workers, 1))))))


def _chunks(runs: int, size: int):
    for a in range(0, runs, size):
        yield np.arange(a, min(a + size, runs))


@dataclass
class MonteCarloResult:
    """Rows of a campaign (sorted by run index) and its summary."""

    pair: str
    unit: str
    params: dict
    master_seed: int
    table: dict
    summary: dict
    workers: int
    scheduler: str
    elapsed_s: float
    compute_s: float

    def to_dict(self) -> dict:
        return {"scenario": self.pair, "unit": self.unit, "runs": len(self.table["run"]),
                "seed": self.master_seed, "params": self.params, **self.summary,
                "workers": self.workers, "scheduler": self.scheduler,
                "elapsed_s": self.elapsed_s, "compute_s": self.compute_s}


def summarize(error, sigma, bound=None) -> dict:
    """Error statistics against the predicted sigma (and an analytic bound when given).

    ``fraction_within_2sigma_se`` is the binomial standard error of that fraction. Runs
    without a result (a non-finite error or sigma: a drive that never started) are left out
    and counted in ``n_without_result``; ``n`` is the runs summarised.
    """
    e = np.asarray(error, dtype=float)
    s = np.asarray(sigma, dtype=float)
    ok = np.isfinite(e) & np.isfinite(s)
    if bound is not None:
        bound = np.asarray(bound, dtype=float)[ok]
    dropped = int(e.size - np.count_nonzero(ok))
    e, s = e[ok], s[ok]
    n = e.size
    if n == 0:
        nan = float("nan")
        return {"n": 0, "rms_error": nan, "mean_error": nan, "std_error": nan, "rms_sigma": nan,
                "rms_normalized_error": nan, "fraction_within_2sigma": nan,
                "fraction_within_2sigma_se": nan, "n_without_result": dropped}
    z = e / s
    frac = float(np.mean(np.abs(z) <= 2.0))
    out = {
        "n": int(n),
        "rms_error": float(np.sqrt(np.mean(e**2))),
        "mean_error": float(np.mean(e)),
        "std_error": float(np.std(e, ddof=1)) if n > 1 else float("nan"),
        "rms_sigma": float(np.sqrt(np.mean(s**2))),
        "rms_normalized_error": float(np.sqrt(np.mean(z**2))),
        "fraction_within_2sigma": frac,
        "fraction_within_2sigma_se": float(np.sqrt(max(frac * (1 - frac), 1e-12) / n)),
        "n_without_result": dropped,
    }
    if bound is not None:
        b = np.asarray(bound, dtype=float)
        out["rms_bound"] = float(np.sqrt(np.mean(b**2)))
        out["rms_error_over_bound"] = out["rms_error"] / out["rms_bound"]
    return out


def _to_table(rows: list[dict]) -> dict:
    rows = sorted(rows, key=lambda r: r["run"])
    keys = list(rows[0])
    return {k: np.array([r[k] for r in rows]) for k in keys}


def run_montecarlo(name: str, runs: int, *, seed: int = 0, params: dict | None = None,
                   workers: int = 2, scheduler: str | None = None, chunk_size: int | None = None,
                   client=None, progress: Callable[[int], None] | None = None) -> MonteCarloResult:
    """Run a registered pair ``runs`` times and summarise.

    Parameters
    ----------
    name : str
        Registered pair (:data:`REGISTRY`).
    runs : int
    seed : int
        Master seed (same seed, same results, whatever the workers and chunking).
    params : dict, optional
        Overrides of the pair's defaults.
    workers : int
        Local cluster size (processes, one thread each); ``0`` runs in this process without Dask.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``); ``workers`` is then ignored.
    chunk_size : int, optional
        Runs per task (default :func:`default_chunk_size`).
    client : dask.distributed.Client, optional
        Use this client (the caller owns it).
    progress : callable, optional
        Called with the number of runs just finished (drives a progress bar).
    """
    import time

    if runs < 1:
        raise SelfnavError(f"--runs must be at least 1 (got {runs})")
    if workers < 0:
        raise SelfnavError(f"--workers must be 0 (in-process) or more (got {workers})")
    pair = get_pair(name)
    p = resolve_params(pair, params)
    seeds = run_seeds(seed, runs)
    t0 = time.perf_counter()
    rows: list[dict] = []
    own_client = own_cluster = None
    if client is None and scheduler is None and workers == 0:
        mode, nw = "in-process", 0
        tc = time.perf_counter()
        size = chunk_size or default_chunk_size(runs, 1)
        for idx in _chunks(runs, size):
            rows += run_chunk(pair.run, idx, seeds[idx], p)
            if progress:
                progress(len(idx))
    else:
        try:
            import dask.distributed  # noqa: F401
        except ImportError:
            raise SelfnavError("Dask is not installed: pip install 'selfnav[dask]', or run in "
                               "this process with --workers 0") from None

        if client is None:
            client, own_cluster = make_client(workers, scheduler)
            own_client = client
        try:
            nw = len(client.scheduler_info().get("workers", {})) or max(workers, 1)
            mode = scheduler or ("local" if own_cluster is not None else "client")
            tc = time.perf_counter()
            size = chunk_size or default_chunk_size(runs, nw)
            futs = [client.submit(run_chunk, pair.run, idx, seeds[idx], p, pure=False)
                    for idx in _chunks(runs, size)]
            for part in results_as_completed(futs):
                rows += part
                if progress:
                    progress(len(part))
        finally:
            if own_client is not None:
                own_client.close()
            if own_cluster is not None:
                own_cluster.close()
    t1 = time.perf_counter()
    table = _to_table(rows)
    summary = summarize(table["error"], table["sigma"], table.get("bound"))
    if pair.summarize is not None:
        summary.update(pair.summarize(table))
    return MonteCarloResult(name, pair.unit, p, seed, table, summary, nw, mode, t1 - t0, t1 - tc)


# ------------------------------------------------------------------------------------------------
# Output
# ------------------------------------------------------------------------------------------------
def write_results(path, result: MonteCarloResult) -> Path:
    """Rows to ``.csv`` (``#`` comment header) or ``.parquet`` (pyarrow, metadata), atomically.

    Both carry the label *simulated* with the scenario, parameters and master seed.
    """
    from selfnav.io.csvio import atomic_path, write_csv

    path = Path(path)
    note = (f"simulated: selfnav montecarlo {result.pair}, {len(result.table['run'])} runs, "
            f"master seed {result.master_seed}, error/sigma/bound in {result.unit}")
    params = ", ".join(f"{k}={v}" for k, v in result.params.items())
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return write_csv(path, result.table, comments=[note, f"params: {params}"],
                         fmt={"run": "%d", "seed": "%d"})
    if suffix in (".parquet", ".pq"):
        import pyarrow as pa
        import pyarrow.parquet as pq

        tab = pa.table({k: pa.array(v) for k, v in result.table.items()})
        tab = tab.replace_schema_metadata({b"selfnav": note.encode(),
                                           b"params": params.encode()})
        with atomic_path(path) as tmp:
            pq.write_table(tab, tmp)
        return path
    raise SelfnavError(f"{path}: output must end in .csv or .parquet")
