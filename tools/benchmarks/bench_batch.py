"""Benchmark batches on Dask distributed (issue 15): a sweep of bake jobs and a Monte Carlo run, 1 vs 2 workers.

Rows (JSON, one object per line on stdout):

* ``sweep``: ``--jobs`` bake jobs (default 12: 2 procedural meshes x 3 materials x 2 lights, model auto,
  icospheres of ``--level``) run four ways on the same jobs, each into a fresh folder:
  ``in-process`` (``run_job`` in a loop here, geometry reused between jobs, all cores to numba),
  ``in-process, no reuse`` (the cache cleared before every job: what reuse saves),
  ``dask, 1 worker`` (a LocalCluster of one process with all cores) and ``dask, 2 workers`` (two processes,
  ``cores // 2`` numba threads each). Wall time of the batch (the cluster is started before the clock; its start-up
  is its own row ``cluster_start``), the overhead per job of Dask against in-process, and the speed-ups. The
  outputs of every way are checked to be the same (radiance to 1e-6 relative).
* ``mc``: one Monte Carlo run of ``--photons`` photons (default 1e7; sigma_s' = 1, sigma_a = 0.01 /mm, eta 1.3,
  a level-4 icosphere of 10 mm, a sun light), in-process vs split on 1 and 2 workers
  (``simulate(..., client=)``, :mod:`meshshade.montecarlo.distributed`); the tallies of the 1- and 2-worker
  runs are checked to be identical.
* ``sizes``: the sweep's in-process and 2-worker times at icosphere levels 3..--level (how the overhead share
  shrinks as jobs grow).

    python tools/benchmarks/bench_batch.py [--jobs 12] [--level 4] [--photons 1e7] [--repeat 2] [--quick]
                                           [--skip mc,sizes]
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from meshshade import memo
from meshshade.batch import open_client, run_batch, run_job
from meshshade.cli.jobs import command_job
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, torus
from meshshade.io import read_baked_ply, write_ply
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions

MATERIALS = ("skin1", "marble", "ketchup")
LIGHTS = ("directional:0.3,-0.4,-1", "directional:-1,0.2,-0.3")


def emit(row):
    print(json.dumps(row), flush=True)


def make_jobs(folder: Path, level: int, n_jobs: int):
    """``n_jobs`` bake jobs over 2 meshes x materials x lights (repeated with other seeds of light if more)."""
    V, F = icosphere(20.0, level)
    write_ply(folder / f"ball{level}.ply", V, F)
    Vt, Ft = torus(20.0, 8.0, 16 * 2 ** (level - 2), 8 * 2 ** (level - 2))
    write_ply(folder / f"torus{level}.ply", Vt, Ft)
    combos = list(itertools.product((f"ball{level}", f"torus{level}"), MATERIALS, LIGHTS))
    jobs = []
    for i in range(n_jobs):
        mesh, material, light = combos[i % len(combos)]
        jobs.append(command_job(f"{mesh}-{material}-{i}", "bake", mesh=str(folder / f"{mesh}.ply"),
                                material=material, light=light, model="auto"))
    return jobs


def _timed(fn):
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def _in_process(jobs, out, reuse):
    memo.clear()
    for job in jobs:
        if not reuse:
            memo.clear()
        rec = run_job(job, out)
        assert rec["status"] == "ok", rec


def _warm(job, base):
    """A worker's warm-up bake, into its own folder."""
    return run_job(job, f"{base}-{os.getpid()}")


def _same_outputs(jobs, a: Path, b: Path) -> float:
    worst = 0.0
    for job in jobs:
        ra = read_baked_ply(a / job.name / "bake.ply")[1]
        rb = read_baked_ply(b / job.name / "bake.ply")[1]
        worst = max(worst, float(np.max(np.abs(ra - rb) / np.maximum(np.abs(rb), 1e-300))))
    return worst


