"""What the volume diffusion alone gives on a real bake scene, against Monte Carlo, as JSON (issue 29's study).

    python tools/volume_far_field.py [--scene spot_sun] [--reference-photons 1e7] [--mc-photons 2e6]

The far field of the volume transport without any near-field correction (docs/physics.md §15): the surface is
tetrahedralised keeping its vertices (``surface_tetrahedra``), the bake's entry samples become Gauss-Laguerre line
sources along the refracted light (eq. (95); points beyond where the line leaves the body are dropped: that
light leaves unscattered), one solve per channel, the exitance read at the surface vertices.
Errors are mean |M / ref - 1| per channel over (a) unlit vertices whose reference is above 1e-2 of the peak (light
that crossed the body) and (b) lit vertices, against an in-mesh Monte Carlo reference; the Monte Carlo of
``--mc-photons`` (another seed) is scored the same way, and every stage is timed.

Scenes: spot_sun (spot.obj at 50 mm, skin1, a sun along (0.3, -0.4, -0.866)), sphere20_sun (a 20 mm icosphere of
level 5, skin1, a sun from above).
"""
from __future__ import annotations

import argparse
import json
import time
import warnings

import igl
import numpy as np

from meshshade.bench.scenes import SCENES
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import DirectionalLight
from meshshade.light.samples import entry_samples
from meshshade.materials import material_from_options
from meshshade.montecarlo import simulate
from meshshade.raycast import make_scene
from meshshade.kernels.fresnel import refract_in
from meshshade.volume import DiffusionOperator, line_sources, locate_points, point_source_vector, surface_tetrahedra


def scene(name):
    if name == "spot_sun":
        return SCENES["spot_50mm_beam"].build(), DirectionalLight((0.3, -0.4, -0.866), 1.0)
    if name == "sphere20_sun":
        return Mesh.from_arrays(*icosphere(20.0, 5)), DirectionalLight((0.0, 0.0, -1.0), 1.0)
    raise SystemExit(f"unknown scene {name!r}")


def volume_exitance(mesh, material, light, n_points=4):
    """(exitance (n, 3) W/mm^2 at the mesh's vertices, seconds per stage)."""
    t = {}
    t0 = time.perf_counter()
    tm = surface_tetrahedra(mesh.vertices, mesh.faces)
    t["tetrahedra"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    es = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, [light],
                       make_scene(mesh.vertices, mesh.faces), material.eta)
    w = refract_in(es.directions, es.normals, material.eta)
    t["entries"] = time.perf_counter() - t0
    out = np.zeros((mesh.n_vertices, 3))
    t["operators"] = t["sources"] = t["solves"] = 0.0
    for c in range(3):
        t0 = time.perf_counter()
        op = DiffusionOperator(tm.nodes, tm.tets, D=float(material.D[c]), sigma_a=float(material.sigma_a[c]),
                               A=float(material._opt.A[c]))
        t["operators"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        pts, pw = line_sources(es.positions, w, es.power, sigma_t_prime=float(material.sigma_t_prime[c]),
                               albedo_prime=float(material.albedo_prime[c]), n_points=n_points)
        inside = igl.fast_winding_number(mesh.vertices, mesh.faces, pts) > 0.5   # the rest left the body unscattered
        t["sources_dropped_power_fraction"] = t.get("sources_dropped_power_fraction", 0.0) + \
            float(pw[~inside].sum() / pw.sum()) / 3.0
        pts, pw = pts[inside], pw[inside]
        tet, bary = locate_points(tm.nodes, tm.tets, pts)
        b = point_source_vector(tm.nodes.shape[0], tm.tets, tet, bary, pw)
        t["sources"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        out[:, c] = op.solve(b)[:tm.n_surface] / (2.0 * float(material._opt.A[c]))
        t["solves"] += time.perf_counter() - t0
    t["nodes"], t["tets"], t["faces_recovered"] = int(tm.nodes.shape[0]), int(tm.tets.shape[0]), tm.faces_recovered
    return out, t


def errors(M, ref, lit):
    peak = ref.max(axis=0)
    out = {}
    unlit = ~lit[:, None] & (ref > 1e-2 * peak)
    for label, sel in (("unlit_above_1e-2_peak", unlit), ("lit", lit[:, None] & (ref > 0))):
        out[label] = [round(float(np.mean(np.abs(M[sel[:, c], c] / ref[sel[:, c], c] - 1.0))), 4) for c in range(3)]
        out[label + "_count"] = [int(sel[:, c].sum()) for c in range(3)]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="spot_sun")
    ap.add_argument("--reference-photons", type=float, default=1e7)
    ap.add_argument("--mc-photons", type=float, default=2e6)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    mesh, light = scene(args.scene)
    mat = material_from_options("skin1")
    lit = mesh.vertex_normals @ (-np.array(light.direction)) > 0
    t0 = time.perf_counter()
    M, stages = volume_exitance(mesh, mat, light)
    wall = time.perf_counter() - t0
    ref = simulate(mesh, mat, [light], photons=int(args.reference_photons), seed=101, beam_distances=False)
    mc = simulate(mesh, mat, [light], photons=int(args.mc_photons), seed=202, beam_distances=False)
    print(json.dumps({"scene": args.scene, "vertices": int(mesh.n_vertices),
                      "volume": {"seconds": round(wall, 2), "stages": {k: round(v, 3) if isinstance(v, float) else v
                                                                         for k, v in stages.items()},
                                 **errors(M, ref.radiance, lit)},
                      "mc": {"photons": int(args.mc_photons), "seconds": round(mc.seconds, 2),
                             **errors(mc.radiance, ref.radiance, lit)},
                      "reference_photons": int(args.reference_photons), "reference_seconds": round(ref.seconds, 1)},
                     indent=1))


if __name__ == "__main__":
    main()
