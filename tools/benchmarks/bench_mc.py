"""Monte Carlo throughput (scattering events/s) of the pooled engine next to the baseline wavefront, as JSON.

    python tools/benchmarks/bench_mc.py [--photons N] [--baseline-photons M] [--threads T]

Per case: the pooled engine with Embree called from the numba threads ("fused", the default), the same engine
with one embreex call per round ("batched"), and the numpy wavefront with an Embree query every step
("baseline", fast_interior=False), all in the same run; ``speedup`` = events/s over the baseline's. ``seconds`` and
``cpu_seconds`` are the wall-clock and process CPU time (all threads) of the walk without the set-up (scene,
safe-distance grid, emitter; ``seconds_with_setup`` includes it). ``cpu_ns_per_event`` is the cost per event that
does not depend on the load; events/s on k free cores is about k * 1e9 / cpu_ns_per_event. The load average is
printed because other processes share the cores.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
import warnings

import numba
import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box, icosphere
from meshshade.light import BeamLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, simulate


def cases():
    return {
        "mcml_semi_infinite_box": (Mesh.from_arrays(*box((10.0, 10.0, 5.0))), Material(9.0, 1.0, eta=1.5),
                                   BeamLight((0.123, 0.0456, 10.0), (0, 0, -1))),
        "mcml_slab_box": (Mesh.from_arrays(*box((20.0, 20.0, 0.2))), Material(2.25, 1.0, eta=1.0, g=0.75),
                          BeamLight((0.123, 0.0456, 1.0), (0, 0, -1))),
        "skin_sphere_R10_level5": (Mesh.from_arrays(*icosphere(10.0, 5)), Material(1.0, 0.01, eta=1.3),
                                   BeamLight((0.01, 0.02, 30.0), (0, 0, -1))),
    }


def run(mesh, mat, beam, photons, **kw):
    t0 = time.perf_counter()
    r = simulate(mesh, mat, [beam], MCOptions(photons=photons, seed=1, beam_distances=False, **kw))
    total = time.perf_counter() - t0
    cpu = r.cpu_seconds
    return r, {"photons": int(r.photons), "events": int(r.events), "boundary_tests": int(r.boundary_tests),
               "tests_per_event": round(r.boundary_tests / max(r.events, 1), 3),
               "seconds": round(r.seconds, 3), "cpu_seconds": round(cpu, 3), "seconds_with_setup": round(total, 3),
               "events_per_second": float(f"{r.events_per_second:.3g}"),
               "cpu_ns_per_event": round(cpu / max(r.events, 1) * 1e9, 1),
               "diffuse_reflectance": float(np.round(r.totals["diffuse_reflectance"][0], 5)),
               "diffuse_reflectance_stderr": float(f"{r.totals['diffuse_reflectance_stderr'][0]:.2g}")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--photons", type=int, default=400_000, help="photons for the pooled engine")
    ap.add_argument("--baseline-photons", type=int, default=50_000, help="photons for the slow baseline")
    ap.add_argument("--threads", type=int, default=None, help="numba threads (default: all cores)")
    ap.add_argument("--no-batched", action="store_true", help="skip the embreex-batched variant")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    if args.threads:
        numba.set_num_threads(args.threads)
    all_cases = cases()
    warm = all_cases["mcml_slab_box"]
    for kw in ({}, {"engine": "batched"}, {"fast_interior": False}):   # numba compile / cache load
        simulate(*warm[:2], [warm[2]], MCOptions(photons=1000, beam_distances=False, **kw))
    out = {"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
           "numba_threads": numba.get_num_threads(), "load_average_before": os.getloadavg(), "cases": {}}
    for name, (mesh, mat, beam) in all_cases.items():
        res = {"faces": int(mesh.n_faces)}
        _, res["fused"] = run(mesh, mat, beam, args.photons, engine="fused")
        if not args.no_batched:
            _, res["batched"] = run(mesh, mat, beam, args.photons, engine="batched")
        _, res["baseline"] = run(mesh, mat, beam, args.baseline_photons, fast_interior=False)
        base = res["baseline"]["events_per_second"]
        res["speedup"] = {k: round(res[k]["events_per_second"] / base, 2) for k in ("fused", "batched") if k in res}
        out["cases"][name] = res
    out["load_average_after"] = os.getloadavg()
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
