"""`meshshade bench`: accuracy against time for every model and knob (thin layer over meshshade.bench.runner)."""
from __future__ import annotations

import argparse
import sys


def add_bench_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (created): accuracy_vs_time.csv, pareto.png, table.md, metadata.json")
    p.add_argument("--quick", action="store_true",
                   help="fewer scenes and knob values, coarser meshes, fewer photons (under 3 min on 2 idle cores)")
    p.add_argument("--seed", type=int, default=0, help="seed of every Monte Carlo run (default 0)")
    p.add_argument("--scenes", metavar="LIST", help="comma list of scene names (default: the mode's set)")
    p.add_argument("--models", metavar="LIST", help="comma list of models (default: every model of the bake)")
    p.add_argument("--mc-photons", type=int, default=None, metavar="N",
                   help="photons of each Monte Carlo reference (default 1000000 quick, 4000000 full)")


def _names(text):
    return None if text is None else [x.strip() for x in text.split(",") if x.strip()]


def run_bench(args) -> int:
    from pathlib import Path  # noqa: PLC0415

    from meshshade.bench import runner as bench  # noqa: PLC0415
    from meshshade.bench import report as bench_report  # noqa: PLC0415
    from meshshade.errors import MeshshadeError, OutputError  # noqa: PLC0415

    if args.mc_photons is not None and args.mc_photons < 16:
        raise MeshshadeError("--mc-photons must be at least 16")
    if args.seed < 0:
        raise MeshshadeError(f"--seed must be >= 0, got {args.seed}")
    plan = bench.bench_plan(quick=args.quick, scenes=_names(args.scenes), models=_names(args.models))
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output folder {out}: {exc.strerror}") from None
    progress = None if args.quiet else (lambda line: print(f"bench: {line}", file=sys.stderr, flush=True))
    result = bench.run_bench(plan, seed=args.seed, mc_photons=args.mc_photons, quick=args.quick, progress=progress)
    paths = bench_report.write_bench(result, out)
    if not args.quiet:
        print(f"{len(result.rows)} measurements in {result.metadata['wall_time_s']:.0f} s; wrote "
              + ", ".join(str(p) for p in paths.values()))
    return 0
