"""How long ``meshshade demo`` takes the first time (numba compiles) and after (numba's cache warm) (issue 32).

Each run is a fresh process of the ``meshshade`` console script next to this Python (``--module``:
``python -m meshshade.cli``), ``meshshade demo --quiet --out <tmp>``, with ``NUMBA_CACHE_DIR`` set to a folder of
this script's own (meshshade leaves a user-set one alone):

* cold: a new, empty folder: what the first run after ``pip install -e .`` (or after any change to meshshade's
  sources, which keys its cache folder) pays;
* warm: ``--warm`` more runs (default 2) with the same folder.

meshshade's derived-asset cache (``MESHSHADE_ASSET_CACHE``: the volume transport's tetrahedral meshes) goes to a
folder of the script's too, empty for the cold run, as after an install. The runs use a copy of the ``meshshade``
package (without ``__pycache__``) taken at the start, found first through ``PYTHONPATH``: numba's cache index
checks each source file's modification time, so an edit or a ``git`` operation in the checkout during the run
would otherwise make the warm runs compile again (``--no-snapshot``: run the checkout's own sources).

Each run's CPU time (user + system over all its threads, from ``getrusage``) is recorded beside its wall time:
numba compiles on one thread, so on a shared machine the CPU seconds of the compilation (cold less warm) move
less with the other jobs than the wall seconds do. For the same run's scale, two baselines are timed
(``--baseline-repeats`` each, the median reported): ``python -c pass`` and ``python -c "import numba"`` (one
heavy import). The load average before and after is recorded: the machine may be shared, so the ratios
(cold / warm, cold / import numba) travel better than seconds.

After the cold run the cache folder is counted: one ``*.nbi`` index per cached compiled function and one
``*.nbc`` per specialisation (signature) of it, listed per function (``module.function``) with ``--functions``.
Functions compiled without ``cache=True`` leave no file; ``--by-function`` counts them too: the cold run then goes
through a small wrapper (``python -c``, the same ``main`` as the console script) that records numba's
``numba:compile`` events and reports, per function, the signatures compiled and the compile time (wall, and CPU
seconds of the compiling thread) less that of the functions it compiled in turn (numba compiles a callee inside its
caller's compilation).

    python tools/benchmarks/bench_first_run.py [--warm 2] [--small] [--functions] [--by-function] [--source DIR]

One JSON object on stdout. About 2-3 minutes on 2 cores (the cold run dominates).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

#: run as ``python -c``: record numba's compile events, run the CLI, write them as JSON to argv[1]
RECORDER = r"""
import json, sys, threading, time
from numba.core import event
records, stacks = [], {}
class Recorder(event.Listener):
    def on_start(self, ev):
        stacks.setdefault(threading.get_ident(), []).append([time.perf_counter(), 0.0, time.thread_time(), 0.0])
    def on_end(self, ev):
        stack = stacks[threading.get_ident()]
        t0, inner, c0, inner_cpu = stack.pop()
        total = time.perf_counter() - t0
        cpu = time.thread_time() - c0
        if stack:
            stack[-1][1] += total
            stack[-1][3] += cpu
        d = ev.data or {}
        disp = d.get("dispatcher")
        py = getattr(disp, "py_func", None)
        name = f"{py.__module__}.{py.__qualname__}" if py is not None else repr(disp)
        records.append({"function": name, "signature": str(tuple(d.get("args", ()))),
                        "total_s": total, "self_s": total - inner, "self_cpu_s": cpu - inner_cpu})
event.register("numba:compile", Recorder())
out = sys.argv[1]
sys.argv = ["meshshade", *sys.argv[2:]]
from meshshade.cli.main import main
try:
    code = main()
finally:
    with open(out, "w") as fh:
        json.dump(records, fh)
