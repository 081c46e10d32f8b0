"""Texels and vertices of one bake: the texture of ``--texture`` read at the vertices' UVs against the vertex bake
(issue 47).

Scene: a UV sphere (:func:`meshshade.geometry.procedural.uv_sphere`, ``--lon`` x ``--lat`` = 96 x 48, radius 20 mm)
with its longitude-latitude map (:func:`meshshade.geometry.procedural.spherical_uv`), skin1, the sun along
(0.3, -0.4, -0.866). The vertex bake is the default ``bake`` through the API; the texture is ``bake_texture`` (the
code path of ``--texture``) at ``--size`` texels per side. The texture is looked up as an engine reads it: bilinear
between the four texels around each corner's UV (texel centres at ((col + 1/2) / W, 1 - (row + 1/2) / H), the
filled image with its padding), a vertex taking the mean over its corners (one UV, except on the seam and at the
poles) but those of the faces across the seam that ``spherical_uv`` squeezes into [0, 1] (they read the texture at
the seam, not at their vertex: counted, and kept in ``texel_vs_vertex_every_corner``).

Printed (one JSON object on stdout): median and 90th percentile of |texel / vertex - 1| per channel and over the
three channels together, over (a) lit vertices (an unshadowed entry sample of positive power) and (b) every vertex
whose vertex exitance is above 1e-3 of the channel's peak; the same per corner; the split of the difference into
its causes: the vertex bake against the volume solution's own value at the vertex (``sample_exitance`` of the
sampling surface, whose first vertices are the input's) and the texture's lookup against that point value
(rasterisation, texel centres, bilinear lookup, poles); which of the two candidates the bake returned (the point
value, or the patch average of eq. (104), ``SamplingSurface.patch_average``); and how well each, drawn as vertex
colours (P1 on the input's faces), shows the solution at every covered texel (area-weighted mean and r.m.s.
difference, and the total).

With ``--mc``, rows (one JSON object each) that weigh the two candidate vertex values against Monte Carlo: the
patch average of eq. (104) and the solution's point value at the vertex, each against a ``--reference-photons``
in-mesh Monte Carlo (seed 101, kept in the asset cache ``bench-references``; its tallies are the hat-weighted patch
averages of the input mesh) with ``bench_volume.errors`` (mean |M / ref - 1| over lit vertices and over unlit ones
above 1e-2 of the peak) and the lit vertices' mean signed error, and a 2e6-photon Monte Carlo (seed 202) as the
yardstick of the reference's noise. ``--fine N``: also against a Monte Carlo on the mesh split N x N on its facets
(the same polyhedron; tallies over patches N times narrower, near point values), at the input's vertices and at
every vertex of the split mesh for three textures: the field itself (texels of point values), the vertices' patch
averages interpolated on the input's faces (texels of the same filter as the vertices) and the point values
interpolated there (vertex colours). Scenes (skin1, the sun along (0.3, -0.4, -0.866) unless said): uvsphere (the
issue's), uvsphere48 (48 x 24, edges 2.6 mm), ico3 (an icosphere of radius 20 mm, level 3: 642 vertices, edges
3 mm), spot100 (spot.obj at 100 mm from ../shared/meshes: edges 1.3 mm, a few split), and bench_volume's sphere20,
spot50 and head200 (the same references; the head is split, the others not).

    python tools/benchmarks/bench_texel_vertex.py [--size 2048] [--lon 96 --lat 48]
    python tools/benchmarks/bench_texel_vertex.py --mc [--scenes uvsphere,uvsphere48,ico3,spot100] \
        [--reference-photons 2e7] [--fine 4]
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, spherical_uv, uv_sphere
from meshshade.geometry.refine import refined_mesh
from meshshade.light import DirectionalLight
from meshshade.light.samples import entry_samples
from meshshade.materials import Material
from meshshade.montecarlo import simulate
from meshshade.geometry.uv import rasterise_uv
from meshshade.output.texture import bake_texture
from meshshade.raycast import make_scene
from meshshade.transport import bake

SUN = (0.3, -0.4, -0.866)


def uv_sphere_scene(lon: int = 96, lat: int = 48, radius: float = 20.0):
    """(mesh, uv (m, 3, 2), material, lights): the issue's UV sphere, skin1, the sun."""
    V, F = uv_sphere(radius, lat, lon)
    mesh = Mesh.from_arrays(V, F, source=f"uv_sphere {lon}x{lat} r{radius:g}")
    return mesh, spherical_uv(V, F), Material.preset("skin1"), [DirectionalLight(SUN, 1.0)]


