"""Speed of the "arc" geodesic neighbourhoods vs the exact window solver (same run); prints JSON.

Icospheres R = 60 mm of ~10k / 40k / 160k vertices, vertex sources, cutoff 28 mm; the window method only on the
smallest (it is ~100x slower).  Pairs per second = neighbour pairs returned / wall time of ``query``.

    python tools/benchmarks/bench_arc_neighbourhood.py                    # levels 5 6 7, 4000 sources each
    python tools/benchmarks/bench_arc_neighbourhood.py --sources 20000 --threads 2
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

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from meshshade.geometry.geodesics.arc import ArcGeodesicNeighbourhoods  # noqa: E402
from meshshade.geometry.geodesics.neighbourhoods import GeodesicNeighbourhoods  # noqa: E402
from meshshade.geometry.procedural import icosphere  # noqa: E402


def _time(solver, src, cut):
    solver.query(None, None, None, src[:8], None, cut)  # JIT warm-up
    t = time.perf_counter()
    nb = solver.query(None, None, None, src, None, cut)
    dt = time.perf_counter() - t
    return nb, dt


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[5, 6, 7])
    ap.add_argument("--sources", type=int, default=4000)
    ap.add_argument("--window-sources", type=int, default=300)
    ap.add_argument("--cutoff", type=float, default=28.0)
    ap.add_argument("--threads", type=int, default=None)
    a = ap.parse_args(argv)
    rows = []
    for j, level in enumerate(a.levels):
        V, F = icosphere(60.0, level)
        N = V / np.linalg.norm(V, axis=1, keepdims=True)
        n = len(V)
        src = np.sort(np.random.default_rng(level).choice(n, min(n, a.sources), replace=False))
        row = {"mesh": f"icosphere R=60 mm level {level}", "n_vertices": n, "cutoff_mm": a.cutoff}
        arc = ArcGeodesicNeighbourhoods(V, F, N, n_threads=a.threads)
        nb, dt = _time(arc, src, a.cutoff)
        row["arc"] = {"sources": int(src.size), "mean_neighbours": float(nb.counts.mean()),
                      "pairs_per_second": nb.n_pairs / dt, "projected_all_vertices_seconds": n * dt / src.size,
                      "fallback_fraction": arc.stats["fallback_fraction"]}
        if j == 0:
            ws = src[:a.window_sources]
            nbw, dtw = _time(GeodesicNeighbourhoods(V, F, N, n_threads=a.threads), ws, a.cutoff)
            row["window"] = {"sources": int(ws.size), "pairs_per_second": nbw.n_pairs / dtw,
                             "projected_all_vertices_seconds": n * dtw / ws.size}
            row["speedup_arc_vs_window"] = row["arc"]["pairs_per_second"] / row["window"]["pairs_per_second"]
        rows.append(row)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    print(json.dumps({"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
                      "load_average_1min_at_end": load, "results": rows}, indent=1))


if __name__ == "__main__":
    main()
