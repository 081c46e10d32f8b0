"""``meshshade bench``: accuracy against time for every model and knob (thin layer over :mod:`meshshade.bench`)."""
from __future__ import annotations

import argparse
import contextlib
import sys

from meshshade.batch.cluster import check_cluster_options, open_client
from meshshade.bench.plan import bench_plan
from meshshade.bench.report import write_bench
from meshshade.bench.runner import run_bench as run_benchmark
from meshshade.cli.options import add_cluster_args, integer, parse_names
from meshshade.io import output_dir
from meshshade.errors import MeshshadeError

HELP = "accuracy vs time of every model and knob against exact or Monte Carlo references"


def add_bench_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (created): accuracy_vs_time.csv, pareto.png, table.md, metadata.json")
    p.add_argument("--quick", action="store_true",
                   help="fewer scenes and knob values, coarser meshes, fewer photons (under 3 min on 2 idle cores)")
    p.add_argument("--seed", type=integer(0), default=0, help="seed of every Monte Carlo run (default 0)")
    p.add_argument("--scenes", metavar="LIST", help="comma list of scene names (default: the mode's set)")
    p.add_argument("--models", metavar="LIST", help="comma list of models (default: every model of the bake)")
    p.add_argument("--near-field", default="point", choices=["point", "beam"],
                   help="the bakes' near field (default point); scenes with a Monte Carlo reference also get rows "
                        "with the other one (knob near_field)")
    p.add_argument("--mc-photons", type=integer(16), default=None, metavar="N",
                   help="photons of each Monte Carlo reference (default 1000000 quick, 4000000 full)")
    add_cluster_args(p)   # the references are split on Dask; every timed run stays in this process


def _progress(line: str) -> None:
    print(f"bench: {line}", file=sys.stderr, flush=True)


def run_bench(args) -> int:
    if args.mc_photons is not None and args.mc_photons < 16:
        raise MeshshadeError("--mc-photons must be at least 16")
    if args.seed < 0:
        raise MeshshadeError(f"--seed must be >= 0, got {args.seed}")
    check_cluster_options(args.scheduler, args.workers)
    plan = bench_plan(quick=args.quick, scenes=parse_names(args.scenes), models=parse_names(args.models),
                      near_field=args.near_field)
    out = output_dir(args.out)
    with contextlib.ExitStack() as stack:
        client = (stack.enter_context(open_client(args.scheduler, args.workers, quiet=args.quiet))
                  if args.scheduler is not None or args.workers is not None else None)
        result = run_benchmark(plan, seed=args.seed, mc_photons=args.mc_photons, quick=args.quick,
                               progress=None if args.quiet else _progress, client=client)
    paths = write_bench(result, out)
    if not args.quiet:
        print(f"{len(result.rows)} measurements in {result.metadata['wall_time_s']:.0f} s; wrote "
              + ", ".join(str(p) for p in paths.values()))
    return 0
