"""Run a batch of jobs on Dask distributed: one task per job, one folder per job, a manifest of them all.

:func:`run_batch` submits every job that is not already done to a :class:`distributed.Client` (a local cluster
sized to the machine unless one is given, :mod:`meshshade.batch.dask_cluster`) and collects the outcomes as they
arrive. Dask places the tasks, moves them between workers and re-runs a task whose worker died; meshshade only
says what a job is and where its files go:

* **One folder per job.** :func:`run_job` (the task) writes the command's outputs into ``.<name>.part-<random>``
  and renames it to ``<out>/<name>`` only when every output and the job's record ``job.json`` are complete
  (:func:`meshshade.io.job_folder`). A job that fails, or a worker killed half-way, leaves no ``<name>`` folder;
  the ``.part`` folder of a killed worker is removed when the job is retried, and at the start of every run.
* **The manifest** ``<out>/manifest.jsonl`` has one JSON line per job of the batch (file order): name, command,
  options, ``param_hash``, ``status`` ("ok" or "failed"), the one-line ``error``, start and end times, seconds,
  the worker, package versions, the SHA-256 of every output file, warnings, and what the worker reused from
  earlier jobs (:mod:`meshshade.memo`). It is rewritten atomically as jobs finish (at most once a second) and at
  the end.
* **Re-running** the same batch skips every job whose folder holds a ``job.json`` with status ok and the same
  ``param_hash`` (its record is kept), runs again the jobs that failed or never finished, and re-runs (then
  replaces) a job whose options changed.
* **A failing job** is one line on stderr and in the manifest, never the end of the batch.

Inside a worker, every job runs in :func:`meshshade.memo.reuse`: the loaded mesh, its curvature and ray-casting
scene and the hierarchical transport are kept for the next job on the same mesh (and material and model), so a
sweep over lights or materials does not rebuild them.
"""
from __future__ import annotations

import contextlib
import io as _io
import os
import platform
import socket
import sys
import time
import warnings
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from meshshade import __version__, memo
from meshshade.batch.dask_cluster import open_client, task_threads
from meshshade.batch.jobs import Job, JobFileError
from meshshade.errors import MeshshadeError
from meshshade.io import (detached, file_sha256, folder_files, job_folder, output_dir, output_transaction, read_json,
                          read_json_lines, remove_stale_parts, write_json, write_json_lines, write_text)
from meshshade.names import BATCH_MANIFEST as MANIFEST  # the manifest's file name
from meshshade.progress import Progress

__all__ = ["BatchResult", "MANIFEST", "RECORD", "run_batch", "run_job", "job_status", "versions"]

RECORD = "job.json"
#: seconds between two rewrites of the manifest while jobs finish
MANIFEST_INTERVAL = 1.0


def versions() -> dict:
    """Versions of meshshade, Python and the libraries its results depend on (in the process that ran a job)."""
    out = {"meshshade": __version__, "python": platform.python_version()}
    for name in ("numpy", "scipy", "numba", "trimesh", "igl", "embreex", "OpenImageIO", "dask", "distributed"):
        mod = sys.modules.get(name)
        if mod is None:
            with contextlib.suppress(ImportError):
                mod = __import__(name)
        version = getattr(mod, "__version__", None)
        if version is not None:
            out[name] = str(version)
    return out


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _one_line(exc: BaseException, limit: int = 300) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    if not isinstance(exc, MeshshadeError):
        text = f"{type(exc).__name__}: {text}"
    return text if len(text) <= limit else text[:limit - 3] + "..."


def run_job(job: Job, out) -> dict:
    """Run one job into ``out/<job.name>`` (a Dask task, or a plain call); returns its record.

    Never raises for a job's own failure (a MeshshadeError or any other exception of the command): the record
    then has ``status="failed"`` and a one-line ``error``, and no folder is left. Only an interrupt
    (KeyboardInterrupt) propagates, after removing the partial folder.
    """
    threads = task_threads()
    out = Path(out)
    record = {"name": job.name, "command": job.command, "options": job.options, "param_hash": job.param_hash,
              "started": _now(), "worker": f"{socket.gethostname()}:{os.getpid()}", "numba_threads": threads}
    t0 = time.perf_counter()
    before = memo.stats()
    try:
        with detached():
            output_dir(out)
            remove_stale_parts(out, {job.name})   # left by an attempt whose worker was killed
            with memo.reuse(), job_folder(out / job.name) as tmp:
                stdout = _io.StringIO()
                with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stdout(stdout):
                    warnings.simplefilter("always")
                    with output_transaction():
                        job.execute(job, tmp)
                if stdout.getvalue():
                    write_text(tmp / "stdout.txt", stdout.getvalue())
                after = memo.stats()
                record.update(
                    status="ok", error=None, finished=_now(), seconds=round(time.perf_counter() - t0, 4),
                    outputs={f: file_sha256(tmp / f) for f in folder_files(tmp)},
                    warnings=list(dict.fromkeys(" ".join(str(w.message).split()) for w in caught)),
                    reused={k: after[k] - before.get(k, 0) for k in after if after[k] != before.get(k, 0)},
                    versions=versions())
                write_json(tmp / RECORD, record)
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # noqa: BLE001 - one job's failure is data, never the end of the batch
        record.update(status="failed", error=_one_line(exc), finished=_now(),
                      seconds=round(time.perf_counter() - t0, 4), outputs={}, versions=versions())
    return record


def job_status(job: Job, out) -> dict | None:
    """The record of a finished job with the same parameters in ``out/<job.name>``, or None."""
    rec = read_json(Path(out) / job.name / RECORD)
    if isinstance(rec, dict) and rec.get("status") == "ok" and rec.get("param_hash") == job.param_hash:
        return rec
    return None


