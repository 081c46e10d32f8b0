"""Benchmark and accuracy report for meshshade.geometry.geodesics.neighbourhoods; prints one JSON document.

Speed: icospheres (R = 10 mm) of about 10k / 40k / 160k vertices, vertex sources, the cutoff chosen so that each
source has about ``--neighbours`` vertices; for each method (window = exact, fmm, dijkstra = baseline) the time per
1000 sources, pairs per second and the projected time for every vertex as a source, all in the same run.
Accuracy: relative error of each method against exact distances (great circles on icospheres, helices on a
cylinder, ``igl.exact_geodesic`` on a torus and on shared meshes when ../shared/meshes exists), for pairs beyond two
mean edge lengths.

    python tools/benchmarks/bench_neighbourhood.py                 # everything (a few minutes)
    python tools/benchmarks/bench_neighbourhood.py --quick         # smaller samples
    python tools/benchmarks/bench_neighbourhood.py --no-accuracy --threads 2 --levels 5 6 7
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from meshshade.geometry.geodesics.neighbourhoods import METHODS, GeodesicNeighbourhoods  # noqa: E402
from meshshade.geometry.procedural import capped_cylinder, icosphere, torus  # noqa: E402

SHARED = Path(os.environ.get("MESHSHADE_SHARED", ROOT.parent / "shared")) / "meshes"


def _stats(err):
    err = np.asarray(err)
    a = np.abs(err)
    return {"max_abs_rel": float(a.max()), "mean_rel": float(err.mean()), "mean_abs_rel": float(a.mean()),
            "p99_abs_rel": float(np.percentile(a, 99)), "pairs": int(err.size)}


def speed(levels, neighbours, n_sources, threads, methods, seed=0):
    out = []
    for level in levels:
        V, F = icosphere(10.0, level)
        n = len(V)
        cut = float(np.sqrt(neighbours * (4 * np.pi * 100.0 / n) / np.pi))
        rng = np.random.default_rng(seed)
        src = np.sort(rng.choice(n, min(n, n_sources), replace=False))
        row = {"mesh": f"icosphere R=10 mm level {level}", "n_vertices": n, "cutoff_mm": cut, "methods": {}}
        for method in methods:
            solver = GeodesicNeighbourhoods(V, F, method=method, n_threads=threads)
            solver.query(None, None, None, src[:8], None, cut)  # JIT warm-up (cached on disk afterwards)
            t = time.perf_counter()
            nb = solver.query(None, None, None, src, None, cut)
            dt = time.perf_counter() - t
            row["methods"][method] = {
                "sources": int(src.size), "mean_neighbours": float(nb.counts.mean()),
                "seconds_per_1k_sources": 1000 * dt / src.size, "pairs_per_second": nb.n_pairs / dt,
                "ns_per_pair": 1e9 * dt / nb.n_pairs, "projected_all_vertices_seconds": n * dt / src.size}
        out.append(row)
    return out


def _accuracy_case(name, V, F, sources, cut, reference, methods):
    res = {"mesh": name, "n_vertices": int(len(V)), "cutoff_mm": cut, "methods": {}}
    for method in methods:
        solver = GeodesicNeighbourhoods(V, F, method=method)
        h = solver.mean_edge_length
        errs, found = [], 0
        for s in sources:
            v, d = solver.query(None, None, None, [int(s)], None, cut).row(0)
            ref = reference(int(s), v)
            far = ref > 2 * h
            errs.append((d[far] - ref[far]) / ref[far])
            found += v.size
        res["methods"][method] = {**_stats(np.concatenate(errs)), "found": found}
    if "window" in res["methods"]:  # exact up to rounding: the reference neighbourhood size
        for st in res["methods"].values():
            st["found_fraction_of_exact"] = st["found"] / res["methods"]["window"]["found"]
    res["mean_edge_mm"] = h
    return res


def accuracy(methods, n_src, shared=True):
    import igl

    def exact(V, F):
        e = np.array([], np.int64)
        return lambda s, v: igl.exact_geodesic(V, F, np.array([s]), e, v.astype(np.int64), e)

    rng = np.random.default_rng(1)
    cases = []
    for level in (3, 4, 5):
        V, F = icosphere(10.0, level)
        U = V / 10.0
        cases.append(_accuracy_case(
            f"icosphere R=10 level {level} vs great circle", V, F, rng.choice(len(V), n_src, replace=False), 8.0,
            lambda s, v, U=U: 10.0 * np.arccos(np.clip(U[v] @ U[s], -1, 1)), methods))
    R = 5.0
    V, F = capped_cylinder(R, 40.0, segments=96, rings=64)
    side = np.flatnonzero((np.abs(np.hypot(V[:, 0], V[:, 1]) - R) < 1e-9) & (np.abs(V[:, 2]) < 2.0))
    th = np.arctan2(V[:, 1], V[:, 0])
    cases.append(_accuracy_case(
        "cylinder R=5 vs helix", V, F, rng.choice(side, n_src, replace=False), 12.0,
        lambda s, v: np.hypot(R * np.angle(np.exp(1j * (th[v] - th[s]))), V[v, 2] - V[s, 2]), methods))
    V, F = torus(20.0, 6.0, 120, 40)
    cases.append(_accuracy_case("torus 20/6 vs igl.exact_geodesic", V, F, rng.choice(len(V), n_src, replace=False),
                                15.0, exact(V, F), methods))
    if shared and SHARED.is_dir():
        import trimesh
        for fname, scale in (("spot.obj", 50.0), ("bunny.ply", 50.0), ("hand.obj", 100.0),
                             ("lee_perry_smith_head.obj", 10.0)):
            m = trimesh.load(SHARED / fname, process=False)
            V, F = np.asarray(m.vertices) * scale, np.asarray(m.faces, dtype=np.int64)
            cases.append(_accuracy_case(f"{fname} x{scale:g} (mm) vs igl.exact_geodesic", V, F,
                                        rng.choice(len(V), n_src, replace=False), 10.0, exact(V, F), methods))
    return cases


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--levels", type=int, nargs="+", default=[5, 6, 7], help="icosphere levels (10k/40k/160k)")
    p.add_argument("--neighbours", type=int, default=1000)
    p.add_argument("--sources", type=int, default=2000, help="sources timed per mesh and method")
    p.add_argument("--threads", type=int, default=None, help="worker threads (default: usable CPUs)")
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--accuracy-sources", type=int, default=4)
    p.add_argument("--no-accuracy", action="store_true")
    p.add_argument("--no-shared", action="store_true")
    p.add_argument("--quick", action="store_true", help="500 timed sources, 2 accuracy sources")
    a = p.parse_args(argv)
    if a.quick:
        a.sources, a.accuracy_sources = 500, 2
    threads = a.threads or len(os.sched_getaffinity(0))
    doc = {"tool": "tools/benchmarks/bench_neighbourhood.py", "argv": sys.argv[1:] if argv is None else list(argv),
           "python": platform.python_version(), "numpy": np.__version__, "threads": threads,
           "cpus_usable": len(os.sched_getaffinity(0)), "load_average_at_start": os.getloadavg()}
    t0 = time.perf_counter()
    doc["speed"] = speed(a.levels, a.neighbours, a.sources, threads, a.methods)
    if not a.no_accuracy:
        doc["accuracy"] = accuracy(a.methods, a.accuracy_sources, shared=not a.no_shared)
    doc["load_average_at_end"] = os.getloadavg()
    doc["wall_seconds"] = time.perf_counter() - t0
    json.dump(doc, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