def bilinear(image, uv):
    """(k, C): ``image`` (H, W, C) read at ``uv`` (k, 2) bilinearly between texel centres (clamped at the border),
    row 0 at v = 1, as a renderer samples a texture without mipmaps."""
    H, W = image.shape[:2]
    x = np.clip(uv[:, 0] * W - 0.5, 0.0, W - 1.0)
    y = np.clip((1.0 - uv[:, 1]) * H - 0.5, 0.0, H - 1.0)
    x0, y0 = np.minimum(np.floor(x).astype(np.int64), W - 2), np.minimum(np.floor(y).astype(np.int64), H - 2)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    return ((1 - fx) * (1 - fy) * image[y0, x0] + fx * (1 - fy) * image[y0, x0 + 1]
            + (1 - fx) * fy * image[y0 + 1, x0] + fx * fy * image[y0 + 1, x0 + 1])


def faithful_corners(mesh, uv):
    """(m * 3,) bool: the corners of faces whose UVs are their corners' own longitude and latitude: not the few
    faces across the date line that :func:`spherical_uv` squeezes back into [0, 1] (a corner of those reads the
    texture at the seam, not at its vertex), a corner at a pole taking any u."""
    P = mesh.vertices[mesh.faces]
    u = 0.5 + np.arctan2(P[..., 1], P[..., 0]) / (2.0 * np.pi)
    du = np.abs(uv[..., 0] - u)
    pole = np.hypot(P[..., 0], P[..., 1]) <= 1e-9 * np.linalg.norm(P, axis=2)
    ok = (np.minimum(du, np.abs(du - 1.0)) < 1e-9) | pole
    return np.repeat(ok.all(axis=1), 3)


def texels_at_vertices(image, mesh, uv, corners=None):
    """(per-vertex (n, 3) mean over each vertex's corners (those of ``corners`` (m * 3,) bool when given), per
    corner (m * 3, 3), the corners' vertices (m * 3,))."""
    corner_v = np.asarray(mesh.faces).ravel()
    at_corner = bilinear(image, np.asarray(uv).reshape(-1, 2))
    w = np.ones(corner_v.size) if corners is None else corners.astype(np.float64)
    count = np.bincount(corner_v, weights=w, minlength=mesh.n_vertices)[:, None]
    per_v = np.stack([np.bincount(corner_v, weights=w * at_corner[:, c], minlength=mesh.n_vertices)
                      for c in range(3)], axis=1) / np.maximum(count, 1)
    return per_v, at_corner, corner_v


def lit_vertices(mesh, material, lights):
    es = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, lights,
                       make_scene(mesh.vertices, mesh.faces), material.eta)
    lit = np.zeros(mesh.n_vertices, dtype=bool)
    lit[es.vertex[(es.vertex >= 0) & (es.power > 0)]] = True
    return lit


def spread(a, b, mask):
    """median and p90 of |a / b - 1| per channel and pooled over the channels, over rows ``mask`` (n,) or
    (n, 3) with b > 0."""
    mask = np.broadcast_to(mask[:, None] if mask.ndim == 1 else mask, a.shape) & (b > 0)
    d = np.where(mask, np.abs(a / np.where(b > 0, b, 1.0) - 1.0), np.nan)
    pooled = d[mask]
    r = lambda x: round(float(x), 5)  # noqa: E731
    return {"median": [r(np.nanmedian(d[:, c])) for c in range(3)],
            "p90": [r(np.nanpercentile(d[:, c], 90)) for c in range(3)],
            "median_all": r(np.median(pooled)), "p90_all": r(np.percentile(pooled, 90)),
            "max_all": r(pooled.max()), "count": int(pooled.size)}