sys.exit(code)
"""

_NBI = re.compile(r"^(?P<func>.+)-(?P<line>\d+)\.py\d+\.nbi$")
_NBC = re.compile(r"^(?P<func>.+)-(?P<line>\d+)\.py\d+\.\d+\.nbc$")


def cli(module: bool) -> list[str]:
    script = None if module else shutil.which("meshshade", path=str(Path(sys.executable).parent))
    return [script] if script else [sys.executable, "-m", "meshshade.cli"]


def clean_env(cache_dir: str, asset_dir: str | None = None, source: str | None = None) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "MESHSHADE_"))}
    env["NUMBA_CACHE_DIR"] = cache_dir
    if asset_dir:
        env["MESHSHADE_ASSET_CACHE"] = asset_dir
    if source:
        env["PYTHONPATH"] = os.pathsep.join([source, *filter(None, [os.environ.get("PYTHONPATH")])])
    return env


def snapshot(dest: Path, source: str | None = None) -> str:
    """Copy the ``meshshade`` package (no ``__pycache__``) of folder ``source`` (default: the one this Python
    imports) into ``dest``; returns the folder to put on ``PYTHONPATH``."""
    if source:
        package = Path(source) / "meshshade"
    else:
        import importlib.util

        package = Path(importlib.util.find_spec("meshshade").submodule_search_locations[0])
    shutil.copytree(package, dest / "meshshade", ignore=shutil.ignore_patterns("__pycache__"))
    return str(dest)


def timed(cmd: list[str], env: dict) -> tuple[float, float, subprocess.CompletedProcess]:
    """(wall seconds, CPU seconds of the child (user + system, all its threads), the finished process)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=tempfile.gettempdir())
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), proc


def cache_contents(folder: Path) -> dict:
    """Cached functions (``*.nbi``) and specialisations (``*.nbc``) under ``folder``, per ``module.function``.

    numba names its files ``<file stem>.<qualname>-<line>.py<XY>.nbi`` in a folder that mirrors the source's path."""
    per_function: Counter = Counter()
    indexes = set()
    for path in folder.rglob("*.nb[ic]"):
        # numba's folder for a source folder: its name, "_", a hash of its full path
        package = ".".join(re.sub(r"_[0-9a-f]{40}$", "", part) for part in path.parent.relative_to(folder).parts)
        m = _NBI.match(path.name) or _NBC.match(path.name)
        if m is None:
            continue
        key = f"{package}.{m['func']}" if package else m["func"]
        if path.suffix == ".nbi":
            indexes.add(key + f"-{m['line']}")
        else:
            per_function[key] += 1
    return {"cached_functions": len(indexes), "specialisations": sum(per_function.values()),
            "per_function": dict(sorted(per_function.items(), key=lambda kv: (-kv[1], kv[0])))}