@dataclass
class BatchResult:
    """Outcome of :func:`run_batch`: ``records`` (one per job, in job order, as in the manifest), the names
    ``ran``, ``skipped`` and ``failed`` in this run, ``seconds`` of wall time."""

    out: Path
    records: list
    ran: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    failed: list = field(default_factory=list)
    seconds: float = 0.0
    dashboard: str | None = None

    @property
    def ok(self) -> bool:
        return not self.failed

    def describe(self) -> str:
        n = len(self.records)
        text = (f"batch: {n} job(s): {len(self.ran) - len(self.failed)} finished now, {len(self.skipped)} already "
                f"done, {len(self.failed)} failed, in {self.seconds:.1f} s; manifest {self.out / MANIFEST}")
        return text

    def __repr__(self) -> str:
        return f"<BatchResult {self.describe()}>"


def _check_jobs(jobs) -> list[Job]:
    jobs = list(jobs)
    if not jobs:
        raise JobFileError("no jobs to run")
    names = set()
    for job in jobs:
        if not isinstance(job, Job):
            raise JobFileError(f"run_batch takes meshshade.batch.Job objects, got {type(job).__name__}")
        if job.name in names:
            raise JobFileError(f"two jobs are named {job.name!r}")
        names.add(job.name)
    return jobs


def run_batch(jobs, out, *, client=None, scheduler: str | None = None, workers: int | None = None,
              progress: bool = True, quiet: bool = False) -> BatchResult:
    """Run ``jobs`` (:class:`~meshshade.batch.jobs.Job`, e.g. from :func:`meshshade.cli.jobs.read_jobs`) on
    Dask, each into its own folder under ``out``, with the manifest ``out/manifest.jsonl`` (module docstring).

    client : a :class:`distributed.Client` to submit to; otherwise one is opened for the call on ``scheduler``
        (an address or scheduler file) or on a local cluster of ``workers`` processes (default: one per core).
    progress : one bar (or periodic lines) over the jobs; quiet : no dashboard line and no per-failure lines.

    Returns a :class:`BatchResult`; a failed job is in ``failed`` and the manifest, not an exception. Raises
    MeshshadeError (one line) only for what stops the whole batch: bad jobs or options, an output folder that
    cannot be made, a scheduler that cannot be reached.
    """
    jobs = _check_jobs(jobs)
    t0 = time.perf_counter()
    with detached():
        out = output_dir(out)
        remove_stale_parts(out, {j.name for j in jobs})
    previous = {r.get("name"): r for r in read_json_lines(out / MANIFEST)}
    records: dict = {}
    skipped, todo = [], []
    for job in jobs:
        done = job_status(job, out)
        if done is not None:
            records[job.name] = done
            skipped.append(job.name)
        else:
            todo.append(job)
            if job.name in previous and previous[job.name].get("param_hash") == job.param_hash:
                records[job.name] = previous[job.name]   # a failure of an earlier run, until this run's outcome
    result = BatchResult(out=out, records=[], skipped=skipped)

    def write_manifest(final: bool = False):
        if final:  # a job whose folder a worker completed before this process heard of it (an interrupt)
            for j in todo:
                if j.name not in result.ran and (rec := job_status(j, out)) is not None:
                    records[j.name] = rec
        with detached():
            write_json_lines(out / MANIFEST, [records[j.name] for j in jobs if j.name in records])

    if not todo:
        write_manifest()
    else:
        try:
            with contextlib.ExitStack() as stack:
                if client is None:
                    client = stack.enter_context(open_client(scheduler, workers, quiet=quiet))
                elif scheduler is not None or workers is not None:
                    raise MeshshadeError("give a client, or a scheduler / number of workers, not both")
                result.dashboard = getattr(client, "dashboard_link", None)
                _collect(client, todo, out, records, result, write_manifest, progress, quiet)
        except BaseException:
            # interrupted (or the cluster failed): the jobs still running were cancelled and a local cluster's
            # workers stopped; their unfinished .part folders go (finished jobs stay: a re-run skips them)
            with detached():
                remove_stale_parts(out, {j.name for j in todo})
            raise
    result.records = [records[j.name] for j in jobs if j.name in records]
    result.seconds = time.perf_counter() - t0
    return result


def _collect(client, todo, out, records, result, write_manifest, progress, quiet):
    from distributed import as_completed

    futures = {client.submit(run_job, job, str(out), key=f"meshshade-job-{job.name}-{job.param_hash}"): job
               for job in todo}
    bar = Progress("batch", len(todo), "jobs", enabled=bool(progress))
    last = time.monotonic()
    try:
        for fut in as_completed(futures):
            job = futures.pop(fut)
            try:
                rec = fut.result()
            except Exception as exc:  # noqa: BLE001 - the task itself died (workers killed again and again, ...)
                rec = {"name": job.name, "command": job.command, "options": job.options,
                       "param_hash": job.param_hash, "status": "failed", "error": _one_line(exc), "finished": _now(),
                       "outputs": {}}
            records[job.name] = rec
            result.ran.append(job.name)
            if rec.get("status") != "ok":
                result.failed.append(job.name)
                if not quiet:
                    print(f"meshshade: batch: job {job.name} failed: {rec.get('error')}", file=sys.stderr)
            bar.update(1)
            if time.monotonic() - last >= MANIFEST_INTERVAL:
                write_manifest()
                last = time.monotonic()
    except BaseException:
        for fut in futures:
            fut.cancel()
        raise
    finally:
        bar.close()
        write_manifest(final=True)
