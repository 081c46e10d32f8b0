"""Benchmark the bake: time per stage and kernel pairs per second (issue: mesh pipeline).

Scenes: icospheres of ~10k/40k/160k vertices (R = 60 mm), spot scaled to 100 mm and the Lee Perry-Smith head
scan scaled to 200 mm (from ../shared/meshes when present), skin1, one directional light. Each scene is baked
with the dipole (the baseline), the curved model, and the curved model with the fast "arc" geodesics in the same
run, so the ratios hold on a noisy machine; each row also gives the relative difference of its radiance from the
first run's (red channel). Prints JSON (one object per scene and model) to stdout.

    python tools/benchmarks/bench_bake.py [--quick] [--runs dipole:exact,curved:exact,curved:arc]
    python tools/benchmarks/bench_bake.py --quick --runs curved:exact,auto:exact,curved:arc   # what auto saves
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.io import read_mesh_arrays
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport.baking import bake
from meshshade.transport import BakeOptions, SurfaceOptions

SHARED = Path(__file__).resolve().parents[3] / "shared" / "meshes"


def scenes(quick: bool):
    for level in ((4,) if quick else (5, 6, 7)):
        V, F = icosphere(60.0, level)
        yield f"icosphere_L{level}", Mesh(V, F)
    for name, size in (("spot.obj", 100.0), ("lee_perry_smith_head.obj", 200.0)):
        path = SHARED / name
        if not path.exists():
            print(f"skipping {name}: {path} not found", file=sys.stderr)
            continue
        V, F = read_mesh_arrays(path)
        V = (V - V.mean(axis=0)) * (size / np.ptp(V, axis=0).max())
        yield f"{Path(name).stem}_{size:g}mm", Mesh(V, F)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small meshes only")
    ap.add_argument("--runs", default="dipole:exact,curved:exact,curved:arc",
                    help="comma list of model:geodesic pairs; the first is the baseline of the ratios")
    args = ap.parse_args(argv)
    material = Material.preset("skin1")
    light = DirectionalLight((0.3, -0.4, -1.0), 1.0)
    bake(Mesh(*icosphere(10.0, 2)), material, [light], BakeOptions(model="curved"))  # compile the numba loops first
    rows = []
    for name, mesh in scenes(args.quick):
        base = None
        for run in args.runs.split(","):
            model, geodesic = run.split(":")
            t = time.perf_counter()
            res = bake(mesh, material, [light], BakeOptions(model=model, surface=SurfaceOptions(geodesic=geodesic)))
            wall = time.perf_counter() - t
            pairs = res.stats.get("pairs_found", 0)
            row = {"scene": name, "vertices": mesh.n_vertices, "model": model, "geodesic": geodesic,
                   "wall_s": round(wall, 4),
                   "stages_s": {k: round(v, 4) for k, v in res.timings.items()},
                   "entry_samples": res.stats["entry_samples"], "pairs": pairs,
                   "pairs_per_s_gather": round(res.stats.get("pairs_evaluated", 0) /
                                               max(res.timings.get("gather", 1e-9), 1e-9)),
                   "shadow_rays_cast": res.stats.get("shadow_rays_cast"),
                   "shadow_rays_skipped": res.stats.get("shadow_rays_skipped")}
            row["geodesic_pairs_computed"] = res.stats.get("geodesic_pairs_computed")
            row.update({k: v for k, v in res.stats.items() if k.startswith(("zone_", "auto_"))})
            if base is None:
                base, base_M = wall, res.radiance
            row["wall_ratio_to_first_model"] = round(wall / base, 3)
            # difference from the first run's radiance (red channel, vertices above 1e-3 of its peak)
            lit = base_M[:, 0] > 1e-3 * base_M[:, 0].max()
            rel = np.abs(res.radiance[lit, 0] - base_M[lit, 0]) / base_M[lit, 0]
            row["rel_diff_to_first_model"] = {"mean": float(f"{rel.mean():.3g}"),
                                              "p99": float(f"{np.quantile(rel, 0.99):.3g}"),
                                              "max": float(f"{rel.max():.3g}")}
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


if __name__ == "__main__":
    main()