def summarise_events(records: list[dict]) -> dict:
    """Per function: signatures compiled and compile time, wall and CPU seconds of the compiling thread (self: less
    its callees' compilations; the CPU seconds move less with other jobs on a shared machine), ordered by CPU."""
    funcs: dict[str, dict] = {}
    for r in records:
        f = funcs.setdefault(r["function"], {"compilations": 0, "self_s": 0.0, "self_cpu_s": 0.0, "signatures": []})
        f["compilations"] += 1
        f["self_s"] += r["self_s"]
        f["self_cpu_s"] += r.get("self_cpu_s", 0.0)
        f["signatures"].append(r["signature"])
    for f in funcs.values():
        f["self_s"] = round(f["self_s"], 3)
        f["self_cpu_s"] = round(f["self_cpu_s"], 3)
    ordered = dict(sorted(funcs.items(), key=lambda kv: (-kv[1]["self_cpu_s"], -kv[1]["self_s"])))
    return {"compiled_functions": len(funcs), "compilations": len(records),
            "compile_self_s_total": round(sum(r["self_s"] for r in records), 2),
            "compile_self_cpu_s_total": round(sum(r.get("self_cpu_s", 0.0) for r in records), 2),
            "functions": ordered}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--warm", type=int, default=2, help="warm runs after the cold one (default 2)")
    ap.add_argument("--baseline-repeats", type=int, default=3, help="runs of each baseline (default 3)")
    ap.add_argument("--small", action="store_true", help="meshshade demo --small (what CI runs)")
    ap.add_argument("--functions", action="store_true", help="list the cached specialisations per function")
    ap.add_argument("--by-function", action="store_true",
                    help="cold run through a wrapper recording numba's compile events: time per function")
    ap.add_argument("--module", action="store_true", help="python -m meshshade.cli instead of the console script")
    ap.add_argument("--no-snapshot", action="store_true", help="run the checkout's sources, not a copy of them")
    ap.add_argument("--source", metavar="DIR", help="run a copy of DIR/meshshade (another checkout, an old copy)")
    ap.add_argument("--keep", metavar="DIR", help="keep the cache folder (and outputs) here instead of a temporary")
    args = ap.parse_args(argv)

    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench-first-run-"))
    work.mkdir(parents=True, exist_ok=True)
    cache = work / "numba-cache"
    if cache.exists() and any(cache.iterdir()):
        ap.error(f"{cache} is not empty: the cold run needs an empty cache folder")
    cache.mkdir(exist_ok=True)
    demo_args = ["demo", "--quiet"] + (["--small"] if args.small else [])
    load_before = os.getloadavg()
    result: dict = {"command": " ".join(["meshshade", *demo_args, "--out", "<tmp>"]),
                    "NUMBA_CACHE_DIR": "a new empty folder (cold), then the same folder (warm)",
                    "cpus": os.cpu_count(), "load_avg_before": [round(x, 2) for x in load_before]}
    try:
        # baselines, each with a throwaway cache folder
        base = {}
        scratch = tempfile.mkdtemp(prefix="bench-first-run-scratch-")
        for name, code in (("python -c pass", "pass"), ("python -c 'import numba'", "import numba")):
            times = [timed([sys.executable, "-c", code], clean_env(scratch))[0] for _ in range(args.baseline_repeats)]
            base[name] = round(statistics.median(times), 3)
        shutil.rmtree(scratch, ignore_errors=True)
        result["baselines_s"] = base
        # cold
        source = None if args.no_snapshot else snapshot(work / "source", args.source)
        result["source"] = str(Path(args.source).resolve() / "meshshade") if args.source else "this checkout"
        env = clean_env(str(cache), str(work / "asset-cache"), source)
        if args.by_function:
            events = work / "compile_events.json"
            cmd = [sys.executable, "-c", RECORDER, str(events), *demo_args, "--out", str(work / "out-cold")]
        else:
            cmd = [*cli(args.module), *demo_args, "--out", str(work / "out-cold")]
        cold, cold_cpu, proc = timed(cmd, env)
        if proc.returncode != 0:
            print(proc.stdout[-2000:], proc.stderr[-4000:], file=sys.stderr)
            raise SystemExit(f"cold run failed with exit code {proc.returncode}")
        counts = cache_contents(cache)
        # warm
        warm, warm_cpu = [], []
        for i in range(args.warm):
            t, cpu, proc = timed([*cli(args.module), *demo_args, "--out", str(work / f"out-warm{i}")], env)
            if proc.returncode != 0:
                print(proc.stderr[-4000:], file=sys.stderr)
                raise SystemExit(f"warm run {i} failed with exit code {proc.returncode}")
            warm.append(round(t, 2))
            warm_cpu.append(round(cpu, 2))
        warm_med = statistics.median(warm) if warm else float("nan")
        warm_cpu_med = statistics.median(warm_cpu) if warm_cpu else float("nan")
        after = cache_contents(cache)
        result.update({
            "cold_s": round(cold, 2), "warm_s": warm, "warm_median_s": round(warm_med, 2),
            "cold_cpu_s": round(cold_cpu, 2), "warm_cpu_s": warm_cpu,
            "compile_s_estimate": round(cold - warm_med, 2),
            "compile_cpu_s_estimate": round(cold_cpu - warm_cpu_med, 2),
            "cold_over_warm": round(cold / warm_med, 2),
            "cold_over_import_numba": round(cold / base["python -c 'import numba'"], 1),
            "warm_over_import_numba": round(warm_med / base["python -c 'import numba'"], 1),
            "cached_functions": counts["cached_functions"], "specialisations": counts["specialisations"],
            "warm_runs_added_specialisations": after["specialisations"] - counts["specialisations"],
        })
        if args.functions:
            result["per_function"] = counts["per_function"]
        if args.by_function:
            result["compile_events"] = summarise_events(json.loads(events.read_text()))
    finally:
        result["load_avg_after"] = [round(x, 2) for x in os.getloadavg()]
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
