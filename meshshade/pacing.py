"""Pacing: long kernel work cut into calls of about 0.2 s on worker threads, so that Ctrl-C acts between calls.

This is also how meshshade's compiled loops use several cores: a loop is compiled serial (``nogil=True``) and
called on blocks of its items from these worker threads (:func:`run_paced`, :func:`run_in_blocks`). numba's own
threads (``parallel=True``, ``prange``) are kept only where one compiled call forks and joins many times (the
volume's conjugate gradients, the Monte Carlo rounds): a parallel build costs about twice a serial one to compile
(``meshshade demo``'s first run: 27 of its 80 compile seconds before the far-field traversal, the arc geodesics and
the volume's assembly, location and near field moved here) and cannot be interrupted.

Python acts on Ctrl-C (and SIGTERM, SIGHUP) only between bytecodes, never inside a compiled loop, so a kernel that
runs over many sources (the geodesic neighbourhood queries, :mod:`meshshade.geometry.geodesics`) is called on
consecutive blocks of sources instead, each of about :data:`BLOCK_SECONDS` of work:

* :class:`Pacer` chooses where the blocks end, from an estimate of each source's work and the seconds per unit
  of work measured on the calls made so far (:func:`pace_rate` keeps one such measurement per size class);
* :func:`run_paced` calls the kernel on the blocks, on worker threads (callers default to
  :func:`default_threads`) or in the calling thread, and on an interrupt drops the queued blocks and tells the
  running ones to stop.

Where blocks end never changes a result: every source is computed on its own. The interrupt handling itself is
:mod:`meshshade.progress`'s (:func:`~meshshade.progress.kernel_interrupts`,
:func:`~meshshade.progress.polled_interrupts`).

Short sweeps called many times in a row (the volume's multigrid: a few milliseconds each, hundreds per solve) take
:func:`parallel_for` instead: equal blocks on a pool of threads kept for the process (no threads started per call,
no pacing), the calling thread working on the first block.
"""
from __future__ import annotations

import math
import os
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

import numpy as np

from meshshade.progress import kernel_interrupts, polled_interrupts

__all__ = ["BLOCK_SECONDS", "POLL_SECONDS", "Pacer", "default_threads", "pace_rate", "parallel_for", "run_in_blocks",
           "run_paced"]

#: seconds of work per kernel call: Python acts on Ctrl-C (and SIGTERM, SIGHUP) only between calls, never inside
#: a compiled loop, so this bounds how long an interrupt waits (see :func:`run_paced`)
BLOCK_SECONDS = 0.2
#: seconds between two looks for an interrupt while run_paced waits on its worker threads
POLL_SECONDS = 0.02


def default_threads() -> int:
    """Worker threads for the compiled loops: numba's thread count for the calling thread where numba is loaded
    (``NUMBA_NUM_THREADS``, or a Dask task's share of its worker's cores set by
    :func:`meshshade.batch.dask_cluster.task_threads`), at most the CPUs this process may run on (its affinity mask
    where the platform has one); at least 1."""
    try:
        n_cpu = max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - macOS/Windows
        n_cpu = max(1, os.cpu_count() or 1)
    numba = sys.modules.get("numba")
    if numba is None:
        return n_cpu
    return max(1, min(n_cpu, int(numba.get_num_threads())))


def pace_rate(rates: dict, work) -> dict:
    """The measured-speed record (:class:`Pacer`'s ``rate``) for sources of this much ``work`` (k,), kept in
    ``rates`` per factor-2 class of the mean work per source: the cost per unit of work may grow with the work
    (the geodesic queries' exact windows: 2-5 us per pair over a few hundred vertices, 30-40 us over a whole mesh
    of 10-40k), and a bake alternates queries of very different radii (auto's near and far zones)."""
    mean = float(np.mean(work)) if len(work) else 1.0
    return rates.setdefault(int(np.log2(max(mean, 1.0))), {})


