"""``meshshade bench``: accuracy against time for every model and knob (thin layer over :mod:`meshshade.bench`).

Its help and arguments are in :mod:`meshshade.cli.arguments.bench`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

import contextlib
import sys

from meshshade.batch.dask_cluster import check_cluster_options, open_client
from meshshade.bench.plan import bench_plan
from meshshade.bench.report import write_bench
from meshshade.bench.runner import run_bench as run_benchmark
from meshshade.cli.options import parse_names
from meshshade.io import output_dir
from meshshade.errors import MeshshadeError


def _progress(line: str) -> None:
    print(f"bench: {line}", file=sys.stderr, flush=True)


def run_bench(args) -> int:
    if args.mc_photons is not None and args.mc_photons < 16:
        raise MeshshadeError("--mc-photons must be at least 16")
    if args.seed < 0:
        raise MeshshadeError(f"--seed must be >= 0, got {args.seed}")
    check_cluster_options(args.scheduler, args.workers)
    plan = bench_plan(quick=args.quick, scenes=parse_names(args.scenes), models=parse_names(args.models),
                      source_model=args.source_model)
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
