"""The bake beside a sun-lit hole against the Monte Carlo (issue 47): how much of its deficit is light entering
through the hole.

The hand of ../shared/meshes/hand.obj at 190 mm with six holes (bench_defects.py's ``holes6``), skin1, the sun of
bench_defects.py. The default bake (``BakeResult.patch_averaged``) against two Monte Carlo runs of ``--photons``
(seed 5) with the bake's inside {w > 1/2}: as ``simulate`` walks (light enters through the lids too) and with the
lids kept dark (an experiment, not an option: the emitter's directional-light weights on the lid faces set to 0,
by replacing ``walks.make_emitter`` in this process). One JSON row: per band of distance from the rims (mm), the
lit vertices and the bake's mean signed and absolute M / MC - 1 (%, r/g/b) against each run, and the power that
enters through the lids (the incident powers' difference, % of the first).

    python tools/studies/bake_at_holes.py [--photons 2e6]
"""
from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

from meshshade.light.samples import entry_samples
from meshshade.montecarlo import MCOptions, simulate
from meshshade.raycast import make_scene
from meshshade.transport import bake

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import bench_defects as bench  # noqa: E402
import bench_open_scan_mc as open_scan  # noqa: E402

#: bands of distance from the rims (mm); [0, 0.01) holds the rims' own vertices
BANDS = ((0.0, 0.01), (0.01, 2.0), (2.0, 5.0), (5.0, 10.0), (10.0, np.inf))


def dark_lids(make_emitter):
    """``make_emitter`` whose directional and point lights put no photon into a lid face."""
    def make(mesh, surface, lights, eta, scene):
        e = make_emitter(mesh, surface, lights, eta, scene)
        for i, part in enumerate(e.parts):
            if part[0] == "area":
                w = part[2].copy()
                w[surface.lid] = 0.0
                total = float(w.sum())
                e.parts[i] = ("area", np.cumsum(w) / total, w, part[3])
                e.light_power[i] = total
        e.total_power = float(e.light_power.sum())
        e.light_cdf = np.cumsum(e.light_power) / e.total_power
        return e
    return make


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=float, default=2e6)
    args = ap.parse_args(argv)
    got = open_scan.hand_with_holes()
    if got is None:
        print(json.dumps({"row": "bake_at_holes", "skipped": f"{bench.SHARED} not found"}))
        return 0
    mesh, mat, light, _ = got
    B = np.asarray(bake(mesh, mat, [light]).patch_averaged())
    o = MCOptions(photons=int(args.photons), seed=5, beam_distances=False)
    import meshshade.montecarlo.simulation as simulation
    import meshshade.montecarlo.walks as walks
    runs = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runs["lids_lit"] = simulate(mesh, mat, [light], o)
        saved = (walks.make_emitter, simulation.make_emitter)
        walks.make_emitter = simulation.make_emitter = dark_lids(saved[0])
        try:
            runs["lids_dark"] = simulate(mesh, mat, [light], o)
        finally:
            walks.make_emitter, simulation.make_emitter = saved
    es = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, [light],
                       make_scene(mesh.vertices, mesh.faces), mat.eta)
    lit = np.zeros(mesh.n_vertices, dtype=bool)
    lit[es.vertex[(es.vertex >= 0) & (es.power > 0)]] = True
    dist = open_scan.rim_distance(mesh.vertices, mesh.faces, mesh.vertices)
    row = {"row": "bake_at_holes", "photons": int(args.photons),
           "lid_entry_%": [round(100.0 * float(x), 2) for x in
                           1.0 - runs["lids_dark"].incident_power / runs["lids_lit"].incident_power]}
    for lo, hi in BANDS:
        out = {}
        for name, run in runs.items():
            R = np.asarray(run.radiance)
            sel = lit & (dist >= lo) & (dist < hi) & np.all(R > 0, axis=1)
            r = B[sel] / R[sel] - 1.0
            out["vertices"] = int(sel.sum())
            out[f"{name}_bias_%"] = [round(100.0 * float(x), 2) for x in r.mean(axis=0)]
            out[f"{name}_abs_%"] = [round(100.0 * float(x), 2) for x in np.abs(r).mean(axis=0)]
        row[f"rims_{lo:g}_{hi:g}mm"] = out
    print(json.dumps(row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
