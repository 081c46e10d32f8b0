"""The Monte Carlo's inside on open meshes (issue 47), and the default bake against it on an open scan (issue 41).

Three JSON rows.

``sphere_holes``: a 20 mm icosphere (level 5, edges 0.76 mm) with three 3 mm holes on its lit side
(:func:`sphere_with_holes`: the faces whose centroids lie within 3 mm of three points at 30 degrees from the pole,
120 degrees apart: holes about 6 mm across), skin1, the sun straight down onto the pole. The Monte Carlo exitance
over the faces 0.5-5 mm from the rims (and in three bands within), relative to the same faces of the closed sphere,
for the walk of the faces alone (``MCOptions(inside="faces")``, the walk before issue 47: a photon walks out through
a hole) and for the default walk (the bake's inside {w > 1/2}: the holes closed by lids,
:mod:`meshshade.montecarlo.boundary`); with the standard errors of the differences (:func:`band_exitance`).
``--sphere-photons`` per run (three runs).

``walk_surface`` (:func:`walk_row`): what the walk surface costs to build (the clean hand, the hand with six
holes, a 328k-face sphere), and how well it follows the seam of two overlapping spheres.

``open_scan_mc``: the scanned hand of ../shared/meshes/hand.obj at 190 mm with six holes punched
(tools/benchmarks/mesh_defects.py, as bench_defects.py makes them: the 2-ring faces around six vertices removed),
skin1, the sun of bench_defects.py. The default ``bake`` (its model; its exitance averaged over each vertex's
patch, ``BakeResult.patch_averaged``, as the Monte Carlo tallies it), ``simulate`` with ``--photons`` (seed 202)
and a reference of ``--reference-photons`` (seed 101), both with the default inside, and the mean |M / ref - 1|
per channel (r, g, b, %) of the bake and of the smaller run over the lit vertices (an unshadowed entry sample)
that have a face: all of them (``lit_all``), those beyond D = 10 and 25 mm of the holes' centres, and those within
5 mm of a rim (``lit_rims``: the rims' own vertices included). ``mc_faces_only`` is the smaller run walked on the
faces alone, against the same reference (what the Monte Carlo did before issue 47). ``meets_target``: the bake's
error at most the smaller run's over all lit vertices, on every channel. ``bake_bias``: the bake's mean signed
M / ref - 1 (the bake lets light in through the mesh's faces only, the Monte Carlo through the lids too);
``bake_points``: the bake's own vertex values (the field at the vertex, not its patch average) against the same. Without
../shared/meshes the row is "skipped".

    python tools/benchmarks/bench_open_scan_mc.py [--rows sphere,walk,hand] [--reference-photons 2e7]
                                                  [--photons 2e6] [--sphere-photons 1e6] [--seam-photons 2e5]

The reference of 2e7 photons takes about 80-100 s of walk on 2 free cores (the whole row 3-4 minutes).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import DirectionalLight
from meshshade.light.samples import entry_samples
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, simulate
from meshshade.raycast import make_scene
from meshshade.transport import bake

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/ is not a package: the defect benchmark beside this

import bench_defects as bench  # noqa: E402
import mesh_defects as md  # noqa: E402

#: the sphere with holes: radius, icosphere level, hole radius, the holes' angle from the lit pole (mm, degrees)
SPHERE_R, SPHERE_LEVEL, HOLE_R, HOLE_POLAR = 20.0, 5, 3.0, 30.0
#: the sun on the sphere (travelling straight down onto the pole)
SPHERE_SUN = (0.0, 0.0, -1.0)
#: bands of distance from the rims (mm) in which the sphere's exitance is compared
BANDS = ((0.5, 5.0), (0.5, 1.5), (1.5, 3.0), (3.0, 5.0))
#: the hand's rim vertices: lit vertices within this distance of a rim (mm)
RIM_REACH = 5.0


def sphere_with_holes(level: int = SPHERE_LEVEL, polar_deg: float = HOLE_POLAR, hole_r: float = HOLE_R):
    """(V, F) of the closed icosphere of radius ``SPHERE_R`` and the :class:`mesh_defects.Defected` with three
    holes of radius ``hole_r`` (the faces whose centroid lies within hole_r of three surface points ``polar_deg``
    from the +z pole, 120 degrees apart)."""
    V, F = icosphere(SPHERE_R, level)
    th = np.radians(polar_deg)
    az = np.radians([0.0, 120.0, 240.0])
    centres = SPHERE_R * np.stack([np.sin(th) * np.cos(az), np.sin(th) * np.sin(az), np.full(3, np.cos(th))], 1)
    return V, F, md.cut_discs(V, F, centres, hole_r)


def rim_distance(vertices, faces, points) -> np.ndarray:
    """(k,) mm: distance from each of ``points`` (k, 3) to the nearest rim of the mesh (its boundary vertices and
    the midpoints of its boundary edges; inf without a rim)."""
    F = np.asarray(faces, dtype=np.int64)
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(e, axis=0, return_counts=True)
    rim = uniq[counts == 1]
    if rim.shape[0] == 0:
        return np.full(len(points), np.inf)
    V = np.asarray(vertices, dtype=np.float64)
    pts = np.concatenate([V[np.unique(rim)], 0.5 * (V[rim[:, 0]] + V[rim[:, 1]])])
    return cKDTree(pts).query(np.asarray(points, dtype=np.float64), k=1)[0]


def band_exitance(face_power, face_power_stderr, areas, band):
    """(value (3,), stderr (3,)) W/mm^2: the power leaving the faces ``band`` (bool mask) over their area.

    The standard error is sqrt(sum of the faces' batch-means standard errors squared) / area: each photon leaves
    through one face, so the batch tallies of different faces are negatively correlated and this bounds the
    error of the sum from above (up to the noise of the per-face estimates)."""
    area = float(np.sum(areas[band]))
    value = np.sum(face_power[band], axis=0) / area
    stderr = np.sqrt(np.sum(face_power_stderr[band] ** 2, axis=0)) / area
    return value, stderr


def sphere_row(photons: int) -> dict:
    V, F, d = sphere_with_holes()
    keep = np.setdiff1d(np.arange(F.shape[0]), d.details["removed_faces"])
    mat, sun = Material.preset("skin1"), DirectionalLight(SPHERE_SUN, 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        closed = Mesh.from_arrays(V, F)
        holed = Mesh.from_arrays(d.vertices, d.faces)
        o = MCOptions(photons=photons, seed=7, beam_distances=False)
        runs = {"closed": simulate(closed, mat, [sun], o),
                "faces_only": simulate(holed, mat, [sun], replace(o, inside="faces")),
                "winding": simulate(holed, mat, [sun], o)}
    dist = rim_distance(holed.vertices, holed.faces, holed.vertices[holed.faces].mean(axis=1))
    areas = holed.face_areas
    row = {"row": "sphere_holes", "photons": photons, "holes": runs["winding"].surface.holes,
           "lid_exit_%": [round(100.0 * float(x), 3) for x in runs["winding"].lid_power
                          / runs["winding"].incident_power],
           "seconds": {k: round(r.seconds, 1) for k, r in runs.items()}}
    for lo, hi in BANDS:
        band = (dist >= lo) & (dist <= hi)
        ref, ref_se = band_exitance(runs["closed"].face_power[keep], runs["closed"].face_power_stderr[keep],
                                    areas, band)
        out = {"faces": int(band.sum())}
        for name in ("faces_only", "winding"):
            val, se = band_exitance(runs[name].face_power, runs[name].face_power_stderr, areas, band)
            out[f"{name}_vs_closed_%"] = [round(100.0 * float(x), 2) for x in val / ref - 1.0]
            out[f"{name}_stderr_%"] = [round(100.0 * float(x), 2) for x in np.hypot(se / ref, val * ref_se / ref ** 2)]
        row[f"rims_{lo:g}_{hi:g}mm"] = out
    return row


def two_spheres(radius: float = 10.0, distance: float = 10.0, level: int = 3):
    """(V, F) of two icospheres of ``radius`` whose centres lie ``distance`` apart on x (overlapping, unwelded; the
    second turned half round about z, so that its first largest face lies outside the first sphere: the mesh's
    validation would otherwise call it a cavity and turn it inward), and the area of their union's surface scaled
    to the polyhedra: (4 pi R^2 - 2 pi R h) x 2 with h = R - d / 2, times the icosphere's area over 4 pi R^2."""
    V, F = icosphere(radius, level)
    W = V * [-1.0, -1.0, 1.0]
    poly = float(np.sum(np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1))) / 2
    h = radius - 0.5 * distance
    union = 2.0 * (4.0 * np.pi * radius ** 2 - 2.0 * np.pi * radius * h) * poly / (4.0 * np.pi * radius ** 2)
    return np.concatenate([V, W + [distance, 0.0, 0.0]]), np.concatenate([F, F + V.shape[0]]), union


