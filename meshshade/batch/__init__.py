"""Beyond one machine: batches and sweeps of meshshade commands on Dask distributed.

* :mod:`meshshade.batch.jobs`: what a batch runs (:class:`Job`: a name, options and an ``execute(job, folder)``);
  TOML job files of meshshade commands and sweeps are read by :func:`meshshade.cli.jobs.read_jobs`;
* :mod:`meshshade.batch.runner`: :func:`run_batch` (one Dask task and one folder per job, the manifest, skip on
  re-run) and :func:`run_job` (the task);
* :mod:`meshshade.batch.dask_cluster`: the :class:`distributed.Client` (a local cluster or an existing scheduler).

Monte Carlo runs split across workers live with the walk: :mod:`meshshade.montecarlo.distributed`.
"""
from meshshade.batch.dask_cluster import open_client
from meshshade.batch.jobs import Job, JobFileError
from meshshade.batch.runner import BatchResult, run_batch, run_job

__all__ = ["Job", "JobFileError", "BatchResult", "run_batch", "run_job", "open_client"]
