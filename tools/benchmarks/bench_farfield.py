"""Benchmark: clustered far-field dipole sum (meshshade/surface/farfield.py) against the direct sum, as JSON.

Sources and receivers are the vertices of a cube-sphere (a subdivided box pushed onto a sphere) or of a box,
lit by a directional light along -z (power = vertex area x max(0, n.z) W per unit irradiance, the same in the
three channels, so half of the receivers see only the far field). r_near = ``--near-lengths`` transport lengths
per channel; cutoff = the bake's cutoff radius (tail fraction 1e-4) clipped to the mesh's diameter.

For each case: time of the clustered sum at each tolerance and of the direct sum (cKDTree candidates + numba
kernel) in the same run, pairs touched (exact pair evaluations + cluster evaluations, per channel), their
ratio, and the max / mean relative error of M_far against the direct sum (over receivers with M_far > 0).
The direct sum is skipped when its predicted time (candidate pairs from cKDTree.count_neighbors times the
ns/pair measured in this run) exceeds ``--direct-limit-s``; the prediction is reported instead, and the errors
are measured on ``--error-subset`` random receivers (direct sum for those receivers only).

    /work/venv/bin/python tools/benchmarks/bench_farfield.py [--sizes 2000 10000 40000 100000] [--materials marble ...]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np
from scipy.spatial import cKDTree

from meshshade.surface.farfield import SourceTree, far_field_exitance, far_field_exitance_pairwise
from meshshade.geometry.procedural import box
from meshshade.materials import Material
from meshshade.surface.gather import cutoff_radii


def vertex_areas(V, F):
    A = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    out = np.zeros(len(V))
    np.add.at(out, F.ravel(), np.repeat(A / 3.0, 3))
    return out


def vertex_normals(V, F):
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    out = np.zeros_like(V)
    for k in range(3):
        np.add.at(out, F[:, k], N)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def geometry(kind: str, n_target: int, size_mm: float):
    s = max(2, int(round(np.sqrt((n_target - 2) / 6.0))))
    V, F = box(1.0, subdivisions=s)
    if kind == "sphere":
        V = V / np.linalg.norm(V, axis=1, keepdims=True) * (0.5 * size_mm)
    else:
        V = V * size_mm
    return V, F


def run_case(kind, n_target, name, args, ns_per_pair):
    m = Material.preset(name)
    V, F = geometry(kind, n_target, args.size_mm)
    power = vertex_areas(V, F) * np.clip(vertex_normals(V, F)[:, 2], 0.0, None)
    power = np.repeat(power[:, None], 3, axis=1)
    r_near = args.near_lengths / m.sigma_t_prime
    diameter = float(np.linalg.norm(V.max(0) - V.min(0)))
    cut = np.minimum(cutoff_radii(m, 1e-4), diameter)
    case = {"geometry": kind, "n": len(V), "material": name, "size_mm": args.size_mm,
            "r_near_mm": r_near.round(4).tolist(), "cutoff_mm": cut.round(4).tolist()}
    t0 = time.perf_counter()
    tree = SourceTree.build(V, power)
    case["tree_build_s"] = round(time.perf_counter() - t0, 4)
    lit = power[:, 0] > 0
    cand = int(cKDTree(V).count_neighbors(cKDTree(V[lit]), float(cut.max())))
    case["direct_candidate_pairs"] = cand
    predicted = cand * ns_per_pair.get("ns", 80.0) * 1e-9
    direct = None
    if predicted <= args.direct_limit_s:
        M_d, sd = far_field_exitance_pairwise((V, power), V, m, r_near, cut)
        direct = M_d
        case["direct"] = {"seconds": round(sd["seconds"], 3), "pairs": sd["pairs_exact"],
                          "ns_per_candidate_pair": round(sd["seconds"] / max(cand, 1) * 1e9, 2)}
        if cand > 1e6:
            ns_per_pair["ns"] = sd["seconds"] / cand * 1e9
    else:
        case["direct"] = {"skipped": f"predicted {predicted:.0f} s > {args.direct_limit_s:g} s limit",
                          "predicted_seconds": round(predicted, 1)}
    # errors are always measured: on every receiver when the direct sum ran, else on a random subset
    subset = np.arange(len(V)) if direct is not None else np.sort(
        np.random.default_rng(1).choice(len(V), size=min(len(V), args.error_subset), replace=False))
    if direct is None:
        direct = far_field_exitance_pairwise((V, power), V[subset], m, r_near, cut)[0]
        case["errors_on_random_receivers"] = len(subset)
    case["clustered"] = []
    for tol in args.tols:
        M, s = far_field_exitance(tree, V, m, r_near, cut, rel_tol=tol)
        row = {"rel_tol": tol, "seconds": round(s["seconds"], 3), "pairs_exact": s["pairs_exact"],
               "clusters_accepted": s["clusters_accepted"], "nodes_visited": s["nodes_visited"],
               "touched_per_receiver": round((s["pairs_exact"] + s["clusters_accepted"]) / len(V), 1),
               "max_bound_over_M": float(np.max(s["error_bound"] / np.where(M > 0, M, np.inf)))}
        ok = direct > 0
        err = np.abs(M[subset] - direct)[ok] / direct[ok]
        row.update(max_rel_err=float(err.max()) if err.size else 0.0,
                   mean_rel_err=float(err.mean()) if err.size else 0.0)
        if "seconds" in case["direct"]:
            row.update(speedup=round(case["direct"]["seconds"] / s["seconds"], 2),
                       pairs_ratio=round(case["direct"]["pairs"] / max(s["pairs_exact"] + s["clusters_accepted"],
                                                                        1), 2))
        else:
            row["speedup_vs_predicted"] = round(predicted / s["seconds"], 2)
        case["clustered"].append(row)
    return case


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[2000, 10000, 40000, 100000])
    ap.add_argument("--materials", nargs="+", default=["marble", "wholemilk", "skin1"])
    ap.add_argument("--geometries", nargs="+", default=["sphere", "box"])
    ap.add_argument("--tols", type=float, nargs="+", default=[1e-2, 1e-1])
    ap.add_argument("--size-mm", type=float, default=50.0, help="sphere diameter / box side [mm]")
    ap.add_argument("--near-lengths", type=float, default=3.0, help="r_near in transport lengths")
    ap.add_argument("--direct-limit-s", type=float, default=60.0)
    ap.add_argument("--error-subset", type=int, default=2000,
                    help="receivers checked against the direct sum when the full direct sum is skipped")
    args = ap.parse_args(argv)
    load_start = list(os.getloadavg())
    # warm-up: compile (or load cached) kernels outside the timings
    V, F = geometry("sphere", 200, args.size_mm)
    p = np.ones((len(V), 3))
    m = Material.preset("marble")
    far_field_exitance((V, p), V, m, 1.0, 20.0)
    far_field_exitance_pairwise((V, p), V, m, 1.0, 20.0)
    ns = {}
    cases = []
    for kind in args.geometries:
        for name in args.materials:
            for n in sorted(args.sizes):
                cases.append(run_case(kind, n, name, args, ns))
                print(json.dumps(cases[-1]), file=sys.stderr, flush=True)
    out = {"load_average_start": load_start, "load_average_end": list(os.getloadavg()),
           "cpu_count": os.cpu_count(), "cases": cases}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