def walk_row(photons: int) -> dict:
    """``walk_surface``: its cost (seconds, once warm) on the clean hand, the hand with six holes and a
    328k-face sphere; and the seam of two overlapping 10 mm spheres (level 3): the walk surface's area against the
    union's, and the red light lost at the seam (``--seam-photons``, sun from above), with the seams split to
    1/32 of an edge (the default) and with the straddling faces kept whole (``SEAM_LEVELS = 0``)."""
    from meshshade.montecarlo import boundary

    row = {"row": "walk_surface", "seconds": {}}
    meshes = {"sphere_328k": icosphere(SPHERE_R, 7)}
    got = bench.scene_arrays("hand190")
    if got is not None:
        V, F, sun = got
        meshes["hand190"] = (V, F)
        d = bench.defective("holes6", V, F, sun)
        meshes["hand190_holes6"] = (d.vertices, d.faces)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        boundary.walk_surface(Mesh.from_arrays(*icosphere(5.0, 1)))         # compiled kernels loaded
        for name, (V, F) in meshes.items():
            mesh = Mesh.from_arrays(V, F)
            t = time.perf_counter()
            s = boundary.walk_surface(mesh)
            row["seconds"][name] = round(time.perf_counter() - t, 2)
            row.setdefault("faces", {})[name] = int(mesh.n_faces)
            row.setdefault("identity", {})[name] = bool(s.identity)
        V, F, union = two_spheres()
        mesh = Mesh.from_arrays(V, F)
        if mesh.defects.n_components_flipped:
            raise SystemExit("two_spheres: a sphere was taken for a cavity")
        sun = DirectionalLight((0.0, 0.0, -1.0), 1.0)
        levels = boundary.SEAM_LEVELS
        for name, lv in (("split", levels), ("whole", 0)):
            boundary.SEAM_LEVELS = lv
            try:
                s = boundary.walk_surface(mesh)
                res = simulate(mesh, Material.preset("skin1"), [sun], MCOptions(photons=photons, seed=3,
                                                                                beam_distances=False))
            finally:
                boundary.SEAM_LEVELS = levels
            row[f"seam_{name}"] = {"area_vs_union_%": round(100.0 * (float(s.areas.sum()) / union - 1.0), 3),
                                   "split_faces": s.split_faces, "transparent": s.transparent,
                                   "lost_%": [round(100.0 * float(x), 3) for x in res.lost]}
    return row


