"""Where the long-running commands run their tasks: in this process, on local worker processes,
or on a Dask distributed cluster — chosen the same way by ``sweep``, ``reproduce`` and
``benchmark accuracy``:

    --workers N            local worker processes (spawn start method; 1: in this process)
    --scheduler ADDRESS    a running Dask scheduler (``tcp://HOST:8786``); its workers need this
                           package installed (the same version)
    --dask-local N         a Dask ``LocalCluster`` of N worker processes on this machine (to try
                           the Dask path)

Every executor is a ``concurrent.futures.Executor`` (Dask's through ``Client.get_executor``), so
the commands submit module-level functions with plain arguments (Drake objects do not pickle:
each task builds its diagram inside its worker).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
from concurrent.futures import ProcessPoolExecutor

from .argtypes import positive_int


def add_executor_arguments(parser, default_workers: int | None = None,
                           workers_help: str | None = None) -> None:
    """Adds ``--workers``, ``--scheduler`` and ``--dask-local`` to an argparse parser."""
    default = default_workers if default_workers is not None else (os.cpu_count() or 1)
    parser.add_argument("--workers", type=positive_int, default=default, metavar="N",
                        help=workers_help or f"local worker processes (default {default}; 1 "
                        "runs in this process)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run on a Dask distributed cluster: its scheduler's address "
                             "(tcp://HOST:8786)")
    parser.add_argument("--dask-local", type=positive_int, metavar="N",
                        help="start a Dask LocalCluster of N worker processes and run on it")


def _ignore_ctrl_c() -> None:
    """In a worker process: Ctrl-C is the parent's business (it stops the sweep and shuts the
    workers down), not a traceback per worker."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def _workers_ignore_ctrl_c():
    """Processes started inside inherit an ignored SIGINT (Python then installs no
    KeyboardInterrupt handler in them); this process's own handler is restored after."""
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def make_executor(workers: int = 1, scheduler: str | None = None,
                  dask_local: int | None = None):
    """Yields ``(executor, description)``; the executor is None for a serial run in this
    process. Shuts down what it started (pool, local cluster, client) on exit."""
    if scheduler and dask_local:
        raise ValueError("--scheduler and --dask-local: choose one executor")
    if isinstance(workers, bool) or int(workers) != workers or workers < 1:
        raise ValueError(f"--workers: expected a positive integer, got {workers!r}")
    # Child processes inherit this: one BLAS thread per worker (the workers are the parallelism).
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if scheduler or dask_local:
        try:
            from distributed import Client, LocalCluster
        except ImportError as e:  # pragma: no cover - a declared dependency
            raise ValueError(f"--scheduler/--dask-local: Dask distributed is not installed "
                             f"({e})") from None
        cluster = None
        try:
            if dask_local:
                with _workers_ignore_ctrl_c():
                    # ":0": the dashboard on a free port (None still tries 8787, and warns
                    # when another cluster holds it).
                    cluster = LocalCluster(n_workers=int(dask_local), threads_per_worker=1,
                                           processes=True, dashboard_address=":0",
                                           silence_logs=logging.ERROR)
                client = Client(cluster)
                where = f"Dask LocalCluster, {dask_local} worker processes"
            else:
                try:
                    client = Client(scheduler, timeout="10s")
                except (OSError, TimeoutError) as e:
                    raise ValueError(f"--scheduler {scheduler}: cannot connect ({e})") from None
                n = len(client.scheduler_info().get("workers", {}))
                where = f"Dask scheduler {scheduler} ({n} workers)"
            executor = client.get_executor(pure=False)
            try:
                yield executor, where
            finally:
                executor.shutdown(wait=False)
                client.close()
        finally:
            if cluster is not None:
                cluster.close()
        return
    if workers > 1:
        pool = ProcessPoolExecutor(max_workers=int(workers),
                                   mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_ignore_ctrl_c)
        try:
            yield pool, f"{workers} local worker processes"
        finally:
            pool.shutdown(cancel_futures=True)
        return
    yield None, "serial, in this process"
