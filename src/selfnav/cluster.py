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
    try:
        return Client(cluster), cluster
    except BaseException:  # a Ctrl-C while the client connects: the cluster is ours to close
        cluster.close()
        raise


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
        _start_forkserver_blocking_sigint()
        with dask.config.set({f"distributed.nanny.pre-spawn-environ.{key}": None,
                              "distributed.worker.multiprocessing-method": "forkserver"}):
            # no dashboard, and the scheduler's HTTP routes (health, metrics) on a free port:
            # on the default 8787 a second cluster on the machine (two campaigns, two test
            # workers) printed distributed's "Port 8787 is already in use"
            return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                dashboard_address=None,
                                scheduler_kwargs={"dashboard_address": ":0"},
                                silence_logs=logging.CRITICAL)
    except BaseException:
        # a Ctrl-C during the start-up leaves a half-started cluster to distributed's exit
        # handlers; its scheduler went on starting and logged (INFO) after the cluster's own
        # silencing had been undone. Keep distributed quiet for the rest of this process: its
        # logger, not its handlers, whose levels the half-started cluster restores at exit
        logging.getLogger("distributed").setLevel(logging.CRITICAL)
        raise
    finally:
        if saved is not None:
            os.environ[key] = saved


def _start_forkserver_blocking_sigint() -> None:
    """Start multiprocessing's fork server with SIGINT blocked; the worker processes it forks
    inherit the signal mask, so Ctrl-C reaches this process only, which then shuts the cluster
    down (no traceback from every worker).

    Blocked, not ignored: a Ctrl-C that arrives while the server is spawned stays pending and is
    delivered here when the mask is restored. With SIGINT ignored for those milliseconds it was
    discarded, and the command went on computing (seen once in CI, reproduced by a SIGINT sent
    as the cluster starts)."""
    import multiprocessing.forkserver as fs
    from multiprocessing import resource_tracker

    if threading.current_thread() is not threading.main_thread():
        fs.ensure_running()
        return
    # the resource tracker first: its own start-up blocks SIGINT and then unblocks it, which
    # inside the block below would have let the fork server start unprotected
    resource_tracker.ensure_running()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        fs.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


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
