"""The default bake in-process, kernels warm, at the thread count this process was started with, beside the
Monte Carlo at the same count (issue 46's many-core rows): one JSON object on stdout.

    NUMBA_NUM_THREADS=16 python tools/benchmarks/bench_bake_threads.py --mc head0.npz head2.npz
    NUMBA_NUM_THREADS=1 python tools/benchmarks/bench_bake_threads.py head0.npz head2.npz

Scenes: the icosphere of radius 20 mm (level 5, the sun from above) and each mesh given (a ``.npz`` with ``V`` (n, 3)
mm and ``F`` (m, 3), or any mesh file meshshade reads; made once with ``bench_volume.py``'s head loop-subdivided, so
that a machine without libigl can run it), skin1 under the sun along (0.3, -0.4, -0.866); asset cache off; each
bake the faster of two (one for meshes over 100k vertices); ``--mc``: ``simulate(photons=2e6)`` once each (not on
meshes over 100k vertices) and its ratio to the bake. With ``bench_mc_scaling.py``'s ``ceiling`` row from the same
machine, the thread counts' ratio says how much of the machine the bake uses.
"""
from __future__ import annotations

import argparse
import json
import os
import time
import warnings
from pathlib import Path

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.io import read_mesh_arrays
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, simulate
from meshshade.transport import bake


def _mesh(path):
    path = Path(path)
    if path.suffix == ".npz":
        d = np.load(path)
        return Mesh.from_arrays(d["V"], np.asarray(d["F"], dtype=np.int64))
    return Mesh.from_arrays(*read_mesh_arrays(path))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("meshes", nargs="*")
    ap.add_argument("--mc", action="store_true", help="also simulate(photons=2e6) on each scene under 100k vertices")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    os.environ["MESHSHADE_ASSET_CACHE"] = "off"
    skin = Material.preset("skin1")
    sun = DirectionalLight((0.3, -0.4, -0.866), 1.0)
    bake(Mesh.from_arrays(*icosphere(5.0, 1)), skin, [sun])          # compile outside the timings
    scenes = {"sphere20": (Mesh.from_arrays(*icosphere(20.0, 5)), DirectionalLight((0, 0, -1), 1.0))}
    scenes.update({Path(p).stem: (_mesh(p), sun) for p in args.meshes})
    out = {"threads": os.environ.get("NUMBA_NUM_THREADS"), "cpus": os.cpu_count()}
    for name, (mesh, light) in scenes.items():
        big = mesh.n_vertices > 100_000
        times = []
        for _ in range(1 if big else 2):
            t = time.perf_counter()
            res = bake(mesh, skin, [light])
            times.append(time.perf_counter() - t)
        row = {"vertices": int(mesh.n_vertices), "bake_s": round(min(times), 2),
               "stages": {k: round(v, 2) for k, v in res.timings.items()}}
        if args.mc and not big:
            simulate(mesh, skin, [light], MCOptions(photons=20_000, seed=1, beam_distances=False))
            t = time.perf_counter()
            simulate(mesh, skin, [light], MCOptions(photons=2_000_000, seed=202, beam_distances=False))
            row["mc_2e6_s"] = round(time.perf_counter() - t, 2)
            row["mc_over_bake"] = round(row["mc_2e6_s"] / row["bake_s"], 2)
        out[name] = row
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
