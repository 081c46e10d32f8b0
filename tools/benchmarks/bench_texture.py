"""What a texture bake costs against the vertex bake of the same mesh (issue 31), and how it grows with the texels.

Each row (JSON, one object per line on stdout) runs in a fresh process (so peak memory is the row's own, and
nothing compiled or cached is shared beyond numba's on-disk cache, warmed first): the default vertex bake
(``bake``, no asset cache) and ``bake_texture`` at ``--sizes`` texels per side of the same mesh, material and
light, with their wall times, the ratio (same run, same machine state), the texture's stage times and peak
resident memory (``ru_maxrss``). Scenes: sphere20 (icosphere of radius 20 mm, level 5, 10k vertices, the
procedural longitude-latitude map), spot50 (spot.obj at 50 mm from ../shared/meshes, an automatic atlas; skipped
with a note without it), ball642 (the 642-vertex ball of radius 20 mm), boot300 (boot.obj at 300 mm, 20k vertices,
an automatic atlas: issue 40's texture target). skin1, the sun along (0.3, -0.4, -0.866). The volume model (the
default) bakes the mesh as it is and reads the texels on its own sampling surface; the surface models refine it.

    python tools/benchmarks/bench_texture.py [--scenes sphere20,spot50,ball642] [--sizes 512,1024,2048]
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, spherical_uv
from meshshade.io import read_mesh_arrays
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.output.texture import bake_texture
from meshshade.transport import bake

SHARED = Path(__file__).resolve().parents[3] / "shared" / "meshes"
SUN = (0.3, -0.4, -0.866)


def scene(name):
    """(mesh, uv or None) of a scene, or None when its mesh is not at hand."""
    if name in ("sphere20", "ball642"):
        V, F = icosphere(20.0, 5 if name == "sphere20" else 3)
        return Mesh.from_arrays(V, F, source=name), spherical_uv(V, F)
    files = {"spot50": ("spot.obj", 50.0), "boot300": ("boot.obj", 300.0)}
    if name in files:
        f, size = files[name]
        if not (SHARED / f).exists():
            return None
        V, F = read_mesh_arrays(SHARED / f)
        V = V - 0.5 * (V.min(axis=0) + V.max(axis=0))
        return Mesh.from_arrays(V * (size / float(np.ptp(V, axis=0).max())), F, source=f), None
    raise SystemExit(f"unknown scene {name!r}")


def one(name: str, size: int) -> dict:
    got = scene(name)
    if got is None:
        return {"scene": name, "skipped": f"{SHARED} not found"}
    mesh, uv = got
    material, light = Material.preset("skin1"), [DirectionalLight(SUN, 1.0)]
    t0 = time.perf_counter()
    vertex = bake(mesh, material, light)
    t_vertex = time.perf_counter() - t0
    t0 = time.perf_counter()
    tex = bake_texture(mesh, material, light, uv=uv, size=size)
    t_tex = time.perf_counter() - t0
    return {"scene": name, "vertices": mesh.n_vertices, "size": size, "refine": tex.refine,
            "surface_vertices": tex.stats["texture_surface_vertices"], "uv_source": tex.uv_source,
            "texels_covered": int(tex.covered.sum()), "vertex_bake_s": round(t_vertex, 2),
            "texture_bake_s": round(t_tex, 2), "ratio": round(t_tex / t_vertex, 2),
            "texture_stages_s": {k: round(v, 2) for k, v in tex.timings.items() if k.startswith(("texture", "uv"))},
            "peak_rss_gb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6, 2),
            "vertex_max_abs_diff_over_peak": [float(x) for x in np.abs(tex.vertex_radiance - vertex.radiance).max(0)
                                              / np.maximum(vertex.radiance.max(0), 1e-300)]}


def warm() -> None:
    """Compile everything once (numba's cache) so that no row pays for it."""
    mesh = Mesh.from_arrays(*icosphere(5.0, 2))
    light = [DirectionalLight(SUN, 1.0)]
    bake(mesh, Material.preset("skin1"), light)
    bake_texture(mesh, Material.preset("skin1"), light, size=32, refine=2)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="sphere20,spot50,ball642")
    ap.add_argument("--sizes", default="512,1024,2048")
    ap.add_argument("--one", nargs=2, metavar=("SCENE", "SIZE"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(one(args.one[0], int(args.one[1]))), flush=True)
        return 0
    warm()
    for name in [s for s in args.scenes.split(",") if s]:
        for size in [int(s) for s in args.sizes.split(",") if s]:
            out = subprocess.run([sys.executable, __file__, "--one", name, str(size)], capture_output=True, text=True)
            line = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else json.dumps(
                {"scene": name, "size": size, "error": out.stderr.strip().splitlines()[-1:]})
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