def sweep(args, tmp: Path, level: int, n_jobs: int, kinds=("in-process", "no-reuse", "dask-1", "dask-2")):
    folder = tmp / f"sweep{level}"
    folder.mkdir()
    jobs = make_jobs(folder, level, n_jobs)
    warm = jobs[0]   # numba caches loaded and first tables built, here and in every worker, before the clocks
    run_job(warm, tmp / f"warm{level}")
    rows, times = [], {}
    R = range(args.repeat)   # each way timed args.repeat times into fresh folders; the minimum is reported
    if "in-process" in kinds:
        times["in-process"] = min(_timed(lambda: _in_process(jobs, tmp / f"ip{level}-{r}", True))[1] for r in R)
    if "no-reuse" in kinds:
        times["in-process, no reuse"] = min(_timed(lambda: _in_process(jobs, tmp / f"nr{level}-{r}", False))[1]
                                            for r in R)
    for n in (1, 2):
        if f"dask-{n}" not in kinds:
            continue
        t0 = time.perf_counter()
        with open_client(workers=n, quiet=True) as client:
            start = time.perf_counter() - t0
            client.run(_warm, warm, str(tmp / f"warm{level}-w"))
            best = float("inf")
            for r in R:
                client.run(memo.clear)   # no geometry kept from before (the in-process runs start clear too)
                res, t = _timed(lambda: run_batch(jobs, tmp / f"d{n}-{level}-{r}", client=client, progress=False,
                                                  quiet=True))
                assert res.ok, res.failed
                best = min(best, t)
            times[f"dask, {n} worker(s)"] = best
        rows.append({"kind": "cluster_start", "workers": n, "seconds": round(start, 3)})
    base = tmp / f"ip{level}-0"
    worst = max((_same_outputs(jobs, base, tmp / f"d{n}-{level}-0") for n in (1, 2) if f"dask-{n}" in kinds),
                default=0.0)
    ip = times.get("in-process")
    row = {"kind": "sweep", "level": level, "vertices": int(icosphere(20.0, level)[0].shape[0]), "jobs": n_jobs,
           "cores": os.cpu_count(), "seconds": {k: round(v, 3) for k, v in times.items()},
           "max_rel_difference_vs_in_process": worst}
    if ip and "dask, 1 worker(s)" in times:
        row["dask_overhead_per_job_s"] = round((times["dask, 1 worker(s)"] - ip) / n_jobs, 4)
    if "dask, 2 worker(s)" in times:
        if "dask, 1 worker(s)" in times:
            row["speedup_2_vs_1_workers"] = round(times["dask, 1 worker(s)"] / times["dask, 2 worker(s)"], 3)
        if ip:
            row["speedup_2_workers_vs_in_process"] = round(ip / times["dask, 2 worker(s)"], 3)
    if ip and "in-process, no reuse" in times:
        row["reuse_saves"] = round(1 - ip / times["in-process, no reuse"], 3)
    rows.append(row)
    return rows


def monte_carlo(args):
    from meshshade.montecarlo.simulation import simulate

    mesh = Mesh(*icosphere(10.0, 4))
    mat = Material([1.0, 1.0, 1.0], [0.01, 0.01, 0.01], eta=1.3, name="sigma_s'=1, sigma_a=0.01")
    sun = DirectionalLight((0.3, -0.4, -1.0), 1.0)
    photons = int(args.photons)
    simulate(mesh, mat, [sun], MCOptions(photons=20_000, seed=1))               # numba caches loaded here
    res, t_in = _timed(lambda: simulate(mesh, mat, [sun], MCOptions(photons=photons, seed=1)))
    row = {"kind": "mc", "photons": photons, "vertices": mesh.n_vertices, "seconds": {"in-process": round(t_in, 3)}}
    tallies = {}
    for n in (1, 2):
        with open_client(workers=n, quiet=True) as client:
            simulate(mesh, mat, [sun], MCOptions(photons=20_000, seed=1), client=client)   # workers load their caches
            r, t = _timed(lambda: simulate(mesh, mat, [sun], MCOptions(photons=photons, seed=1), client=client))
        row["seconds"][f"dask, {n} worker(s)"] = round(t, 3)
        tallies[n] = r.face_power
    row["identical_1_vs_2_workers"] = bool(np.array_equal(tallies[1], tallies[2]))
    row["max_rel_difference_vs_in_process"] = float(np.max(np.abs(tallies[2] - res.face_power)
                                                           / np.maximum(np.abs(res.face_power), 1e-300)))
    row["speedup_2_vs_1_workers"] = round(row["seconds"]["dask, 1 worker(s)"] / row["seconds"]["dask, 2 worker(s)"], 3)
    row["speedup_2_workers_vs_in_process"] = round(t_in / row["seconds"]["dask, 2 worker(s)"], 3)
    return [row]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--jobs", type=int, default=12)
    p.add_argument("--level", type=int, default=4, help="icosphere level of the sweep's meshes (and the top size)")
    p.add_argument("--photons", type=float, default=1e7)
    p.add_argument("--repeat", type=int, default=2, help="timings per way (the minimum is reported)")
    p.add_argument("--quick", action="store_true", help="4 jobs at level 3, 1e5 photons, no size series")
    p.add_argument("--skip", default="", help="comma-separated parts to skip: sweep, mc, sizes")
    args = p.parse_args(argv)
    if args.quick:
        args.jobs, args.level, args.photons = 4, 3, 1e5
    skip = set(filter(None, args.skip.split(",")))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if "sweep" not in skip:
            for row in sweep(args, tmp, args.level, args.jobs):
                emit(row)
        if "mc" not in skip:
            for row in monte_carlo(args):
                emit(row)
        if "sizes" not in skip and not args.quick:
            for level in range(3, args.level):
                for row in sweep(args, tmp, level, args.jobs, kinds=("in-process", "dask-2")):
                    emit(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