def measure(lon=96, lat=48, size=2048):
    mesh, uv, material, lights = uv_sphere_scene(lon, lat)
    t = time.perf_counter()
    vertex = bake(mesh, material, lights)
    t_vertex = time.perf_counter() - t
    t = time.perf_counter()
    tex = bake_texture(mesh, material, lights, uv=uv, size=size)
    t_tex = time.perf_counter() - t
    faithful = faithful_corners(mesh, uv)
    per_v, per_c, corner_v = texels_at_vertices(tex.image, mesh, uv, faithful)
    M = np.asarray(vertex.radiance)
    point = np.asarray(vertex.sample_exitance)[:mesh.n_vertices]          # the solution at the input's vertices
    lit = lit_vertices(mesh, material, lights)
    bright = M > 1e-3 * M.max(axis=0)
    masks = {"lit": lit, "above_1e-3_peak": bright}
    patch = np.asarray(patch_average(vertex))
    texel, face, bary, _ = rasterise_uv(uv, size, size)
    field = tex.image.reshape(-1, 3)[texel]
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    weight = mesh.face_areas[face] / np.where(uv_area[face] > 0, uv_area[face], np.inf)   # mm^2 per texel
    engine = {k: vertex_colours(values, mesh, face, bary, field, weight) for k, values in
              (("patch_average", patch), ("point_value", point))}
    return {"scene": f"uv_sphere {lon}x{lat} r20 skin1 sun {SUN}", "vertices": int(mesh.n_vertices),
            "sampling_vertices": int(vertex.stats.get("volume_samples", mesh.n_vertices)),
            "sampling_split": bool(vertex.stats.get("volume_samples_split", False)), "texture_size": size,
            "texels_covered": int(tex.covered.sum()), "lit_vertices": int(lit.sum()),
            "seconds": {"vertex_bake": round(t_vertex, 2), "texture_bake": round(t_tex, 2)},
            "texel_vs_vertex": {k: spread(per_v, M, m) for k, m in masks.items()},
            "texel_vs_vertex_per_corner": {k: spread(per_c, M[corner_v], m.reshape(len(m), -1)[corner_v]
                                                     & faithful[:, None]) for k, m in masks.items()},
            "texel_vs_vertex_every_corner": {k: spread(per_c, M[corner_v], m[corner_v]) for k, m in masks.items()},
            "squeezed_corners": int((~faithful).sum()),
            "vertex_vs_point": {k: spread(M, point, m) for k, m in masks.items()},
            "texel_vs_point": {k: spread(per_v, point, m) for k, m in masks.items()},
            "texture_vertex_radiance_equals_bake": bool(np.array_equal(tex.vertex_radiance, M)),
            "bake_radiance_is": which(M, patch, point), "vertex_colours_vs_field": engine}


def patch_average(result):
    """Eq. (104) of a bake's field at its vertices (the code before issue 47, where ``to_vertices`` was eq. (104)
    on a split surface and the identity elsewhere, is measured with the same script)."""
    surface = result.volume.surface
    if hasattr(surface, "patch_average"):
        return surface.patch_average(result.sample_exitance)
    return surface.to_vertices(result.sample_exitance)


def which(M, patch, point):
    """Which of the two candidate vertex values the bake returned."""
    return "patch_average" if np.array_equal(M, patch) else "point_value" if np.array_equal(M, point) else "other"


