"""The default bake against the in-mesh Monte Carlo on an open scan (issue 41): the scanned hand of
../shared/meshes/hand.obj at 190 mm with six holes punched (tools/benchmarks/mesh_defects.py, as
bench_defects.py makes them: the 2-ring faces around six vertices removed), skin1, the sun of bench_defects.py.

One JSON row: the default ``bake`` (its model), ``simulate(photons=2e6, seed=202)`` and a reference of
``--reference-photons`` (seed 101), and the mean |M / ref - 1| per channel (r, g, b, %) of the bake and of the 2e6-
photon run over the lit vertices (an unshadowed entry sample) that have a face, at every distance D (0, 10, 25 mm)
from the holes. The Monte Carlo treats a hole as no surface (photons pass through it and walk on outside: exitance
near a hole is too low, meshshade.montecarlo.walks warns), so only the rows beyond a few millimetres compare like
with like. Without ../shared/meshes the row is "skipped".

    python tools/benchmarks/bench_open_scan_mc.py [--reference-photons 2e7]
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
from meshshade.light import DirectionalLight
from meshshade.light.samples import entry_samples
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, simulate
from meshshade.raycast import make_scene
from meshshade.transport import bake

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/ is not a package: the defect benchmark beside this

import bench_defects as bench  # noqa: E402
import mesh_defects as md  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference-photons", type=float, default=2e7)
    args = ap.parse_args(argv)
    got = bench.scene_arrays("hand190")
    if got is None:
        print(json.dumps({"row": "open_scan_mc", "skipped": f"{bench.SHARED} not found"}))
        return 0
    V, F, sun = got
    d = bench.defective("holes6", V, F, sun)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = Mesh.from_arrays(d.vertices, d.faces)
    mat, light = Material.preset("skin1"), DirectionalLight(sun, 1.0)
    t = time.perf_counter()
    res = bake(mesh, mat, [light])
    t_bake = time.perf_counter() - t
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                     # the open mesh's warning, said in the docstring
        mc = simulate(mesh, mat, [light], MCOptions(photons=2_000_000, seed=202, beam_distances=False))
        ref = simulate(mesh, mat, [light], MCOptions(
            photons=int(args.reference_photons), seed=101, beam_distances=False))
    es = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, [light],
                       make_scene(mesh.vertices, mesh.faces), mat.eta)
    lit = np.zeros(mesh.n_vertices, dtype=bool)
    lit[es.vertex[(es.vertex >= 0) & (es.power > 0)]] = True
    referenced = np.zeros(mesh.n_vertices, dtype=bool)
    referenced[mesh.faces.reshape(-1)] = True
    R = np.asarray(ref.radiance)
    row = {"row": "open_scan_mc", "scene": "hand190 holes6", "model": res.model, "bake_s": round(t_bake, 2),
           "mc_seconds": round(mc.seconds, 1), "reference_photons": int(args.reference_photons),
           "reference_seconds": round(ref.seconds, 1)}
    for D in (0.0, 10.0, 25.0):
        far = md.far_from(mesh.vertices, d.points, D) & referenced & lit
        errs = {}
        for name, M in (("bake", np.asarray(res.patch_averaged())), ("mc2e6", np.asarray(mc.radiance))):
            errs[name] = [round(100.0 * float(np.mean(np.abs(M[far & (R[:, c] > 0), c] / R[far & (R[:, c] > 0), c]
                                                              - 1.0))), 2) for c in range(3)]
        errs["vertices"] = int(far.sum())
        row[f"lit_beyond_{int(D)}mm"] = errs
    row["meets_target"] = all(b <= m for b, m in zip(row["lit_beyond_10mm"]["bake"], row["lit_beyond_10mm"]["mc2e6"]))
    print(json.dumps(row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
