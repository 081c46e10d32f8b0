"""Monte Carlo throughput (scattering events/s), printed as JSON: python tools/bench_mc.py [--photons N]."""
from __future__ import annotations

import argparse
import json
import platform
import warnings

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box, icosphere
from meshshade.lights import BeamLight
from meshshade.materials import Material
from meshshade.montecarlo import simulate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--photons", type=int, default=100_000)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    cases = {
        "mcml_semi_infinite_box": (Mesh.from_arrays(*box((10.0, 10.0, 5.0))), Material(9.0, 1.0, eta=1.5),
                                   BeamLight((0.123, 0.0456, 10.0), (0, 0, -1))),
        "mcml_slab_box": (Mesh.from_arrays(*box((20.0, 20.0, 0.2))), Material(2.25, 1.0, eta=1.0, g=0.75),
                          BeamLight((0.123, 0.0456, 1.0), (0, 0, -1))),
        "skin_sphere_R10_level5": (Mesh.from_arrays(*icosphere(10.0, 5)), Material(1.0, 0.01, eta=1.3),
                                   BeamLight((0.01, 0.02, 30.0), (0, 0, -1))),
    }
    simulate(cases["mcml_slab_box"][0], cases["mcml_slab_box"][1], [cases["mcml_slab_box"][2]], photons=1000,
             beam_distances=False)  # numba compile / cache load
    out = {"machine": platform.processor() or platform.machine(), "photons": args.photons, "cases": {}}
    for name, (mesh, mat, beam) in cases.items():
        for fast in (False, True):
            r = simulate(mesh, mat, [beam], photons=args.photons, seed=1, beam_distances=False,
                         fast_interior=fast)
            out["cases"][f"{name}{'' if fast else '_embree_every_step'}"] = {
                "faces": int(mesh.n_faces), "events": int(r.events), "boundary_events": int(r.boundary_events),
                "seconds": round(r.seconds, 3), "events_per_second": float(f"{r.events_per_second:.3g}"),
                "diffuse_reflectance": float(np.round(r.totals["diffuse_reflectance"][0], 5))}
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
