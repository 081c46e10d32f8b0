"""``meshshade batch``: run a TOML file of jobs and sweeps on Dask distributed (thin layer over
:func:`meshshade.cli.jobs.read_jobs` and :func:`meshshade.batch.runner.run_batch`).

Exit codes: 0 when every job is done, 1 when some jobs failed (each is one line on stderr and in the manifest;
re-running the command retries them), 2 when the batch could not run at all (a bad job file or option, an output
folder that cannot be made, an unreachable scheduler).


Its help and arguments are in :mod:`meshshade.cli.arguments.batch`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

from meshshade.batch import runner
from meshshade.batch.runner import job_status
from meshshade.cli.jobs import read_jobs


def run_batch(args) -> int:
    jobs = read_jobs(args.jobs)
    if args.dry_run:
        for job in jobs:
            state = "done" if job_status(job, args.out) is not None else "to run"
            print(f"{job.name}\t{job.command}\t{state}")
        return 0
    result = runner.run_batch(jobs, args.out, scheduler=args.scheduler, workers=args.workers, progress=not args.quiet,
                       quiet=args.quiet)
    if not args.quiet:
        print(result.describe())
    return 0 if result.ok else 1