class Pacer:
    """Cuts k sources into consecutive blocks of about ``seconds`` of kernel work each.

    ``work`` (k,) estimates each source's work, in the caller's unit (the geodesic queries: expected pairs,
    :func:`meshshade.geometry.geodesics.neighbourhoods.expected_work`); the seconds per unit of work are measured
    on the calls made so far (``rate``, a dict the caller may keep across queries: ``{"seconds", "work"}``, older
    calls fading by half every few calls), starting from ``prior`` (seconds per unit of work; a conservative
    guess, or None: the first block is ``min_block`` sources). A block has between ``min_block`` and
    ``max_block`` sources. Where blocks end never changes a result: every source is computed on its own.
    """

    def __init__(self, work, rate: dict | None = None, *, prior: float | None = None,
                 seconds: float = BLOCK_SECONDS, min_block: int = 1, max_block: int = 512):
        self.cum = np.cumsum(np.asarray(work, dtype=np.float64))
        self.rate = {} if rate is None else rate
        self.prior = None if prior is None else float(prior)
        self.seconds = float(seconds)
        self.min_block, self.max_block = max(1, int(min_block)), max(1, int(max_block))

    def seconds_per_work(self) -> float | None:
        """The measured seconds per unit of work, else the prior (None: neither)."""
        r = self.rate
        return r["seconds"] / r["work"] if r.get("work", 0.0) > 0 else self.prior

    def next(self, a: int) -> int:
        """End (exclusive) of the block that starts at source ``a``."""
        k = self.cum.shape[0]
        per_work = self.seconds_per_work()
        if per_work is None:  # nothing measured and no prior: the smallest block
            return int(min(k, a + self.min_block))
        start = self.cum[a - 1] if a > 0 else 0.0
        b = int(np.searchsorted(self.cum, start + self.seconds / per_work, side="right"))
        return int(min(k, a + self.max_block, max(b, a + self.min_block)))

    def work(self, a: int, b: int) -> float:
        """The estimated work of sources ``a:b``."""
        return float(self.cum[b - 1] - (self.cum[a - 1] if a > 0 else 0.0))

    def record(self, a: int, b: int, seconds: float) -> None:
        """A call over sources ``a:b`` took ``seconds``."""
        r = self.rate
        r["seconds"] = 0.8 * r.get("seconds", 0.0) + seconds
        r["work"] = 0.8 * r.get("work", 0.0) + self.work(a, b)


def run_paced(run, pacer: Pacer, k: int, *, n_threads: int = 1, progress=None, stop=None) -> list:
    """``run(a, b)`` over consecutive blocks ``a:b`` of ``k`` sources chosen by ``pacer``; the results in source
    order.

    With ``n_threads`` > 1 the blocks run on worker threads (the kernels release the GIL), at most two per
    thread submitted at a time, while the calling thread waits (a wait Python interrupts at once). Each call
    takes about :data:`BLOCK_SECONDS`, so after Ctrl-C (a KeyboardInterrupt raised in the calling thread, also
    by ``progress``) at most the blocks already running finish before it propagates; the queued ones are
    cancelled, and ``stop`` ((1,) array or None) is set to 1, which tells the running kernels that watch it to
    return at once (their results are dropped). In the calling thread, an interrupt that numba reports as a
    SystemError is raised as the KeyboardInterrupt it is (:func:`meshshade.progress.kernel_interrupts`).
    ``progress(done, k)`` is called after each block with the number of sources done.
    """
    results: dict = {}
    done = 0
    if k == 0:
        return []
    first = pacer.next(0)
    if n_threads <= 1 or first >= k:
        a = 0
        while a < k:
            b = first if a == 0 else pacer.next(a)
            t = time.perf_counter()
            with kernel_interrupts():  # a Ctrl-C during the call: KeyboardInterrupt, never numba's SystemError
                results[a] = run(a, b)
            pacer.record(a, b, time.perf_counter() - t)
            done += b - a
            a = b
            if progress is not None:
                progress(done, k)
        return [results[a] for a in sorted(results)]

    def timed(a, b):
        t = time.perf_counter()
        out = run(a, b)
        return out, time.perf_counter() - t

    ex = _shared_pool(n_threads)      # the process's pool: no threads started or joined per call
    pending: dict = {}
    # signals are polled between the executor's calls, never raised inside them (progress.polled_interrupts)
    with polled_interrupts() as poll:
        try:
            a = 0
            while a < k or pending:
                while a < k and len(pending) < 2 * n_threads:
                    b = first if a == 0 else pacer.next(a)
                    pending[ex.submit(timed, a, b)] = (a, b)
                    a = b
                finished, _ = wait(pending, timeout=POLL_SECONDS, return_when=FIRST_COMPLETED)
                poll()
                for f in finished:
                    a0, b0 = pending.pop(f)
                    results[a0], seconds = f.result()
                    pacer.record(a0, b0, seconds)
                    done += b0 - a0
                    if progress is not None:
                        progress(done, k)
        except BaseException:
            if stop is not None:
                stop[0] = 1  # kernels that watch it return at their next step
            raise
        finally:  # on an interrupt or error: queued blocks are dropped, running ones finish (or stop early)
            for f in pending:
                f.cancel()
            wait(pending)
    return [results[a] for a in sorted(results)]



