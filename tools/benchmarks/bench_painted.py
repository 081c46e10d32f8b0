"""What painting a material costs (issue 49, docs/physics.md §17): a painted bake against the same mesh in one
material, same run, same light, best of ``--repeats`` interleaved.

Rows (JSON, one object per line on stdout): ``one`` (skin1, homogeneous), ``painted_const`` (skin1 painted with
its own total reflectance everywhere: the painted code path on the same lattice as ``one``, so its ratio is the
path's own overhead), ``painted_map`` (spot's colour map through its MTL ``map_Kd``, sRGB decoded, the 0s and 1s of
the map clamped just inside the reachable range: the lattice then resolves the darkest paint, and the near field
is summed at NEAR_FIELD_NODES albedos), ``painted_map_h0_one`` (the same at the lattice spacing of ``one``: what the
finer lattice costs and changes; ``vs_painted_map``: the median and 90th percentile of |difference| / value over
the vertices above 1e-3 of the peak, per channel), ``radius_map`` (skin1's own colour with a radius map over the
UVs, eq. (132): the factor 0.7 + 0.7 u, 0.7-1.4 across the map, as smooth as a painted thickness mask; the lattice
resolves the shortest mean free path and the near field takes four tables per pair) and ``one_shortest`` (skin1 at
its mean free path times 0.7, the map's shortest, homogeneous: the lattice the map needs, so ``radius_map`` over
``one_shortest`` is the map's own cost). Each row: wall time (best), the ratio to ``one``, the lattice's h0 and
unknowns, the stage times of the best run. spot_textured.obj from ../shared/meshes scaled to 50 mm, the sun along
(0.3, -0.4, -0.866).

    python tools/benchmarks/bench_painted.py [--repeats 2] [--size-mm 50]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.io import load_mesh, mtl_colour_map, read_colour_map, read_uv_map
from meshshade.kernels.painted_reflectance import model_total_reflectance
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.painted import PaintedMaterial
from meshshade.transport import bake
from meshshade.transport.options import BakeOptions
from meshshade.volume.options import VolumeOptions

SHARED = Path(__file__).resolve().parents[3] / "shared" / "meshes"
SUN = (0.3, -0.4, -0.866)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--size-mm", type=float, default=50.0)
    args = ap.parse_args(argv)
    path = SHARED / "spot_textured.obj"
    if not path.exists():
        print(json.dumps({"skipped": f"{path} not found"}))
        return 0
    loaded = load_mesh(path)
    V = loaded.vertices - 0.5 * (loaded.vertices.min(axis=0) + loaded.vertices.max(axis=0))
    mesh = Mesh.from_arrays(V * (args.size_mm / float(np.ptp(V, axis=0).max())), loaded.faces, source=path.name)
    uv = read_uv_map(path, mesh)
    base = Material.preset("skin1")
    own = model_total_reflectance(base.albedo_prime, base.eta, base.g)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        painted_map = PaintedMaterial(base, image=read_colour_map(mtl_colour_map(path)), uv=uv, clamp=True)
    u = np.linspace(0.0, 1.0, 64)
    radius = np.broadcast_to((0.7 + 0.7 * u)[None, :, None], (64, 64, 3))
    rows = {"one": base, "painted_const": PaintedMaterial(base, colour=np.broadcast_to(own, (mesh.n_vertices, 3))),
            "painted_map": painted_map, "painted_map_h0_one": painted_map,
            "radius_map": PaintedMaterial(base, radius_image=radius, uv=uv),
            "one_shortest": Material(base.sigma_s_prime / 0.7, base.sigma_a / 0.7, base.eta, base.g, "skin1 x 0.7")}
    light = [DirectionalLight(SUN, 1.0)]
    best = {k: None for k in rows}
    h0_one = None
    for _ in range(max(1, args.repeats)):
        for name, material in rows.items():             # interleaved: the machine's state shared alike
            options = BakeOptions(volume=VolumeOptions(h0=h0_one)) if name.endswith("h0_one") else None
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.perf_counter()
                r = bake(mesh, material, light, options)
                wall = time.perf_counter() - t0
            if best[name] is None or wall < best[name][0]:
                best[name] = (wall, r)
            if name == "one":
                h0_one = r.stats["volume_resolution_mm"]
    ref = best["painted_map"][1].radiance
    lit = ref > 1e-3 * ref.max(axis=0)
    for name, (wall, r) in best.items():
        rel = np.abs(r.radiance - ref) / np.where(lit, ref, 1.0)
        diff = {"median": [round(float(np.median(rel[lit[:, c], c])), 4) for c in range(3)],
                "p90": [round(float(np.percentile(rel[lit[:, c], c], 90)), 4) for c in range(3)]}
        print(json.dumps({"row": name, "vertices": mesh.n_vertices, "size_mm": args.size_mm,
                          "wall_s": round(wall, 3), "ratio_to_one": round(wall / best["one"][0], 3),
                          **({"ratio_to_one_shortest": round(wall / best["one_shortest"][0], 3)}
                             if name == "radius_map" else {}),
                          "volume_resolution_mm": r.stats["volume_resolution_mm"],
                          "volume_unknowns": r.stats["volume_unknowns"],
                          "clamped_values": getattr(rows[name], "clamped", 0),
                          **({"vs_painted_map": diff} if name == "painted_map_h0_one" else {}),
                          "stages_s": {k: round(v, 3) for k, v in r.timings.items()}}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
