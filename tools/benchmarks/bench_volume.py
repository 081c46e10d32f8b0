"""The default bake (the volume transport) against Monte Carlo: accuracy, wall time, and how its cost grows (issues
29, 40).

Rows (JSON, one object per line on stdout):

* ``accuracy`` per scene: the default ``bake`` from scratch (a fresh volume transport) and again reusing it (the
  same process: what a second light set costs), ``mc --photons 2e6`` (seed 202) and a reference Monte Carlo of
  ``--reference-photons`` (seed 101, kept in the asset cache ``bench-references`` between runs); the bake's side is
  its exitance averaged over each vertex's patch as the Monte Carlo tallies it (``BakeResult.patch_averaged``,
  eq. (104)), like with like. Errors: mean
  |M / ref - 1| per channel over (a) *lit* vertices (an unshadowed entry sample of positive power) and (b)
  *unlit* vertices whose reference is above 1e-2 of the channel's peak (light that crossed the body or went round
  it), for the bake and the 2e6-photon Monte Carlo alike, with wall times and their ratios (same run).
* ``cli`` per scene (``--cli``): ``meshshade bake`` and ``meshshade mc --photons 2e6`` as a user runs them, each a
  fresh process (start, imports and compiled-code loading included; numba's cache warmed by a first run that is
  not counted), the fastest of ``--repeats``, and their ratio.
* ``scaling``: the head (200 mm, skin1, the sun) loop-subdivided 0 .. ``--levels`` times: the default bake's wall
  time from scratch, its stages and its peak resident memory (each size in a fresh process, with
  NUMBA_NUM_THREADS set to each of ``--threads``), and the fitted cost exponent per thread count; with several
  thread counts, ``threads`` rows: per size, the whole bake's and each stage's speed-up from the first thread count
  to the others (the stages over 0.3 s below 1.5x listed); the thread counts are interleaved and each repeated
  ``--repeats`` times (up to 566k vertices), the fastest kept;
* ``cli-scaling`` (``--cli-scaling``): the same sizes through the command line, as a user runs them: ``meshshade
  bake head.ply`` in a fresh process (start, imports, reading the file, writing the result), its wall time and
  peak resident memory (the child's, from the operating system), at each of ``--threads``.

Scenes (the sun along (0.3, -0.4, -0.866) unless said): sphere20 (an icosphere of radius 20 mm, level 5, 10k
vertices, skin1, the sun from above), spot50 (spot.obj at 50 mm, skin1), head200 (the head scan at 200 mm, skin1),
blub80 (blub.obj at
80 mm, marble). The meshes other than the sphere come from ../shared/meshes (skipped with a note without it).

    python tools/benchmarks/bench_volume.py [--scenes sphere20,spot50] [--reference-photons 2e7] [--cli]
                                            [--scaling --levels 3 --threads 1,2] [--cli-scaling --levels 4]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.asset_cache import AssetCache
from meshshade.io import read_mesh_arrays
from meshshade.light import DirectionalLight
from meshshade.light.samples import entry_samples
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, simulate
from meshshade.raycast import make_scene
from meshshade.transport import bake

SHARED = Path(__file__).resolve().parents[3] / "shared" / "meshes"
SUN = (0.3, -0.4, -0.866)


def _scaled(name, size_mm):
    V, F = read_mesh_arrays(SHARED / name)
    V = V - 0.5 * (V.min(axis=0) + V.max(axis=0))
    return Mesh.from_arrays(V * (size_mm / float(np.ptp(V, axis=0).max())), F, source=name)


def scene(name):
    """(mesh, material, light) of a scene, or None when its mesh is not at hand."""
    if name == "sphere20":
        return Mesh.from_arrays(*icosphere(20.0, 5)), Material.preset("skin1"), DirectionalLight((0, 0, -1), 1.0)
    files = {"spot50": ("spot.obj", 50.0, "skin1"), "head200": ("lee_perry_smith_head.obj", 200.0, "skin1"),
             "blub80": ("blub.obj", 80.0, "marble")}
    if name not in files:
        raise SystemExit(f"unknown scene {name!r}; choose among sphere20, {', '.join(files)}")
    f, size, mat = files[name]
    if not (SHARED / f).exists():
        return None
    return _scaled(f, size), Material.preset(mat), DirectionalLight(SUN, 1.0)


def lit_vertices(mesh, mat, lights) -> np.ndarray:
    """(n,) bool: the vertices with an unshadowed entry sample of positive power (the *lit* ones of :func:`errors`)."""
    es = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, list(lights),
                       make_scene(mesh.vertices, mesh.faces), mat.eta)
    lit = np.zeros(mesh.n_vertices, dtype=bool)
    lit[es.vertex[(es.vertex >= 0) & (es.power > 0)]] = True
    return lit


def errors(M, ref, lit):
    peak = ref.max(axis=0)
    out = {"lit": [], "unlit": [], "unlit_count": []}
    for c in range(3):
        sl = lit & (ref[:, c] > 0)
        su = ~lit & (ref[:, c] > 1e-2 * peak[c])
        out["lit"].append(round(float(np.mean(np.abs(M[sl, c] / ref[sl, c] - 1.0))), 4))
        out["unlit"].append(round(float(np.mean(np.abs(M[su, c] / ref[su, c] - 1.0))), 4) if su.any() else None)
        out["unlit_count"].append(int(su.sum()))
    return out


def reference(name, mesh, mat, light, photons):
    cache = AssetCache("bench-references")
    key = f"{name}-{int(photons)}-seed101"
    got = cache.read(key)
    if got is not None and got["radiance"].shape == (mesh.n_vertices, 3):
        return got["radiance"], float(got["seconds"])
    ref = simulate(mesh, mat, [light], MCOptions(photons=int(photons), seed=101, beam_distances=False))
    cache.write(key, radiance=ref.radiance, seconds=ref.seconds)
    return ref.radiance, ref.seconds


def accuracy(name, args):
    got = scene(name)
    if got is None:
        return {"row": "accuracy", "scene": name, "skipped": f"{SHARED} not found"}
    mesh, mat, light = got
    lit = lit_vertices(mesh, mat, [light])
    small = Mesh.from_arrays(*icosphere(5.0, 1))                    # compile both outside the timings
    bake(small, mat, [light])
    simulate(small, mat, [light], MCOptions(photons=4096, seed=1, beam_distances=False))
    t = time.perf_counter()
    scratch = bake(mesh, mat, [light])
    t_scratch = time.perf_counter() - t
    t = time.perf_counter()
    cached = bake(mesh, mat, [light], reuse=scratch.volume)
    t_cached = time.perf_counter() - t
    ref, ref_s = reference(name, mesh, mat, light, args.reference_photons)
    mc = simulate(mesh, mat, [light], MCOptions(photons=int(args.mc_photons), seed=202, beam_distances=False))
    return {"row": "accuracy", "scene": name, "vertices": int(mesh.n_vertices), "material": mat.name,
            "bake": {"seconds_from_scratch": round(t_scratch, 2), "seconds_cached": round(t_cached, 2),
                     "timings": {k: round(v, 3) for k, v in scratch.timings.items()},
                     "unknowns": scratch.stats.get("volume_unknowns"), "model": scratch.model,
                     **errors(scratch.patch_averaged(), ref, lit)},
            "mc": {"photons": int(args.mc_photons), "seconds": round(mc.seconds, 2), **errors(mc.radiance, ref, lit)},
            "mc_over_bake_time": {"from_scratch": round(mc.seconds / t_scratch, 2),
                                  "cached": round(mc.seconds / t_cached, 2)},
            "reference": {"photons": int(args.reference_photons), "seconds": round(ref_s, 1)},
            "identical_when_reused": bool(np.array_equal(scratch.radiance, cached.radiance))}


def cli(name, args):
    """Wall seconds of ``meshshade bake`` and ``meshshade mc`` as fresh processes on the scene's mesh."""
    from meshshade.io import write_ply

    got = scene(name)
    if got is None:
        return {"row": "cli", "scene": name, "skipped": f"{SHARED} not found"}
    mesh, mat, light = got
    d = light.direction
    light_arg = f"directional:{d[0]:.6g},{d[1]:.6g},{d[2]:.6g}"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{name}.ply"
        write_ply(path, mesh.vertices, mesh.faces)
        common = [str(path), "--material", mat.name, "--light", light_arg, "-q"]
        cmds = {"bake": ["bake", *common, "--out", str(Path(tmp) / "b.ply")],
                "mc": ["mc", *common, "--photons", str(int(args.mc_photons)), "--seed", "202",
                       "--out", str(Path(tmp) / "m.ply")]}
        env = {**os.environ, "MESHSHADE_ASSET_CACHE": "off"}
        exe = [sys.executable, "-m", "meshshade.cli"]                # what the meshshade script runs
        best = {}
        for key, argv in cmds.items():
            subprocess.run([*exe, *argv], check=True, env=env, capture_output=True)
            times = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                subprocess.run([*exe, *argv], check=True, env=env, capture_output=True)
                times.append(time.perf_counter() - t)
            best[key] = round(min(times), 2)
    return {"row": "cli", "scene": name, "vertices": int(mesh.n_vertices), "bake_s": best["bake"], "mc_s": best["mc"],
            "mc_photons": int(args.mc_photons), "mc_over_bake": round(best["mc"] / best["bake"], 2),
            "repeats": args.repeats}


