"""Accuracy versus time (`meshshade bench`): scenes as data, a plan of runs, the runner, exact and Monte Carlo
references, reports.

``plan = bench_plan(quick=...)``, ``result = run_bench(plan, seed=...)``, ``write_bench(result, out_dir)``;
modules: :mod:`~meshshade.bench.scenes`, :mod:`~meshshade.bench.plan`, :mod:`~meshshade.bench.runner`,
:mod:`~meshshade.bench.references`, :mod:`~meshshade.bench.report`.
"""
from meshshade.bench.plan import FULL, KNOBS, NO_SERIES, QUICK, BenchConfig, Run, bake_defaults, bench_plan
from meshshade.bench.report import FILES, write_bench
from meshshade.bench.runner import COLUMNS, BenchResult, machine_info, run_bench
from meshshade.bench.scenes import MATERIAL, SCENES, Scene, shared_meshes_dir

__all__ = [
    "BenchConfig", "BenchResult", "COLUMNS", "FILES", "FULL", "KNOBS", "MATERIAL", "NO_SERIES", "QUICK", "Run",
    "SCENES", "Scene", "bake_defaults", "bench_plan", "machine_info", "run_bench", "shared_meshes_dir",
    "write_bench",
]
