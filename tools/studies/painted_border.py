"""A straight border between two paints (issue 49, docs/physics.md eq. (134)): how the bake and the Monte Carlo
mix the two media across it.

A box of 60 x 60 x 20 mm (moved off the lattice's planes) in skin1, painted ``--dark`` for x < 0 and skin1's own
total reflectance (eq. (105)) beyond, a sun at normal incidence on its top. The default bake's exitance (averaged
over each vertex's patch) and an in-mesh Monte Carlo walk of ``--photons`` (seed 5) in the same painted medium,
averaged over the top's vertices within 12 mm of the middle line in bands of distance from the border: one JSON
object per band (the band, the vertices, both means per channel and the bake's signed difference in %).

    python tools/studies/painted_border.py [--dark 0.06] [--photons 300000]
"""
from __future__ import annotations

import argparse
import json
import time
import warnings

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box
from meshshade.kernels.painted_reflectance import model_total_reflectance
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, simulate
from meshshade.painted import PaintedMaterial
from meshshade.transport import bake

#: the box's offset from the origin, mm (off the lattice's planes)
SHIFT = np.array([0.37, 0.21, 0.37])
BANDS = ((-25, -10), (-10, -5), (-5, -3), (-3, -2), (-2, -1), (-1, 0), (0, 1), (1, 2), (2, 5), (5, 10), (10, 25))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dark", type=float, default=0.06, help="the colour for x < 0 (all channels)")
    ap.add_argument("--photons", type=float, default=3e5)
    args = ap.parse_args(argv)
    V, F = box((60.0, 60.0, 20.0), 60)
    mesh = Mesh.from_arrays(V + SHIFT, F)
    base = Material.preset("skin1")
    own = model_total_reflectance(base.albedo_prime, base.eta, base.g)
    x = mesh.vertices[:, 0] - SHIFT[0]
    colour = np.where(x[:, None] < 0.0, args.dark, own[None, :])
    painted = PaintedMaterial(base, colour=colour, name=f"skin1 | {args.dark}")
    sun = DirectionalLight((0.0, 0.0, -1.0), 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = time.perf_counter()
        M = bake(mesh, painted, [sun]).patch_averaged()
        bake_s = time.perf_counter() - t
        t = time.perf_counter()
        R = simulate(mesh, painted, [sun], MCOptions(photons=int(args.photons), seed=5, beam_distances=False))
        mc_s = time.perf_counter() - t
    top = (mesh.vertices[:, 2] > 10.0) & (np.abs(mesh.vertices[:, 1] - SHIFT[1]) < 12.0)
    for lo, hi in BANDS:
        s = top & (x >= lo) & (x < hi)
        if not s.any():
            continue
        mb, mr = M[s].mean(axis=0), R.radiance[s].mean(axis=0)
        print(json.dumps({"band_mm": [lo, hi], "vertices": int(s.sum()), "bake": np.round(mb, 5).tolist(),
                          "mc": np.round(mr, 5).tolist(),
                          "bake_off_pct": np.round(100.0 * (mb / mr - 1.0), 1).tolist()}))
    print(json.dumps({"bake_s": round(bake_s, 1), "mc_s": round(mc_s, 1), "photons": int(args.photons)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