def _one_size(level):
    """Child process: bake the head subdivided ``level`` times; prints its vertex count, seconds and peak RSS."""
    import igl

    got = scene("head200")
    mesh, mat, light = got
    V, F = mesh.vertices, mesh.faces
    if level:
        V, F = igl.loop(np.asarray(V), np.asarray(F), level)
    mesh = Mesh.from_arrays(V, F)
    bake(Mesh.from_arrays(*icosphere(5.0, 1)), mat, [light])
    os.environ["MESHSHADE_ASSET_CACHE"] = "off"
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    t = time.perf_counter()
    res = bake(mesh, mat, [light])
    sec = time.perf_counter() - t
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0   # MiB on Linux
    keys = ("volume_resolution_mm", "volume_resolution_limited_by", "volume_samples", "volume_cells_per_level",
            "volume_unknowns", "volume_solve_iterations", "near_field_pairs")
    print(json.dumps({"vertices": int(mesh.n_vertices), "seconds": round(sec, 2), "peak_rss_mib": round(rss),
                      "peak_rss_before_mib": round(rss0), "model": res.model,
                      **{k: res.stats.get(k) for k in keys},
                      "timings": {k: round(v, 2) for k, v in res.timings.items()}}))


def scaling(args):
    """Each size in fresh processes at each thread count, the thread counts interleaved size by size and repeated
    ``--repeats`` times (the fastest kept, whole and per stage), so that a change in the machine's load touches
    every thread count alike."""
    if scene("head200") is None:
        return {"row": "scaling", "skipped": f"{SHARED} not found"}
    counts = [int(t) for t in args.threads.split(",")]
    sizes, exponents = [], {}
    for level in range(args.levels + 1):
        best = {}
        for _ in range(max(1, args.repeats) if level < 3 else 1):
            for threads in counts:
                env = {**os.environ, "NUMBA_NUM_THREADS": str(threads)}
                out = subprocess.run([sys.executable, __file__, "--one-size", str(level)], capture_output=True,
                                     text=True, env=env)
                if out.returncode:
                    lines = [x for x in out.stderr.strip().splitlines() if "Error" in x or "error" in x]
                    best.setdefault(threads, {"level": level, "threads": threads, "failed": f"exit {out.returncode}: "
                                              + (lines[-1] if lines else "no error message (killed?)")})
                    continue
                got = {"level": level, "threads": threads, **json.loads(out.stdout.strip().splitlines()[-1])}
                old = best.get(threads)
                if old is None or "seconds" not in old:
                    best[threads] = got
                else:      # the fastest run, and each stage's fastest
                    keep = got if got["seconds"] < old["seconds"] else old
                    keep["timings"] = {k: min(v, old["timings"].get(k, v)) for k, v in got["timings"].items()}
                    best[threads] = keep
        for threads in counts:
            sizes.append(best[threads])
            print(json.dumps({"row": "scaling-size", **sizes[-1]}), flush=True)
    for threads in counts:
        ok = [s for s in sizes if "seconds" in s and s["threads"] == threads and s["vertices"] >= 8000]
        exponents[threads] = (round(float(np.polyfit(np.log([s["vertices"] for s in ok]),
                                                     np.log([s["seconds"] for s in ok]), 1)[0]), 3)
                              if len(ok) > 1 else None)
    for row in thread_rows(sizes):
        print(json.dumps(row), flush=True)
    return {"row": "scaling", "scene": "head200 loop-subdivided", "sizes": sizes, "cost_exponent": exponents,
            "load_average": os.getloadavg()}


