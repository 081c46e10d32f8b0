"""How the Monte Carlo walk's throughput grows with threads, as JSON (issue 30).

    python tools/benchmarks/bench_mc_scaling.py [--threads 1,2] [--repeats 5] [--scenes spot_point,sphere20_sun,...]

Every scene is walked with the same photons and seed at each thread count (``numba.set_num_threads`` in this
process; NUMBA_NUM_THREADS bounds it), the thread counts alternating within each repeat so that a noisy machine
loads them alike; the median over the repeats is reported. The work is identical at every thread count (the
engine is bitwise independent of it, checked here: ``identical``), so events/s ratios are speedups.

``ceiling`` is a loop of pure arithmetic timed the same way: the most any code gains on this machine (shared or
throttled cores show here, not in the engine). Per scene and thread count: wall seconds of the walk (median),
events/s, ``speedup`` over one thread (medians), ``speedup_of_fastest`` (the fastest repeat of each: the least
disturbed), ``efficiency`` = speedup / threads, ``cpu_per_wall`` (process CPU over wall: how
many cores were busy) and the fraction of events that were boundary tests.

Scenes (skin1, Jensen et al. 2001; ../shared/meshes where named, skipped if absent):
spot_point (spot.obj scaled to 50 mm, a point light 30 mm above), hand_point (hand.obj, 150 mm, point light),
armadillo_point (armadillo.obj, 100 mm, point light), sphere20_sun (20 mm icosphere level 5, sun from above),
mcml_slab (MCML's semi-infinite box test, a pencil beam).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
import warnings

import numba
import numpy as np
from numba import njit, prange

from meshshade.bench.scenes import shared_meshes_dir
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box, icosphere
from meshshade.io import read_mesh_arrays
from meshshade.light import BeamLight, DirectionalLight, PointLight
from meshshade.materials import Material, material_from_options
from meshshade.montecarlo import MCOptions, simulate

SKIN1 = material_from_options("skin1")


def _shared(name, size_mm):
    path = shared_meshes_dir() / name
    if not path.exists():
        return None
    V, F = read_mesh_arrays(path)
    V = (V - 0.5 * (V.min(axis=0) + V.max(axis=0))) * (size_mm / np.ptp(V, axis=0).max())
    return Mesh.from_arrays(V, F)


def _point_above(mesh, height):
    c = mesh.bbox.mean(axis=0)
    return PointLight((c[0] + 0.1 * height, c[1] + 0.2 * height, mesh.bbox[1, 2] + height), 1000.0)


def scenes():
    """name -> (mesh builder, material, light builder, photons)."""
    return {
        "spot_point": (lambda: _shared("spot.obj", 50.0), SKIN1, lambda m: _point_above(m, 30.0), 400_000),
        "hand_point": (lambda: _shared("hand.obj", 150.0), SKIN1, lambda m: _point_above(m, 60.0), 400_000),
        "armadillo_point": (lambda: _shared("armadillo.obj", 100.0), SKIN1, lambda m: _point_above(m, 50.0),
                            400_000),
        "sphere20_sun": (lambda: Mesh.from_arrays(*icosphere(20.0, 5)), SKIN1,
                         lambda m: DirectionalLight((0.0, 0.0, -1.0), 1.0), 400_000),
        "mcml_slab": (lambda: Mesh.from_arrays(*box((10.0, 10.0, 5.0))), Material(9.0, 1.0, eta=1.5),
                      lambda m: BeamLight((0.123, 0.0456, 10.0), (0, 0, -1)), 1_000_000),
    }


@njit(parallel=True, cache=True)
def _arithmetic(n):
    s = 0.0
    for i in prange(n):
        x = 0.0
        for k in range(2000):
            x += math.log(1.0 + ((i * 7 + k) % 1000) * 1e-3)
        s += x
    return s


def _ceiling(threads, repeats):
    _arithmetic(64)
    wall = {t: [] for t in threads}
    for _ in range(repeats):
        for t in threads:
            numba.set_num_threads(t)
            t0 = time.perf_counter()
            _arithmetic(100_000)
            wall[t].append(time.perf_counter() - t0)
    med = {t: statistics.median(wall[t]) for t in threads}
    fast = {t: min(wall[t]) for t in threads}
    return {str(t): {"seconds": round(med[t], 3), "speedup": round(med[threads[0]] / med[t] * threads[0], 3),
                     "speedup_of_fastest": round(fast[threads[0]] / fast[t] * threads[0], 3)} for t in threads}


class StageTimer:
    """Wall seconds spent in each stage of the pooled engine (``--profile``): the compiled emission, the walk,
    the per-batch reduction; the rest of a run is Python between the rounds and the set-up."""

    def __init__(self):
        from meshshade.montecarlo import emission, engine, kernels

        self.seconds = {}
        self._patches = [(emission.EmitterKernel, "emit_into", "emission"), (engine, "walk_parallel", "walk"),
                         (kernels, "reduce_round", "reduce")]
        for owner, attr, stage in self._patches:
            real = getattr(owner, attr)
            setattr(owner, attr, self._timed(real, stage))

    def _timed(self, real, stage):
        def run(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return real(*args, **kwargs)
            finally:
                self.seconds[stage] = self.seconds.get(stage, 0.0) + time.perf_counter() - t0
        return run

    def take(self):
        out, self.seconds = self.seconds, {}
        return out


def bench_scene(name, build, mat, make_light, photons, threads, repeats, timer=None):
    mesh = build()
    if mesh is None:
        return {"skipped": f"{name}: mesh not found under {shared_meshes_dir()}"}
    light = make_light(mesh)
    kw = dict(photons=photons, seed=7, beam_distances=False, keep_beam_exits=False)
    numba.set_num_threads(max(threads))
    simulate(mesh, mat, [light], MCOptions(**{**kw, "photons": 20_000}))   # compile / load the kernels, the memory
    rows = {t: [] for t in threads}
    first = {}
    for r in range(repeats):
        for t in (threads if r % 2 == 0 else threads[::-1]):
            numba.set_num_threads(t)
            if timer is not None:
                timer.take()
            res = simulate(mesh, mat, [light], MCOptions(**kw))
            rows[t].append((res.seconds, res.cpu_seconds, res.events, res.boundary_events,
                            timer.take() if timer is not None else {}))
            first.setdefault(t, res.face_power)
    identical = all(np.array_equal(first[t], first[threads[0]]) for t in threads)
    out = {"vertices": int(mesh.n_vertices), "faces": int(mesh.n_faces), "photons_per_channel": photons,
           "identical_across_threads": bool(identical), "threads": {}}
    base = base_min = None
    for t in threads:
        sec = statistics.median(x[0] for x in rows[t])
        fastest = min(x[0] for x in rows[t])
        cpu = statistics.median(x[1] / x[0] for x in rows[t])
        ev, bd = rows[t][0][2], rows[t][0][3]
        eps = ev / sec
        base = base or eps / t   # the first thread count's rate per thread
        base_min = base_min or ev / fastest / t
        out["threads"][str(t)] = {"seconds": round(sec, 3), "events": int(ev), "events_per_second": float(f"{eps:.4g}"),
                                  "speedup": round(eps / base, 3), "efficiency": round(eps / base / t, 3),
                                  "speedup_of_fastest": round(ev / fastest / base_min, 3),
                                  "cpu_per_wall": round(cpu, 2), "boundary_fraction": round(bd / ev, 4),
                                  "all_seconds": [round(x[0], 3) for x in rows[t]]}
        if timer is not None:   # median seconds per stage; "other": the run's seconds not in a stage
            stages = {k: statistics.median(x[4].get(k, 0.0) for x in rows[t]) for k in ("emission", "walk", "reduce")}
            stages["other"] = sec - sum(stages.values())
            out["threads"][str(t)]["stage_seconds"] = {k: round(v, 3) for k, v in stages.items()}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    cores = os.cpu_count() or 1
    default = sorted({1, 2, *[t for t in (4, 8, 12, 16) if t <= cores], cores})
    ap.add_argument("--threads", default=",".join(map(str, default)), help="thread counts (first: the baseline)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--scenes", default="spot_point,hand_point,sphere20_sun,mcml_slab")
    ap.add_argument("--photons-scale", type=float, default=1.0, help="multiply every scene's photon count")
    ap.add_argument("--profile", action="store_true", help="also the wall seconds of each stage of the engine")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    threads = [int(t) for t in args.threads.split(",")]
    if max(threads) > numba.config.NUMBA_NUM_THREADS:
        sys.exit(f"--threads up to {max(threads)} needs NUMBA_NUM_THREADS >= {max(threads)} "
                 f"(it is {numba.config.NUMBA_NUM_THREADS})")
    out = {"machine": platform.processor() or platform.machine(), "cpus": cores,
           "numba_threading_layer": None, "load_average_before": os.getloadavg(), "repeats": args.repeats,
           "ceiling": _ceiling(threads, args.repeats), "scenes": {}}
    out["numba_threading_layer"] = numba.threading_layer()
    all_scenes = scenes()
    timer = StageTimer() if args.profile else None
    for name in args.scenes.split(","):
        build, mat, light, photons = all_scenes[name]
        out["scenes"][name] = bench_scene(name, build, mat, light, int(photons * args.photons_scale), threads,
                                          args.repeats, timer)
        print(json.dumps({name: out["scenes"][name]}), file=sys.stderr, flush=True)
    out["load_average_after"] = os.getloadavg()
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
