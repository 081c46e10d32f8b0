#!/usr/bin/env python
"""Environment and area lights (issue 43): what an environment bake costs against a sun bake, the noise its
quadrature leaves, the linearity targets, and the default bake against the in-mesh Monte Carlo under a studio HDRI.

Rows (JSON, one object per line on stdout):

* ``cost`` (``--mode cost``, the default) per mesh (``--meshes``; sphere10k: assets/sphere_r10mm.ply, 10,242
  vertices; spot50: spot.obj at 50 mm, 11,533 vertices): the default bake (skin1) from scratch (asset cache in a
  fresh folder: the tetrahedral mesh is built) under a sun and under the studio HDRI of
  tools/benchmarks/studio_hdri.py (written to an EXR and read back through ``--light env:``), in the same process
  after both were compiled on a small mesh, alternately ``--repeats`` times: wall seconds (min and median), the
  ratio env / sun, the stages' seconds, entry samples, directions per vertex, shadow rays and the error left.
* ``noise`` (``--mode noise``): the same environment bake with two seeds of the light: the relative difference per
  vertex over sqrt(2) (rms and 99th percentile per channel), the noise the quadrature leaves in the bake, against
  the per-vertex error it reports.
* ``linearity`` (``--mode linearity``): the targets of tests/light/test_environment_bake.py measured (a uniform sky
  against 256 directional lights on a Fibonacci set; a map holding one small bright disc against a directional
  light of its irradiance), on an icosphere of radius 10 mm (level ``--level``).
* ``mc`` (``--mode mc``) per scene (spot50, head200: the head scan at 200 mm; skin1, the studio HDRI): the default
  bake, ``mc --photons 2e6`` (seed 202) and a reference Monte Carlo of ``--reference-photons`` (seed 101, kept in
  the asset cache ``bench-references``): mean |M / ref - 1| per channel over the vertices whose reference is above
  1e-2 of the channel's peak, bake and 2e6-photon Monte Carlo alike, with wall times. The references take minutes
  to hours on 2 cores.

Meshes other than the sphere come from ../shared/meshes (skipped with a note without it).

    python tools/benchmarks/bench_environment.py [--mode cost|noise|linearity|mc] [--meshes sphere10k,spot50]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from meshshade.geometry.mesh import Mesh  # noqa: E402
from meshshade.geometry.procedural import icosphere  # noqa: E402
from meshshade.io import load_mesh, read_mesh_arrays, write_exr  # noqa: E402
from meshshade.light import DirectionalLight, EnvironmentLight, parse_light_spec  # noqa: E402
from meshshade.materials import Material  # noqa: E402
from meshshade.montecarlo import simulate  # noqa: E402
from meshshade.transport import bake  # noqa: E402
from meshshade.montecarlo import MCOptions
from bench_volume import reference  # noqa: E402  (kept in the asset cache "bench-references", seed 101)
from studio_hdri import studio_hdri  # noqa: E402

SHARED = ROOT.parent / "shared" / "meshes"
SUN = (0.3, -0.4, -0.866)
#: the studio map's strength: its window then delivers about 1e-3 W/mm^2 of the sun's 1
STRENGTH = 1e-3


def _scaled(name, size_mm):
    V, F = read_mesh_arrays(SHARED / name)
    V = V - 0.5 * (V.min(axis=0) + V.max(axis=0))
    return Mesh.from_arrays(V * (size_mm / float(np.ptp(V, axis=0).max())), F, source=name)


def mesh_of(name):
    if name == "sphere10k":
        return load_mesh(ROOT / "assets" / "sphere_r10mm.ply")
    files = {"spot50": ("spot.obj", 50.0), "head200": ("lee_perry_smith_head.obj", 200.0)}
    if name not in files:
        raise SystemExit(f"unknown mesh {name!r}; choose among sphere10k, {', '.join(files)}")
    f, size = files[name]
    return _scaled(f, size) if (SHARED / f).exists() else None


def studio_light(folder, seed=0, error=None):
    path = Path(folder) / "studio.exr"
    if not path.exists():
        write_exr(path, studio_hdri(256))
    light = parse_light_spec(f"env:{path}:{STRENGTH}")
    kw = {"seed": seed}
    if error is not None:
        kw["error"] = error
    return EnvironmentLight(light.radiance, strength=light.strength, path=light.path, **kw)


def _compile(mat, lights):
    small = Mesh.from_arrays(*icosphere(5.0, 2))
    for light in lights:
        bake(small, mat, [light])


def _timed_bake(mesh, mat, light):
    with tempfile.TemporaryDirectory() as tmp:          # from scratch: an empty asset cache
        os.environ["MESHSHADE_ASSET_CACHE"] = tmp
        t = time.perf_counter()
        r = bake(mesh, mat, [light])
        seconds = time.perf_counter() - t
        del os.environ["MESHSHADE_ASSET_CACHE"]
    return seconds, r


def cost(name, args, folder):
    mesh = mesh_of(name)
    if mesh is None:
        return {"row": "cost", "mesh": name, "skipped": f"{SHARED} not found"}
    mat = Material.preset("skin1")
    sun, env = DirectionalLight(SUN, 1.0), studio_light(folder, error=args.error)
    _compile(mat, [sun, env])
    times = {"sun": [], "env": []}
    last = {}
    for _ in range(args.repeats):
        for key, light in (("sun", sun), ("env", env)):
            s, r = _timed_bake(mesh, mat, light)
            times[key].append(s)
            last[key] = r
    q = last["env"].stats["quadrature"][0]
    out = {"row": "cost", "mesh": name, "vertices": int(mesh.n_vertices), "material": "skin1",
           "load_average": [round(x, 2) for x in os.getloadavg()]}
    for key in ("sun", "env"):
        r = last[key]
        out[key] = {"seconds_min": round(min(times[key]), 2), "seconds_median": round(float(np.median(times[key])), 2),
                    "entry_samples": int(r.stats["entry_samples"]), "model": r.model,
                    "timings": {k: round(v, 3) for k, v in r.timings.items()}}
    out["env"].update({"directions_per_vertex": q["directions"], "rel_error_rms": round(q["rel_error_rms"], 5),
                       "rel_error_p99": round(q["rel_error_p99"], 5), "rays_cast": q["rays_cast"],
                       "light_error": env.error})
    out["ratio_env_over_sun"] = {"min": round(min(times["env"]) / min(times["sun"]), 2),
                                 "median": round(float(np.median(times["env"]) / np.median(times["sun"])), 2)}
    return out


def noise(name, args, folder):
    mesh = mesh_of(name)
    if mesh is None:
        return {"row": "noise", "mesh": name, "skipped": f"{SHARED} not found"}
    mat = Material.preset("skin1")
    lights = [studio_light(folder, seed=s, error=args.error) for s in (1, 2)]
    runs = [bake(mesh, mat, [light]) for light in lights]
    a, b = runs[0].radiance, runs[1].radiance
    ok = (a > 0) & (b > 0)
    rel = np.where(ok, np.abs(a - b) / np.where(ok, 0.5 * (a + b), 1.0), 0.0) / math.sqrt(2.0)
    q = runs[0].stats["quadrature"][0]
    return {"row": "noise", "mesh": name, "light_error": lights[0].error, "directions_per_vertex": q["directions"],
            "reported_entering_error_rms": round(q["rel_error_rms"], 5),
            "bake_noise_rms": [round(float(np.sqrt(np.mean(rel[ok[:, c], c] ** 2))), 5) for c in range(3)],
            "bake_noise_p99": [round(float(np.percentile(rel[ok[:, c], c], 99)), 5) for c in range(3)]}


def _fibonacci(n):
    k = np.arange(n)
    z = 1.0 - (2.0 * k + 1.0) / n
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def linearity(args):
    sys.path.insert(0, str(ROOT / "tests" / "light"))
    from test_environment_bake import _disc_map  # the test's own disc and its irradiance

    mesh = Mesh.from_arrays(*icosphere(10.0, args.level))
    mat = Material.preset("skin1")
    L = 2e-3
    kw = {} if args.error is None else {"error": args.error}
    t = time.perf_counter()
    sky = bake(mesh, mat, [EnvironmentLight.uniform(L, **kw)])
    t_sky = time.perf_counter() - t
    t = time.perf_counter()
    suns = bake(mesh, mat, [DirectionalLight(tuple(-d), L * 4 * math.pi / 256) for d in _fibonacci(256)])
    t_suns = time.perf_counter() - t
    rel = np.abs(sky.radiance / suns.radiance - 1.0)
    s = np.array([0.3, 0.8, -0.5])
    s /= np.linalg.norm(s)
    Y, E = _disc_map(128, s, 2.0, 1.0)
    env = bake(mesh, mat, [EnvironmentLight(Y, **kw)]).radiance
    sun = bake(mesh, mat, [DirectionalLight(tuple(-s), E)]).radiance
    sees = mesh.vertex_normals @ s > math.sin(math.radians(6.0))
    rd = np.abs(env[sees] / sun[sees] - 1.0)
    return {"row": "linearity", "vertices": int(mesh.n_vertices), "material": "skin1",
            "uniform_vs_256_suns": {"mean": rel.mean(axis=0).round(5).tolist(),
                                    "p99": np.percentile(rel, 99, axis=0).round(5).tolist(),
                                    "seconds_uniform": round(t_sky, 2), "seconds_256_suns": round(t_suns, 2),
                                    "directions_per_vertex": sky.stats["quadrature"][0]["directions"]},
            "disc_vs_sun": {"mean": rd.mean(axis=0).round(5).tolist(), "vertices_compared": int(sees.sum())},
            "targets": {"uniform_mean": 0.01, "uniform_p99": 0.03, "disc_mean": 0.02}}


def _errors(M, ref):
    peak = ref.max(axis=0)
    out = []
    for c in range(3):
        keep = ref[:, c] > 1e-2 * peak[c]
        out.append(round(float(np.mean(np.abs(M[keep, c] / ref[keep, c] - 1.0))), 4))
    return out


def mc(name, args, folder):
    mesh = mesh_of(name)
    if mesh is None:
        return {"row": "mc", "scene": name, "skipped": f"{SHARED} not found"}
    mat = Material.preset("skin1")
    light = studio_light(folder, error=args.error)
    _compile(mat, [light])
    simulate(Mesh.from_arrays(*icosphere(5.0, 1)), mat, [light], MCOptions(photons=4096, seed=1, beam_distances=False))
    t_bake, baked = _timed_bake(mesh, mat, light)
    ref, ref_s = reference(f"{name}-studio-{light.digest}", mesh, mat, light, args.reference_photons)
    run = simulate(mesh, mat, [light], MCOptions(photons=int(args.mc_photons), seed=202, beam_distances=False))
    return {"row": "mc", "scene": name, "vertices": int(mesh.n_vertices), "material": "skin1",
            "bake": {"seconds_from_scratch": round(t_bake, 2), "error": _errors(baked.patch_averaged(), ref),
                     "directions_per_vertex": baked.stats["quadrature"][0]["directions"]},
            "mc": {"photons": int(args.mc_photons), "seconds": round(run.seconds, 2),
                   "error": _errors(run.radiance, ref)},
            "reference": {"photons": int(args.reference_photons), "seconds": round(ref_s, 1)},
            "bake_not_worse_than_mc_2e6": [b <= m for b, m in zip(_errors(baked.patch_averaged(), ref),
                                                                   _errors(run.radiance, ref))]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mode", default="cost", choices=["cost", "noise", "linearity", "mc"])
    ap.add_argument("--meshes", default=None, help="comma list (cost, noise: sphere10k,spot50; mc: spot50,head200)")
    ap.add_argument("--repeats", type=int, default=2, help="cost: alternating sun/env bakes per mesh (default 2)")
    ap.add_argument("--error", type=float, default=None, help="the environment's --light-error (default: its own)")
    ap.add_argument("--level", type=int, default=3, help="linearity: the icosphere's subdivision level (default 3)")
    ap.add_argument("--mc-photons", type=float, default=2e6)
    ap.add_argument("--reference-photons", type=float, default=2e7)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        if args.mode == "linearity":
            print(json.dumps(linearity(args)), flush=True)
            return 0
        default = "spot50,head200" if args.mode == "mc" else "sphere10k,spot50"
        run = {"cost": cost, "noise": noise, "mc": mc}[args.mode]
        for name in (args.meshes or default).split(","):
            print(json.dumps(run(name.strip(), args, folder)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