def thread_rows(sizes):
    """Per size: the whole bake's and each stage's speed-up from the first thread count to each other one."""
    rows = []
    counts = sorted({s["threads"] for s in sizes if "seconds" in s})
    for level in sorted({s["level"] for s in sizes}):
        base = next((s for s in sizes if s["level"] == level and s["threads"] == counts[0] and "seconds" in s), None)
        for t in counts[1:]:
            other = next((s for s in sizes if s["level"] == level and s["threads"] == t and "seconds" in s), None)
            if base is None or other is None:
                continue
            stages = {k: round(v / max(other["timings"].get(k, 0.0), 1e-9), 2)
                      for k, v in base["timings"].items() if k in other["timings"]}
            slow = sorted(k for k, v in base["timings"].items() if v > 0.3 and stages.get(k, 0.0) < 1.5)
            rows.append({"row": "threads", "level": level, "vertices": base["vertices"], "from": counts[0], "to": t,
                         "speedup": round(base["seconds"] / other["seconds"], 2), "stage_speedup": stages,
                         "stages_over_0.3s_below_1.5x": slow})
    return rows


def cli_scaling(args):
    """``meshshade bake`` of the head subdivided 0 .. ``--levels`` times, each a fresh process: wall seconds and the
    child's peak resident memory, at each of ``--threads``."""
    import igl

    from meshshade.io import write_ply

    got = scene("head200")
    if got is None:
        return [{"row": "cli-scaling", "skipped": f"{SHARED} not found"}]
    mesh, mat, light = got
    d = light.direction
    light_arg = f"directional:{d[0]:.6g},{d[1]:.6g},{d[2]:.6g}"
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for level in range(args.levels + 1):
            V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
            if level:
                V, F = igl.loop(V, F, level)
            path = Path(tmp) / f"head{level}.ply"
            write_ply(path, V, F)
            paths.append((level, int(V.shape[0]), path))
        exe = [sys.executable, "-m", "meshshade.cli"]
        for threads in [int(t) for t in args.threads.split(",")]:
            env = {**os.environ, "MESHSHADE_ASSET_CACHE": "off", "NUMBA_NUM_THREADS": str(threads)}
            warm = [*exe, "bake", str(paths[0][2]), "--material", mat.name, "--light", light_arg, "-q", "--out",
                    str(Path(tmp) / "warm.ply")]
            subprocess.run(warm, check=True, env=env, capture_output=True)       # numba's cache, not counted
            for level, n, path in paths:
                argv = [*exe, "bake", str(path), "--material", mat.name, "--light", light_arg, "-q", "--out",
                        str(Path(tmp) / f"out{level}.ply")]
                times, peaks = [], []
                for _ in range(args.repeats if level < 3 else 1):
                    t = time.perf_counter()
                    child = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                             text=True)
                    err = child.stderr.read()
                    _, status, usage = os.wait4(child.pid, 0)           # this child's own resource usage
                    times.append(time.perf_counter() - t)
                    peaks.append(usage.ru_maxrss / 1024.0)               # KiB on Linux
                    code = child.returncode = os.waitstatus_to_exitcode(status)
                row = {"row": "cli-scaling", "level": level, "vertices": n, "threads": threads,
                       "seconds": round(min(times), 2), "repeats": len(times), "peak_rss_mib": round(max(peaks)),
                       "exit": code}
                if code:
                    row["error"] = err.strip().splitlines()[-1:] or ["(none)"]
                print(json.dumps(row), flush=True)
                rows.append(row)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default="sphere20,spot50")
    ap.add_argument("--reference-photons", type=float, default=2e7)
    ap.add_argument("--mc-photons", type=float, default=2e6)
    ap.add_argument("--scaling", action="store_true")
    ap.add_argument("--levels", type=int, default=2)
    ap.add_argument("--threads", default="2", help="NUMBA_NUM_THREADS of the scaling runs, comma-separated")
    ap.add_argument("--cli", action="store_true", help="time meshshade bake and mc as fresh processes")
    ap.add_argument("--cli-scaling", action="store_true", help="time meshshade bake of the subdivided head as fresh "
                    "processes, with the children's peak memory")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--no-accuracy", action="store_true")
    ap.add_argument("--one-size", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one_size is not None:
        return _one_size(args.one_size)
    for name in [s for s in args.scenes.split(",") if s]:
        if not args.no_accuracy:
            print(json.dumps(accuracy(name, args)), flush=True)
        if args.cli:
            print(json.dumps(cli(name, args)), flush=True)
    if args.scaling:
        print(json.dumps(scaling(args)), flush=True)
    if args.cli_scaling:
        cli_scaling(args)


if __name__ == "__main__":
    main()