def run_in_blocks(run, k: int, *, n_threads: int | None = None, block: int | None = None, min_block: int = 256,
                  progress=None) -> list:
    """``run(a, b)`` over consecutive blocks ``a:b`` of ``k`` items on ``n_threads`` worker threads (default
    :func:`default_threads`), the results in item order: a serial compiled loop (``nogil=True``) over items that
    are each computed on their own, run on several cores (:func:`run_paced` with blocks of one size; Ctrl-C acts
    between blocks).

    ``block``: items per call; by default ``k`` split into four blocks per thread (for balance), at least
    ``min_block`` items. Where blocks end never changes a result when every item is computed on its own.
    """
    n_threads = default_threads() if n_threads is None else max(1, int(n_threads))
    if block is None:
        block = max(int(min_block), math.ceil(k / (4 * n_threads)))
    block = max(1, int(block))
    pacer = Pacer(np.ones(k), seconds=np.inf, min_block=block, max_block=block)
    return run_paced(run, pacer, k, n_threads=n_threads, progress=progress)


_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _shared_pool(workers: int) -> ThreadPoolExecutor:
    """The process's pool of at least ``workers`` threads (made, or remade larger, on demand)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None or _POOL._max_workers < workers:
            old, _POOL = _POOL, ThreadPoolExecutor(max_workers=workers, thread_name_prefix="meshshade")
            if old is not None:
                old.shutdown(wait=False)
        return _POOL


def parallel_for(run, k: int, *, n_threads: int | None = None, min_block: int = 2048) -> None:
    """``run(a, b)`` over ``n_threads`` equal consecutive blocks ``a:b`` of ``k`` items (default
    :func:`default_threads`), at least ``min_block`` items each: the calling thread runs the first block while the
    process's pool runs the others, and the call returns when all are done. For compiled kernels that release the
    interpreter (``nogil=True``), each item computed on its own (so where blocks end never changes a result), short
    and called many times (no threads are started per call). A Ctrl-C acts when the call returns."""
    n = default_threads() if n_threads is None else max(1, int(n_threads))
    n = min(n, max(1, k // max(1, int(min_block))))
    if n <= 1:
        if k > 0:
            run(0, k)
        return
    edges = [round(i * k / n) for i in range(n + 1)]
    pool = _shared_pool(n - 1)
    futures = [pool.submit(run, edges[i], edges[i + 1]) for i in range(1, n)]
    try:
        run(edges[0], edges[1])
    finally:
        for f in futures:
            f.result()
