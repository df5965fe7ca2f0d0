"""A local Dask cluster or a client of an existing one (shared by ``selfnav montecarlo`` and
``selfnav match``; Dask is the optional ``dask`` extra)."""
from __future__ import annotations

import logging
import os
import signal
import threading
import time

from selfnav.errors import SelfnavError, check_interrupt


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
        _start_forkserver_ignoring_sigint()
        with dask.config.set({f"distributed.nanny.pre-spawn-environ.{key}": None,
                              "distributed.worker.multiprocessing-method": "forkserver"}):
            # no dashboard, and the scheduler's HTTP routes (health, metrics) on a free port:
            # on the default 8787 a second cluster on the machine (two campaigns, two test
            # workers) printed distributed's "Port 8787 is already in use"
            return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                dashboard_address=None,
                                scheduler_kwargs={"dashboard_address": ":0"},
                                silence_logs=logging.CRITICAL)
    finally:
        if saved is not None:
            os.environ[key] = saved


def _start_forkserver_ignoring_sigint() -> None:
    """Start multiprocessing's fork server with SIGINT ignored; the worker processes it forks
    inherit that, so Ctrl-C reaches this process only, which then shuts the cluster down (no
    traceback from every worker). Only the fork and exec of the server (milliseconds) run with
    SIGINT ignored here: a Ctrl-C during the cluster's start-up is not lost."""
    import multiprocessing.forkserver as fs

    if threading.current_thread() is not threading.main_thread():
        fs.ensure_running()
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        fs.ensure_running()
    finally:
        signal.signal(signal.SIGINT, old)


def results_as_completed(futures, poll_s: float = 0.05):
    """Results of Dask futures as they finish, polling so that the main thread stays responsive
    to Ctrl-C (a signal the kernel hands to one of Dask's threads would not wake a blocking
    wait: the process hung until the next future finished)."""
    pending = list(futures)
    while pending:
        check_interrupt()
        still = []
        for f in pending:
            if f.done():
                yield f.result()
            else:
                still.append(f)
        pending = still
        if pending:
            time.sleep(poll_s)