def vertex_colours(values, mesh, face, bary, field, weight):
    """How well vertex values (n, 3) show the solution as an engine draws vertex colours (P1 on the input's
    faces) at every covered texel (``face``, ``bary``; ``field`` (k, 3) the texels' values, the solution's point
    values), area-weighted (``weight`` (k,) mm^2 per texel): the relative mean and r.m.s. difference and the
    relative difference of the total, per channel, over texels above 1e-3 of the channel's peak."""
    shown = np.einsum("ij,ijc->ic", bary, values[mesh.faces[face]])
    out = {"mean": [], "rms": [], "total": []}
    for c in range(3):
        keep = field[:, c] > 1e-3 * field[:, c].max()
        w, f, g = weight[keep], field[keep, c], shown[keep, c]
        out["mean"].append(round(float(np.sum(w * np.abs(g - f)) / np.sum(w * f)), 5))
        out["rms"].append(round(float(np.sqrt(np.sum(w * (g - f) ** 2) / np.sum(w * f * f))), 5))
        out["total"].append(round(float(np.sum(w * g) / np.sum(w * f) - 1.0), 6))
    return out


def mc_scene(name):
    """(mesh, material, lights, reference key) of a ``--mc`` scene, or None when its mesh is not at hand; the
    scenes of bench_volume share its references (the same key)."""
    if name in ("uvsphere", "uvsphere48"):
        mesh, _, material, lights = uv_sphere_scene(*((96, 48) if name == "uvsphere" else (48, 24)))
        return mesh, material, lights, f"texel-vertex-{name}"
    if name == "ico3":
        V, F = icosphere(20.0, 3)
        return (Mesh.from_arrays(V, F, source=name), Material.preset("skin1"), [DirectionalLight(SUN, 1.0)],
                f"texel-vertex-{name}")
    from bench_volume import SHARED, _scaled, scene
    if name == "spot100":
        if not (SHARED / "spot.obj").exists():
            return None
        return _scaled("spot.obj", 100.0), Material.preset("skin1"), [DirectionalLight(SUN, 1.0)], \
            f"texel-vertex-{name}"
    got = scene(name)
    return None if got is None else (got[0], got[1], [got[2]], name)


def signed(M, ref, lit):
    """Mean (M / ref - 1) per channel over lit vertices (its bias; bench_volume.errors gives the mean of its
    absolute value)."""
    return [round(float(np.mean(M[lit & (ref[:, c] > 0), c] / ref[lit & (ref[:, c] > 0), c] - 1.0)), 4)
            for c in range(3)]


def against_mc(name, reference_photons, mc_photons=2e6, fine=0):
    """The patch average (eq. (104)) and the point value at the vertices against Monte Carlo (module docstring);
    ``fine`` > 1: also against a Monte Carlo on the mesh split fine x fine on its facets (the same polyhedron),
    read at the input's vertices, whose tallies are averages over patches ``fine`` times narrower."""
    from bench_volume import errors, reference
    got = mc_scene(name)
    if got is None:
        return {"row": "mc", "scene": name, "skipped": "../shared/meshes not found"}
    mesh, material, lights, key = got
    result = bake(mesh, material, lights)
    point = np.asarray(result.sample_exitance)[:mesh.n_vertices]
    patch = np.asarray(patch_average(result))
    lit = lit_vertices(mesh, material, lights)
    ref, ref_s = reference(key, mesh, material, lights[0], reference_photons)
    mc = simulate(mesh, material, lights, photons=int(mc_photons), seed=202, beam_distances=False)
    row = {"row": "mc", "scene": name, "vertices": int(mesh.n_vertices),
           "sampling_vertices": int(result.stats["volume_samples"]), "reference_photons": int(reference_photons),
           "reference_seconds": round(ref_s, 1), "bake_radiance_is": which(result.radiance, patch, point),
           "patch_average": {**errors(patch, ref, lit), "lit_bias": signed(patch, ref, lit)},
           "point_value": {**errors(point, ref, lit), "lit_bias": signed(point, ref, lit)},
           f"mc_{int(mc_photons)}": errors(mc.radiance, ref, lit)}
    if fine > 1:
        row[f"against_mc_on_the_mesh_split_{fine}x{fine}"] = against_fine_mc(
            mesh, material, lights, key, fine, reference_photons, result, point, patch, lit, ref)
    return row


