"""Where distributed work runs: a Dask ``distributed`` client on a local cluster or an existing scheduler.

meshshade schedules nothing itself: batches (:mod:`meshshade.batch.runner`) and split Monte Carlo runs
(:mod:`meshshade.montecarlo.distributed`) submit tasks to a :class:`distributed.Client` and Dask places, retries
and moves them. :func:`open_client` gives one:

* ``scheduler="tcp://host:8786"`` (or a scheduler file's path, as written by ``dask scheduler
  --scheduler-file``): connect to a running cluster (started by hand, by dask-jobqueue on SLURM/PBS, by the Dask
  Kubernetes operator, ...). Its workers must be able to import meshshade and read the input paths.
* otherwise a :class:`distributed.LocalCluster` of ``workers`` processes (default: one per core), one task
  thread each; each process's compiled loops get ``cores // workers`` threads (at least 1), so the machine is
  not oversubscribed, and glibc's default memory trimming (Dask's own setting made bakes 20-50 % slower).

Inside a task, :func:`task_threads` sets the numba thread count for the worker it runs on (``MESHSHADE_TASK_THREADS``
when set, as on the local cluster; otherwise the worker's cores divided by the tasks it runs at once).
"""
from __future__ import annotations

import contextlib
import os
import sys

from meshshade.errors import MeshshadeError

__all__ = ["open_client", "check_cluster_options", "task_threads", "dashboard_line"]

#: seconds to wait for a remote scheduler before a one-line error
CONNECT_TIMEOUT = 10
#: environment variable: numba threads per task, set by :func:`open_client` for its local workers (numba reads
#: NUMBA_NUM_THREADS once, at import, which in a spawned worker may come before the cluster's environment)
THREADS_ENV = "MESHSHADE_TASK_THREADS"


def check_cluster_options(scheduler=None, workers=None) -> tuple:
    """Validate ``(scheduler, workers)`` before any work: one-line MeshshadeError for both given, a workers count
    that is not an integer >= 1, or a scheduler that is neither an address (``tcp://``, ``tls://``, ``ucx://``,
    ``inproc://``) nor an existing scheduler file."""
    if scheduler is not None and workers is not None:
        raise MeshshadeError("give either a scheduler address or a number of local workers, not both")
    if workers is not None:
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise MeshshadeError(f"workers must be an integer >= 1, got {workers!r}")
    if scheduler is not None:
        s = str(scheduler)
        if "://" not in s and not os.path.isfile(s):
            raise MeshshadeError(f"scheduler {s!r} is neither an address such as tcp://host:8786 nor an existing "
                                 "scheduler file")
    return scheduler, workers


def dashboard_line(client) -> str:
    """``dask dashboard: http://...`` for the client's cluster ('' when it has none)."""
    link = getattr(client, "dashboard_link", None)
    return f"meshshade: dask dashboard: {link}" if link else ""


@contextlib.contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None, *, quiet: bool = False):
    """A :class:`distributed.Client` for the duration of the ``with`` block (the local cluster, if one was
    started, is closed afterwards). Prints the dashboard address on stderr unless ``quiet``.

    Raises MeshshadeError (one line) for bad options or a scheduler that cannot be reached in
    :data:`CONNECT_TIMEOUT` seconds.
    """
    check_cluster_options(scheduler, workers)
    import logging

    import dask
    from distributed import Client, LocalCluster

    # a worker process that a test (or the OS) kills is reported by the nanny at length: keep it to warnings
    for name in ("distributed", "distributed.nanny", "distributed.scheduler", "distributed.worker"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    cluster = None
    try:
        if scheduler is not None:
            kw = {"scheduler_file": scheduler} if "://" not in str(scheduler) else {"address": scheduler}
            try:
                client = Client(timeout=CONNECT_TIMEOUT, **kw)
            except (OSError, TimeoutError) as exc:
                raise MeshshadeError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None
        else:
            cores = os.cpu_count() or 1
            n = workers or cores
            threads = max(1, cores // n)
            # Dask starts workers with MALLOC_TRIM_THRESHOLD_=65536, which makes glibc return memory after every
            # large free; a bake allocates and frees large arrays all the time and ran 20-50 % slower so
            # (tools/benchmarks/bench_batch.py). Workers keep glibc's default here.
            # Worker processes log to stderr; at shutdown after an interrupt they report lost connections with
            # tracebacks. A job's own errors are in its record, so worker logs are kept to critical ones.
            with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                                  "distributed.nanny.pre-spawn-environ.DASK_LOGGING__DISTRIBUTED": "critical"}):
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                                       env={THREADS_ENV: str(threads), "OMP_NUM_THREADS": str(threads)})
            client = Client(cluster)
        if not quiet and (line := dashboard_line(client)):
            print(line, file=sys.stderr)
        try:
            yield client
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()


def task_threads() -> int:
    """Inside a Dask task: set numba's thread count to this worker's cores divided by its task threads (at least 1,
    at most ``NUMBA_NUM_THREADS``) and return it; outside a worker, leave numba alone and return its count."""
    import numba

    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return numba.get_num_threads()
    wanted = os.environ.get(THREADS_ENV)
    n = int(wanted) if wanted and wanted.isdigit() else (os.cpu_count() or 1) // max(1, worker.state.nthreads)
    n = max(1, min(numba.config.NUMBA_NUM_THREADS, n))
    numba.set_num_threads(n)
    return n
