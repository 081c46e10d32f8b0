"""How long the command line takes to answer before any work (issue 32: ``--help`` and argument errors in 0.3 s).

Each row is a command run in a fresh process, timed from start to exit, ``--repeats`` times (default 5), the
rows interleaved round by round so that a change in the machine's load touches them all alike; one JSON object per
row on stdout: the median and minimum wall time, and the median less the median of ``python -c pass`` (the
interpreter's own start, measured in the same run). Rows:

* baselines: ``python -c pass``; ``python -c "import numpy"`` (what one heavy library costs here);
* ``meshshade --help``, ``meshshade bake --help``, ``meshshade bake m.obj --bogus`` (an argument error): the
  ``meshshade`` console script next to this Python (else, or with ``--module``, ``python -m meshshade.cli``, which
  follows ``PYTHONPATH``: another checkout is measured so, run from its own folder since ``-m`` puts the working
  directory first); each must stay within ``--limit`` (default 0.3 s), reported as ``within_limit``;
* for scale, ``python -c "import meshshade.cli.bake"``: what a bake imports once its arguments are parsed.

    python tools/benchmarks/bench_startup.py [--repeats 5] [--limit 0.3] [--module]

About 15 s on 2 cores.
"""
from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path


def commands(module: bool = False) -> list[tuple[str, list[str], bool]]:
    """(row name, argv, checked against the limit)."""
    script = None if module else shutil.which("meshshade", path=str(Path(sys.executable).parent))
    cli = [script] if script else [sys.executable, "-m", "meshshade.cli"]
    py = sys.executable
    return [
        ("python -c pass", [py, "-c", "pass"], False),
        ("python -c 'import numpy'", [py, "-c", "import numpy"], False),
        ("meshshade --help", [*cli, "--help"], True),
        ("meshshade bake --help", [*cli, "bake", "--help"], True),
        ("meshshade bake m.obj --bogus", [*cli, "bake", "m.obj", "--bogus"], True),
        ("python -c 'import meshshade.cli.bake'", [py, "-c", "import meshshade.cli.bake"], False),
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5, help="runs of each command (default 5; the median is reported)")
    ap.add_argument("--limit", type=float, default=0.3, help="seconds --help and argument errors may take (0.3)")
    ap.add_argument("--module", action="store_true", help="python -m meshshade.cli instead of the console script")
    args = ap.parse_args(argv)
    rows = commands(args.module)
    times: dict[str, list[float]] = {name: [] for name, _, _ in rows}
    codes: dict[str, set] = {name: set() for name, _, _ in rows}
    for name, cmd, _ in rows:  # one untimed run each: the files in the OS cache, __pycache__ written
        subprocess.run(cmd, capture_output=True)
    for _ in range(args.repeats):
        for name, cmd, _ in rows:
            t0 = time.perf_counter()
            proc = subprocess.run(cmd, capture_output=True)
            times[name].append(time.perf_counter() - t0)
            codes[name].add(proc.returncode)
    python = statistics.median(times["python -c pass"])
    for name, cmd, checked in rows:
        median = statistics.median(times[name])
        row = {"command": name, "median_s": round(median, 4), "min_s": round(min(times[name]), 4),
               "over_python_s": round(median - python, 4), "runs": args.repeats, "exit_codes": sorted(codes[name])}
        if checked:
            row["within_limit"] = median <= args.limit
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