def _errors(M, R, sel, signed: bool = False):
    """Mean |M / R - 1| (%) per channel over ``sel`` where the reference is positive (``signed``: mean M / R - 1)."""
    out = []
    for c in range(3):
        r = M[sel & (R[:, c] > 0), c] / R[sel & (R[:, c] > 0), c] - 1.0
        out.append(round(100.0 * float(np.mean(r if signed else np.abs(r))), 2))
    return out


def hand_with_holes():
    """(mesh, skin1, the sun, the holes' points) of the hand at 190 mm with six holes (mesh_defects' ``holes6``; the
    points where they were cut), or None without the shared meshes."""
    got = bench.scene_arrays("hand190")
    if got is None:
        return None
    V, F, sun = got
    d = bench.defective("holes6", V, F, sun)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = Mesh.from_arrays(d.vertices, d.faces)
    return mesh, Material.preset("skin1"), DirectionalLight(sun, 1.0), d.points


def hand_row(reference_photons: int, photons: int) -> dict:
    got = hand_with_holes()
    if got is None:
        return {"row": "open_scan_mc", "skipped": f"{bench.SHARED} not found"}
    mesh, mat, light, holes = got
    t = time.perf_counter()
    res = bake(mesh, mat, [light])
    t_bake = time.perf_counter() - t
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                     # the open mesh's note (lids), said in the docstring
        o = MCOptions(photons=photons, seed=202, beam_distances=False)
        mc = simulate(mesh, mat, [light], o)
        old = simulate(mesh, mat, [light], replace(o, inside="faces"))
        ref = simulate(mesh, mat, [light], MCOptions(photons=reference_photons, seed=101, beam_distances=False))
    es = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, [light],
                       make_scene(mesh.vertices, mesh.faces), mat.eta)
    lit = np.zeros(mesh.n_vertices, dtype=bool)
    lit[es.vertex[(es.vertex >= 0) & (es.power > 0)]] = True
    referenced = np.zeros(mesh.n_vertices, dtype=bool)
    referenced[mesh.faces.reshape(-1)] = True
    R = np.asarray(ref.radiance)
    near_rim = rim_distance(mesh.vertices, mesh.faces, mesh.vertices) <= RIM_REACH
    row = {"row": "open_scan_mc", "scene": "hand190 holes6", "model": res.model, "bake_s": round(t_bake, 2),
           "photons": photons, "mc_seconds": round(mc.seconds, 1), "reference_photons": reference_photons,
           "reference_seconds": round(ref.seconds, 1), "holes_closed": ref.surface.holes,
           "lid_exit_%": [round(100.0 * float(x), 3) for x in ref.lid_power / ref.incident_power]}
    sets = {"lit_all": referenced & lit, "lit_rims": referenced & lit & near_rim}
    for D in (10.0, 25.0):
        sets[f"lit_beyond_{int(D)}mm"] = md.far_from(mesh.vertices, holes, D) & referenced & lit
    for name, sel in sets.items():
        B = np.asarray(res.patch_averaged())
        row[name] = {"bake": _errors(B, R, sel), "mc": _errors(np.asarray(mc.radiance), R, sel),
                     "mc_faces_only": _errors(np.asarray(old.radiance), R, sel),
                     "bake_bias": _errors(B, R, sel, signed=True),
                     "bake_points": _errors(np.asarray(res.radiance), R, sel), "vertices": int(sel.sum())}
    row["meets_target"] = all(b <= m for b, m in zip(row["lit_all"]["bake"], row["lit_all"]["mc"]))
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", default="sphere,walk,hand", help="comma-separated: sphere, walk, hand")
    ap.add_argument("--reference-photons", type=float, default=2e7)
    ap.add_argument("--photons", type=float, default=2e6, help="the hand's Monte Carlo run compared with the bake")
    ap.add_argument("--sphere-photons", type=float, default=1e6)
    ap.add_argument("--seam-photons", type=float, default=2e5, help="the overlapping spheres of the walk row")
    args = ap.parse_args(argv)
    rows = [r.strip() for r in args.rows.split(",") if r.strip()]
    if "sphere" in rows:
        print(json.dumps(sphere_row(int(args.sphere_photons))), flush=True)
    if "walk" in rows:
        print(json.dumps(walk_row(int(args.seam_photons))), flush=True)
    if "hand" in rows:
        print(json.dumps(hand_row(int(args.reference_photons), int(args.photons))), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
