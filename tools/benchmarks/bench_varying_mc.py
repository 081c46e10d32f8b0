"""What a varying medium costs the Monte Carlo (issue 49, docs/physics.md §17 "The Monte Carlo in a varying
medium"): the same scene walked in one material, painted and in parts, in one process, interleaved, best of
``--repeats``.

Scene: the 20 mm UV sphere (96 x 48, :func:`meshshade.geometry.procedural.uv_sphere`) in skin1 under the sun along
(0.3, -0.4, -0.866). Rows (one JSON object per line on stdout):

* ``one``: skin1, homogeneous (the baseline of every ratio);
* ``painted_checker``: skin1 painted per vertex with a 5 mm checkerboard (in x, y, z) of skin1's own total
  reflectance (eq. (105)) and 0.6 times it (g = 0: every collision real, one closest-point search each);
* ``painted_checker_g08``: the same paint on skin1 with g = 0.8 (sigma_t varies: delta tracking, null collisions);
* ``parts_one``: skin1 as one part (the winding-number lookup through the label grid; bitwise ``one``);
* ``parts_core``: skin1 with a 10 mm core of marble (the same index) as a second part (interior faces index-matched;
  null collisions in the shell, where marble's sigma_t is the majorant).

Each row: wall seconds of the walk (best), photons, events, null collisions, seconds per photon and its ratio to
``one``. A last row ``part_lookup`` times the parts' medium lookup at 2e5 random points of the sphere with the
label grid and without it (every lookup by winding numbers), and the grid's labelled fraction.

    python tools/benchmarks/bench_varying_mc.py [--photons 50000] [--repeats 2]
"""
from __future__ import annotations

import argparse
import json
import time
import warnings

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, uv_sphere
from meshshade.kernels.painted_reflectance import model_total_reflectance
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, media, simulate
from meshshade.painted import PaintedMaterial
from meshshade.parts import PartedMaterial

SUN = (0.3, -0.4, -0.866)


def checker(vertices, size=5.0):
    """(n,) bool: the 5 mm checkerboard's squares in x, y, z."""
    return (np.floor(vertices / size).astype(np.int64).sum(axis=1) % 2) == 0


def scenes():
    V, F = uv_sphere(20.0, 48, 96)
    sphere = Mesh.from_arrays(V, F, source="uv_sphere 96x48 r20")
    skin = Material.preset("skin1")
    skin_g = Material.preset("skin1", g=0.8)

    def paint(m):
        own = model_total_reflectance(m.albedo_prime, m.eta, m.g)
        colour = np.where(checker(sphere.vertices)[:, None], own, 0.6 * own)
        return PaintedMaterial(m, colour=colour, name=f"{m.name} checker")

    Vi, Fi = icosphere(10.0, 4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cored = Mesh.from_arrays(np.concatenate([V, Vi]), np.concatenate([F, Fi + V.shape[0]]),
                                 source="uv_sphere r20 + core r10")
    part = np.concatenate([np.zeros(len(F), np.int64), np.ones(len(Fi), np.int64)])
    core = PartedMaterial([skin, Material.preset("marble")], part, ["shell", "core"])
    return {"one": (sphere, skin), "painted_checker": (sphere, paint(skin)),
            "painted_checker_g08": (sphere, paint(skin_g)),
            "parts_one": (sphere, PartedMaterial([skin], np.zeros(len(F), np.int64))),
            "parts_core": (cored, core)}


def part_lookup(n=200_000):
    _, (mesh, pm) = list(scenes().items())[-1]
    groups, fields = media.medium_fields(pm, mesh, pm.face_part == 0)
    fld = fields[0]
    rng = np.random.default_rng(0)
    d = rng.normal(size=(n, 3))
    P = d / np.linalg.norm(d, axis=1, keepdims=True) * (19.9 * rng.random(n) ** (1 / 3))[:, None]
    media.medium_at_points(fld, P[:100])    # compiled
    t = time.perf_counter()
    a = media.medium_at_points(fld, P)
    with_grid = time.perf_counter() - t
    labels = fld.parts[13]
    bare = media.MediumField(fld.kind, fld.majorant, fld.constant, fld.fp, fld.paint,
                             (*fld.parts[:13], np.full_like(labels, -1), fld.parts[14]))
    t = time.perf_counter()
    b = media.medium_at_points(bare, P)
    without = time.perf_counter() - t
    return {"row": "part_lookup", "points": n, "grid_shape": list(labels.shape),
            "labelled_fraction": fld.grid_fraction, "seconds_grid": with_grid, "seconds_windings": without,
            "speedup": without / with_grid, "same_media": bool(np.array_equal(a, b))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=int, default=50_000)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args(argv)
    sc = scenes()
    light = [DirectionalLight(SUN, 1.0)]
    opt = MCOptions(photons=args.photons, seed=1)
    best: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, (mesh, mat) in sc.items():      # warm-up: numba compiles or loads each walk once
            simulate(mesh, mat, light, MCOptions(photons=256, seed=0))
        for _ in range(args.repeats):
            for name, (mesh, mat) in sc.items():
                r = simulate(mesh, mat, light, opt)
                if name not in best or r.seconds < best[name].seconds:
                    best[name] = r
    base = best["one"].seconds / best["one"].photons
    for name, r in best.items():
        per = r.seconds / r.photons
        print(json.dumps({"row": name, "seconds": r.seconds, "photons": r.photons, "events": r.events,
                          "null_collisions": r.null_collisions, "seconds_per_photon": per,
                          "ratio_to_one": per / base,
                          "diffuse_reflectance": [float(v) for v in r.totals["diffuse_reflectance"]]}))
    print(json.dumps(part_lookup()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
