"""Monte Carlo references in painted media, and the painted bake against them (issue 49, docs/physics.md §17 "The
Monte Carlo in a varying medium").

Scenes (the sun along (0.3, -0.4, -0.866)):

* ``spot50``: spot_textured.obj (../shared/meshes) at 50 mm, skin1 painted with its colour map (the MTL's map_Kd,
  sRGB decoded, the map's 0s and 1s clamped just inside the reachable range, as ``--albedo-map mtl
  --albedo-clamp``);
* ``checker20``: the 20 mm UV sphere (96 x 48), skin1 painted per vertex with a 5 mm checkerboard (in x, y, z) of
  skin1's own total reflectance (eq. (105)) and 0.6 times it.

Per scene: a reference walk of ``--reference-photons`` (seed 101) and a walk of ``--photons`` (seed 202), each kept
in the asset cache (kind ``varying-references``, per-vertex exitance and its standard error as .npz, keyed by the
scene, the photon count, the seed and a digest of the paint) so that a second run reads them; the default bake of
the same painted material. Errors as tools/benchmarks/bench_volume.py computes them: mean |M / ref - 1| per channel
over lit vertices and over unlit ones above 1e-2 of the channel's peak (the bake's exitance averaged over each
vertex's patch, as the walk tallies it). One JSON object per scene on stdout.

    python tools/studies/varying_media_references.py [--scenes spot50,checker20] [--reference-photons 1e7]
        [--photons 2e6] [--only-references]
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from meshshade.asset_cache import AssetCache
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import uv_sphere
from meshshade.io import load_mesh, mtl_colour_map, read_colour_map, read_uv_map
from meshshade.kernels.painted_reflectance import model_total_reflectance
from meshshade.light import DirectionalLight
from meshshade.light.samples import entry_samples
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, simulate
from meshshade.painted import PaintedMaterial
from meshshade.raycast import make_scene
from meshshade.transport import bake

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_volume import errors  # noqa: E402

SHARED = Path(__file__).resolve().parents[3] / "shared" / "meshes"
SUN = (0.3, -0.4, -0.866)


def checker(vertices, size=5.0):
    """(n,) bool: the squares of a checkerboard of ``size`` mm in x, y, z."""
    return (np.floor(vertices / size).astype(np.int64).sum(axis=1) % 2) == 0


def scene(name):
    """(mesh, painted material) of scene ``name``, or None where its mesh is absent."""
    base = Material.preset("skin1")
    if name == "checker20":
        V, F = uv_sphere(20.0, 48, 96)
        mesh = Mesh.from_arrays(V, F, source="uv_sphere 96x48 r20")
        own = model_total_reflectance(base.albedo_prime, base.eta, base.g)
        colour = np.where(checker(mesh.vertices)[:, None], own, 0.6 * own)
        return mesh, PaintedMaterial(base, colour=colour, name="skin1 checker 5 mm")
    if name == "spot50":
        path = SHARED / "spot_textured.obj"
        if not path.exists():
            return None
        loaded = load_mesh(path)
        V = loaded.vertices - 0.5 * (loaded.vertices.min(axis=0) + loaded.vertices.max(axis=0))
        mesh = Mesh.from_arrays(V * (50.0 / float(np.ptp(V, axis=0).max())), loaded.faces, source=path.name)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            painted = PaintedMaterial(base, image=read_colour_map(mtl_colour_map(path)), uv=read_uv_map(path, mesh),
                                      clamp=True, name="skin1 spot map")
        return mesh, painted
    raise SystemExit(f"unknown scene {name!r}")


def walk(name, mesh, material, light, photons, seed):
    """(radiance, stderr, seconds) of a walk, from the asset cache when it holds it."""
    cache = AssetCache("varying-references")
    digest = hashlib.sha1(material.describe().encode()).hexdigest()[:10]
    key = f"{name}-{int(photons)}-seed{seed}-{digest}"
    got = cache.read(key)
    if got is not None and got["radiance"].shape == (mesh.n_vertices, 3):
        return got["radiance"], got["stderr"], float(got["seconds"])
    r = simulate(mesh, material, [light], MCOptions(photons=int(photons), seed=seed, beam_distances=False),
                 progress=f"mc {name} {photons:.0e}")
    cache.write(key, radiance=r.radiance, stderr=r.radiance_stderr, seconds=r.seconds)
    return r.radiance, r.radiance_stderr, r.seconds


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="spot50,checker20")
    ap.add_argument("--reference-photons", type=float, default=1e7)
    ap.add_argument("--photons", type=float, default=2e6)
    ap.add_argument("--only-references", action="store_true", help="walk (or read) the references only")
    args = ap.parse_args(argv)
    light = DirectionalLight(SUN, 1.0)
    for name in [s for s in args.scenes.split(",") if s]:
        got = scene(name)
        if got is None:
            print(json.dumps({"scene": name, "skipped": f"{SHARED} not found"}))
            continue
        mesh, material = got
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref, ref_se, ref_s = walk(name, mesh, material, light, args.reference_photons, 101)
            if args.only_references:
                print(json.dumps({"scene": name, "reference_photons": int(args.reference_photons),
                                  "seconds": round(ref_s, 1)}))
                continue
            mc, _mc_se, mc_s = walk(name, mesh, material, light, args.photons, 202)
            t = time.perf_counter()
            baked = bake(mesh, material, [light])
            bake_s = time.perf_counter() - t
        es = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, [light],
                           make_scene(mesh.vertices, mesh.faces), material.eta)
        lit = np.zeros(mesh.n_vertices, dtype=bool)
        lit[es.vertex[(es.vertex >= 0) & (es.power > 0)]] = True
        sel = lit & np.all(ref > 0, axis=1)
        print(json.dumps({
            "scene": name, "vertices": int(mesh.n_vertices), "material": material.describe(),
            "reference": {"photons": int(args.reference_photons), "seconds": round(ref_s, 1),
                          "median_relative_stderr_lit": [round(float(np.median(ref_se[sel, c] / ref[sel, c])), 5)
                                                         for c in range(3)]},
            "bake": {"seconds": round(bake_s, 2), "model": baked.model, **errors(baked.patch_averaged(), ref, lit)},
            "mc": {"photons": int(args.photons), "seconds": round(mc_s, 1), **errors(mc, ref, lit)}}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
