"""A local Dask cluster or a client of an existing one (shared by ``selfnav montecarlo`` and
``selfnav match``; Dask is the optional ``dask`` extra)."""
from __future__ import annotations

import logging
import os

from selfnav.errors import SelfnavError


def make_client(workers: int, scheduler: str | None):
    """A Dask client: of the scheduler at ``scheduler`` (``tcp://host:8786``), or of a new
    :func:`local_cluster` of ``workers`` processes. Returns ``(client, cluster or None)``; the
    caller closes both."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise SelfnavError("Dask is not installed: pip install 'selfnav[dask]', or run in "
                           "this process with --workers 0") from None

    if scheduler:
        try:
            return Client(scheduler, timeout="10s"), None
        except (OSError, TimeoutError) as e:
            raise SelfnavError(f"cannot reach the Dask scheduler at {scheduler}: {e}") from None
    cluster = local_cluster(workers)
    return Client(cluster), cluster


def local_cluster(workers: int):
    """A ``LocalCluster`` of ``workers`` processes with one thread each, tuned for many small runs.

    Dask sets ``MALLOC_TRIM_THRESHOLD_=65536`` in its workers, which also switches off glibc's
    dynamic mmap threshold: every NumPy array above 128 kB (a 60 s, 100 Hz IMU record is 144 kB)
    is then mmapped and unmapped per use, and the workers spent ~45 % more CPU per run than this
    process (measured). The variable is left unset here, so the workers allocate like any Python
    process.
    """
    import dask
    from dask.distributed import LocalCluster

    key = "MALLOC_TRIM_THRESHOLD_"
    saved = os.environ.pop(key, None)  # a nanny of an earlier cluster may have exported it
    try:
        with dask.config.set({f"distributed.nanny.pre-spawn-environ.{key}": None}):
            return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                dashboard_address=None, silence_logs=logging.ERROR)
    finally:
        if saved is not None:
            os.environ[key] = saved