def points_of(mesh, fine_mesh, n):
    """(face (k,), bary (k, 3)): each vertex of ``fine_mesh`` (``mesh`` split n x n, face f's sub-faces at rows
    f n^2 ..) as a point of an input face."""
    F, Ff = mesh.faces, fine_mesh.faces
    origin = np.repeat(np.arange(F.shape[0]), n * n)
    face = np.empty(fine_mesh.n_vertices, dtype=np.int64)
    face[Ff.ravel()] = np.repeat(origin, 3)
    A, B, C = (mesh.vertices[F[face, k]] for k in range(3))
    P = fine_mesh.vertices
    e1, e2, d = B - A, C - A, P - A
    g11, g12, g22 = (np.einsum("ij,ij->i", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
    r1, r2 = np.einsum("ij,ij->i", d, e1), np.einsum("ij,ij->i", d, e2)
    det = g11 * g22 - g12 * g12
    l1, l2 = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det
    bary = np.clip(np.stack([1.0 - l1 - l2, l1, l2], axis=1), 0.0, 1.0)
    return face, bary / bary.sum(axis=1, keepdims=True)


def against_fine_mc(mesh, material, lights, key, fine, photons, result, point, patch, lit, ref):
    """The vertex values and the texture's two candidates against a Monte Carlo on the mesh split fine x fine on
    its facets (the same polyhedron; its tallies average over patches ``fine`` times narrower: near the point
    values): at the input's vertices, and at every vertex of the split mesh as a texel there would be, the field
    itself (P1 on the sampling surface: texels of point values) or the vertices' patch averages interpolated on the
    input's faces (texels of the same filter as eq. (104)'s vertices); and the point values at the input's
    vertices interpolated on its faces (vertex colours of point values)."""
    from bench_volume import errors, reference
    fmesh = refined_mesh(mesh, fine)
    fref, fs = reference(f"{key}-fine{fine}", fmesh, material, lights[0], photons)
    face, bary = points_of(mesh, fmesh, fine)
    sub, lam = result.volume.surface.locate(face, bary)
    S = result.volume.surface.samples
    field = np.einsum("ij,ijc->ic", lam, np.asarray(result.sample_exitance)[S.faces[sub]])
    filtered = np.einsum("ij,ijc->ic", bary, patch[mesh.faces[face]])
    pointwise = np.einsum("ij,ijc->ic", bary, point[mesh.faces[face]])
    flit = lit_vertices(fmesh, material, lights)
    n = mesh.n_vertices
    return {"reference_seconds": round(fs, 1), "vertices": int(fmesh.n_vertices),
            "at_the_vertices": {"patch_average": {**errors(patch, fref[:n], lit),
                                                  "lit_bias": signed(patch, fref[:n], lit)},
                                "point_value": {**errors(point, fref[:n], lit),
                                                "lit_bias": signed(point, fref[:n], lit)},
                                "mc_on_the_input": errors(ref, fref[:n], lit)},
            "at_every_split_vertex": {"texels_point_value": {**errors(field, fref, flit),
                                                             "lit_bias": signed(field, fref, flit)},
                                      "texels_same_filter": {**errors(filtered, fref, flit),
                                                             "lit_bias": signed(filtered, fref, flit)},
                                      "point_values_interpolated_on_the_input": {
                                          **errors(pointwise, fref, flit), "lit_bias": signed(pointwise, fref, flit)}}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=2048)
    ap.add_argument("--lon", type=int, default=96)
    ap.add_argument("--lat", type=int, default=48)
    ap.add_argument("--mc", action="store_true", help="the vertex values against Monte Carlo (module docstring)")
    ap.add_argument("--scenes", default="uvsphere,uvsphere48,ico3,spot100")
    ap.add_argument("--reference-photons", type=float, default=2e7)
    ap.add_argument("--fine", type=int, default=0, help="also a Monte Carlo on the mesh split N x N (--mc)")
    args = ap.parse_args(argv)
    if args.mc:
        for name in [s for s in args.scenes.split(",") if s]:
            print(json.dumps(against_mc(name, args.reference_photons, fine=args.fine)), flush=True)
        return 0
    print(json.dumps(measure(args.lon, args.lat, args.size)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
