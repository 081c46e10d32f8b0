"""``meshshade batch``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.batch`)."""
from __future__ import annotations

import argparse

from meshshade.cli.arguments.common import add_cluster_args
from meshshade.names import BATCH_MANIFEST as MANIFEST

HELP = "run a TOML file of bakes, renders, compares, Monte Carlo runs and sweeps on Dask (local or a cluster)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("jobs", metavar="JOBS.toml", help="job file: [[job]] and [[sweep]] entries (docs/batch.md)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help=f"output folder: one folder per job and {MANIFEST}; a re-run skips finished jobs")
    add_cluster_args(p)
    p.add_argument("--dry-run", action="store_true", help="list the jobs and whether each is done; run nothing")
