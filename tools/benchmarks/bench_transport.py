"""Benchmark the hierarchical transport against the direct sum (issue 13): cost vs vertex count, accuracy, MC ratio.

Rows (JSON, one object per line on stdout):

* ``scaling``: icospheres of 20 mm (sigma_s' = 1, sigma_a = 0.01 /mm, eta 1.3: the issue's low-absorption
  sphere) at levels 3..--max-level, one directional light, ``--model`` (default auto): wall time of
  ``bake(transport="hierarchical")`` and, up to --direct-max-level, of ``transport="direct"`` in the same run,
  with the hierarchical result's mean / p99 relative error against the direct one (vertices above 1e-3 of the
  peak) and the fitted cost exponents (log time vs log vertices);
* ``mc``: the 10k-vertex sphere (level 5, skin1, sun light): the default bake against ``mc --photons 2e6`` on the
  same mesh, wall times and their ratio;
* ``distance_check``: the hierarchical far field's distance check (hierarchical.far_distance_check) on the shared
  meshes (spot, bob, the head at 200 mm; skipped without ../shared): the near radius it chooses, or why the bake
  falls back to the direct sum.

    python tools/benchmarks/bench_transport.py [--max-level 6] [--direct-max-level 5] [--model auto] [--quick]
    python tools/benchmarks/bench_transport.py --plot rows.jsonl [rows2.jsonl ...] \
        --out docs/images/transport_scaling.png
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.io import read_mesh_arrays
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.montecarlo.simulation import simulate
from meshshade.transport.baking import bake
from meshshade.surface.gather import cutoff_radii
from meshshade.surface.hierarchical import far_distance_check
from meshshade.montecarlo import MCOptions
from meshshade.transport import BakeOptions, SurfaceOptions

SHARED = Path(__file__).resolve().parents[3] / "shared" / "meshes"
LOW_ABSORPTION = Material([1.0, 1.0, 1.0], [0.01, 0.01, 0.01], eta=1.3, name="sigma_s'=1, sigma_a=0.01")
SUN = DirectionalLight((0.3, -0.4, -1.0), 1.0)


def _errors(M, R):
    m = R[:, 0] > 1e-3 * R[:, 0].max()
    e = np.abs(M[m, 0] - R[m, 0]) / R[m, 0]
    return float(e.mean()), float(np.percentile(e, 99))


def _timed(fn):
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def scaling(args):
    rows = []
    for level in range(3, args.max_level + 1):
        mesh = Mesh(*icosphere(10.0, level))
        h, th = _timed(lambda: bake(mesh, LOW_ABSORPTION, [SUN], BakeOptions(
            model=args.model, surface=SurfaceOptions(transport="hierarchical"))))
        row = {"kind": "scaling", "model": args.model, "level": level, "vertices": mesh.n_vertices,
               "hierarchical_s": round(th, 3), "timings": {k: round(v, 3) for k, v in h.timings.items()},
               "far_clusters": h.stats.get("far_clusters"), "far_pairs": h.stats.get("far_pairs"),
               "near_pairs": h.stats.get("near_pairs")}
        if level <= args.direct_max_level:
            d, td = _timed(lambda: bake(mesh, LOW_ABSORPTION, [SUN], BakeOptions(
                model=args.model, surface=SurfaceOptions(transport="direct"))))
            mean, p99 = _errors(h.radiance, d.radiance)
            row.update(direct_s=round(td, 3), speedup=round(td / th, 1), mean_rel_err=mean, p99_rel_err=p99)
        rows.append(row)
        print(json.dumps(row), flush=True)
    for key in ("hierarchical_s", "direct_s"):
        pts = [(r["vertices"], r[key]) for r in rows if key in r and r["level"] >= 4]
        if len(pts) >= 2:
            n, t = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
            print(json.dumps({"kind": "exponent", "transport": key[:-2], "model": args.model,
                              "cost_exponent": round(float(np.polyfit(n, t, 1)[0]), 2),
                              "levels": [r["level"] for r in rows if key in r and r["level"] >= 4]}), flush=True)


def mc_ratio(args):
    mesh = Mesh(*icosphere(10.0, 5))
    skin = Material.preset("skin1")
    b, tb = _timed(lambda: bake(mesh, skin, [SUN], BakeOptions(model="auto")))
    _, tm = _timed(lambda: simulate(mesh, skin, [SUN], MCOptions(photons=2_000_000, seed=1, beam_distances=False)))
    print(json.dumps({"kind": "mc", "vertices": mesh.n_vertices, "bake_auto_s": round(tb, 3),
                      "transport": b.stats["transport"], "mc_2e6_s": round(tm, 3), "mc_over_bake": round(tm / tb, 1)}),
          flush=True)


def distance_checks(args):
    skin = Material.preset("skin1")
    for name, size in (("spot.obj", 50.0), ("bob.obj", 50.0), ("lee_perry_smith_head.obj", 200.0)):
        path = SHARED / name
        if not path.exists():
            print(f"skipping {name}: {path} not found", file=sys.stderr)
            continue
        V, F = read_mesh_arrays(path)
        mesh = Mesh((V - V.mean(axis=0)) * (size / np.ptp(V, axis=0).max()), F)
        cut = np.minimum(cutoff_radii(skin, 1e-4), mesh.scale)
        chk, t = _timed(lambda: far_distance_check(mesh, skin, cut, np.sqrt(mesh.vertex_areas / np.pi)))
        print(json.dumps({"kind": "distance_check", "mesh": f"{Path(name).stem}_{size:g}mm",
                          "vertices": mesh.n_vertices, "near_patch_radii": chk["near_patch_radii"],
                          "errors": chk["errors"], "seconds": round(t, 2)}), flush=True)


def plot(paths, out):
    """Log-log plot of wall time vs vertex count from the ``scaling`` rows of one or more runs (one per model)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.2))
    for path in paths:
        rows = [json.loads(line) for line in Path(path).read_text().splitlines() if line.startswith("{")]
        rows = [r for r in rows if r.get("kind") == "scaling"]
        if not rows:
            continue
        model = rows[0]["model"]
        n = [r["vertices"] for r in rows]
        ax.loglog(n, [r["hierarchical_s"] for r in rows], "o-", label=f"hierarchical ({model})")
        d = [(r["vertices"], r["direct_s"]) for r in rows if "direct_s" in r]
        if d:
            ax.loglog(*zip(*d), "s--", label=f"direct sum ({model})")
    ax.set_xlabel("vertices (20 mm icosphere, levels 3-7)")
    ax.set_ylabel("bake wall time [s], 2 cores")
    ax.set_title("sigma_s' = 1, sigma_a = 0.01 /mm, eta 1.3, one directional light", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    tmp = Path(out).with_name(".tmp-" + Path(out).name)
    fig.savefig(tmp, dpi=120)
    tmp.replace(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plot", nargs="+", metavar="JSONL", help="plot the scaling rows of earlier runs instead")
    ap.add_argument("--out", default="docs/images/transport_scaling.png", help="the plot's file (with --plot)")
    ap.add_argument("--max-level", type=int, default=6)
    ap.add_argument("--direct-max-level", type=int, default=5)
    ap.add_argument("--model", default="auto")
    ap.add_argument("--quick", action="store_true", help="levels 3-4, no MC, no shared meshes")
    args = ap.parse_args(argv)
    if args.plot:
        plot(args.plot, args.out)
        return
    if args.quick:
        args.max_level, args.direct_max_level = 4, 4
    bake(Mesh(*icosphere(10.0, 2)), LOW_ABSORPTION, [SUN], BakeOptions(model=args.model))  # compile the numba loops
    scaling(args)
    if not args.quick:
        mc_ratio(args)
        distance_checks(args)


if __name__ == "__main__":
    main()
