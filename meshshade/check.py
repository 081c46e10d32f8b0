"""``meshshade check``: what the pipeline will make of a mesh, before any long job.

``check_mesh(mesh, material=None) -> dict`` is a pure function of a validated
:class:`~meshshade.geometry.mesh.Mesh` (and optionally a :class:`~meshshade.materials.Material`);
``format_check(report) -> str`` renders it as text. The report holds:

* **size**: vertex/face counts, bounding box in mm, and (with a material) the largest extent in transport
  mean free paths ``1/sigma_t'`` per channel, so a unit mistake (a 10 m apple, a 0.01 mm head) shows at once;
* **defects**: the validation report (open boundary, non-manifold edges, degenerate faces, components,
  unreferenced vertices, winding and orientation repairs), the same lines ``load_mesh`` warns about;
* **volume**: what the default bake (the volume transport) makes of the mesh (:func:`volume_report`): whether it
  can (a flat sheet encloses nothing: the surface transport), closed or holes closed by the winding number, parts,
  vertices buried inside other parts (reported as 0), and with a material the lattice's spacing and the sampling;
* **curvature**: the principal curvatures ``k1 >= k2`` (1/mm) the bake will use (``principal_curvatures``, same
  default neighbourhood), min/max and percentiles over the vertices that faces use, the fraction of convex,
  concave and saddle vertices, the smallest radius of curvature, and how many vertices took the fallback
  curvature (``n_fallback``), of which ``n_no_plane`` have no tangent plane (their normals cancel: a non-manifold
  bow-tie vertex, faces duplicated with opposite winding, a small symmetric component; libigl would crash there,
  :mod:`meshshade.geometry.curvature`);
* **per channel** (with a material): ``z_r`` (depth of the dipole's real source, the kernel's width near the
  entry point), the diffusion length ``1/sigma_tr`` (the width of its tail), the bake's neighbourhood cutoff,
  and two verdicts:

  - *resolution*: the mean edge length ``h`` against ``z_r``. ``h <= z_r``: the kernel's peak is resolved;
    ``h <= 1/sigma_tr``: only its tail is (the bake's patch average keeps the energy right, the peak is smeared
    over one vertex area); otherwise ``unresolved``: light does not spread past one vertex, the result is
    essentially the incident light's shape.
  - *first-order validity*: the fraction of vertices where ``curvature_validity`` (kernels/curvature/coefficients.py,
    ``max(|k1|, |k2|) (|a(rho)| + |b(rho)| + z_r) <= tol``) holds. **Choice of rho:** the radius that holds
    99 % of the diffuse reflectance, ``cutoff_radii(material, 1e-2)``, clipped to the mesh's size as the bake
    clips its cutoff. At the bake's own cutoff (1e-4 of the reflectance, several times farther out) ``a(rho)``
    grows about linearly with rho and the measure would flag almost every curved vertex for light that carries
    a ten-thousandth of the energy; rho_99 asks instead whether the first-order kernel is right where the
    light is. The fraction at the bake cutoff is reported too, and so is the smallest radius of curvature
    (mm) at which first order holds at rho_99 (``tol / (|a| + |b| + 1)``, converted to mm), and, per vertex,
    the geodesic distance from an entry point there up to which it holds (65-point grid to the bake cutoff,
    on the running maximum of ``|a| + |b| + 1``), as min/max/percentiles in mm.

Everything is finite for every valid mesh and material (an infinite radius of curvature is reported as
``inf`` for a flat mesh, and the JSON writer turns non-finite numbers into ``null``).
"""
from __future__ import annotations

import json
import math

import numpy as np

from meshshade.geometry.curvature import principal_curvatures
from meshshade.kernels.curvature import VALIDITY_TOL, curvature_ratios, curvature_validity
from meshshade.materials import CHANNELS, Material
from meshshade.surface import cutoff_radii
from meshshade.volume.inside import SurfaceVolume
from meshshade.raycast import make_scene
from meshshade.volume.resolution import volume_resolution
from meshshade.volume.surface import SamplingSurface
from meshshade.volume.transport import BURIED_OFFSET_MM, SAMPLE_SPACING_OVER_H0, thin_parts

__all__ = ["check_mesh", "volume_report", "format_check", "report_to_json", "VALIDITY_RHO_TOL", "PERCENTILES"]

#: validity is judged at the radius holding all but this fraction of the diffuse reflectance (see module doc)
VALIDITY_RHO_TOL = 1e-2
#: the bake's default neighbourhood cutoff tolerance (reported alongside)
BAKE_CUTOFF_TOL = 1e-4
PERCENTILES = (1, 5, 50, 95, 99)


def _stats(x: np.ndarray) -> dict:
    pct = np.percentile(x, PERCENTILES) if x.size else np.full(len(PERCENTILES), np.nan)
    return {"min": float(x.min()), "max": float(x.max()),
            "percentiles": {str(p): float(v) for p, v in zip(PERCENTILES, pct)}}


def _resolution(h: float, z_r: float, diffusion_length: float) -> str:
    if h <= z_r:
        return "resolved"
    if h <= diffusion_length:
        return "tail only"
    return "unresolved"


def check_mesh(mesh, material: Material | None = None, *, curvature_radius_mm: float | None = None,
               tol: float = VALIDITY_TOL) -> dict:
    """Report what the pipeline will make of ``mesh`` (a validated Mesh, mm) with ``material`` (optional).

    Returns
    -------
    dict with keys ``mesh`` (counts, bbox, edge lengths), ``defects``, ``curvature`` and, with a material,
    ``material`` and ``channels`` (one dict per r, g, b); see the module docstring. Plain Python types only
    (floats, ints, str, lists, dicts), so ``json.dumps`` works after :func:`report_to_json`.
    """
    d = mesh.defects
    size = mesh.bbox_size_mm
    h = float(mesh.mean_edge_length)
    report: dict = {
        "mesh": {
            "source": mesh.source, "mm_per_unit": float(mesh.mm_per_unit),
            "n_vertices": mesh.n_vertices, "n_faces": mesh.n_faces,
            "bbox_min_mm": mesh.bbox[0].tolist(), "bbox_max_mm": mesh.bbox[1].tolist(),
            "size_mm": size.tolist(), "diagonal_mm": mesh.scale,
            "surface_area_mm2": float(mesh.total_area), "mean_edge_mm": h,
        },
        "defects": {
            "closed": bool(d.is_closed), "n_boundary_edges": d.n_boundary_edges,
            "n_nonmanifold_edges": d.n_nonmanifold_edges, "n_nonmanifold_vertices": d.n_nonmanifold_vertices,
            "n_degenerate_faces": d.n_degenerate_faces,
            "n_components": d.n_components, "n_unreferenced_vertices": d.n_unreferenced_vertices,
            "n_faces_rewound": d.n_faces_rewound, "n_components_flipped": d.n_components_flipped,
            "n_winding_conflicts": d.n_winding_conflicts, "warnings": list(d.warnings), "fixed": list(d.fixed),
        },
    }
    curv = principal_curvatures(mesh.vertices, mesh.faces, radius_mm=curvature_radius_mm)
    used = np.zeros(mesh.n_vertices, bool)
    used[mesh.nondegenerate_faces.reshape(-1)] = True  # the vertices curvature is fitted at
    k1, k2 = curv.k1[used], curv.k2[used]
    kmax = np.maximum(np.abs(k1), np.abs(k2))
    scale_k = 1e-9 / max(mesh.scale, 1e-300)  # curvature below this (1/mm) counts as flat
    peak = float(kmax.max())
    report["curvature"] = {
        "radius_mm": float(curv.radius_mm), "n_fallback": curv.n_fallback, "n_no_plane": curv.n_no_plane,
        "k1_per_mm": _stats(k1), "k2_per_mm": _stats(k2),
        "min_radius_of_curvature_mm": (1.0 / peak) if peak > 0 else math.inf,
        "fraction_convex": float(np.mean((k2 > scale_k))),
        "fraction_concave": float(np.mean((k1 < -scale_k))),
        "fraction_saddle": float(np.mean((k1 > scale_k) & (k2 < -scale_k))),
    }
    report["volume"] = volume_report(mesh, material)
    if material is None:
        return report
    report["material"] = material.to_dict()
    rho99 = np.minimum(cutoff_radii(material, VALIDITY_RHO_TOL), mesh.scale)
    rho_bake = np.minimum(cutoff_radii(material, BAKE_CUTOFF_TOL), mesh.scale)
    channels = []
    for c, name in enumerate(CHANNELS):
        ch = material.channel(c)
        st = ch["sigma_t_prime"]
        kw = {"albedo_prime": ch["albedo_prime"], "eta": ch["eta"]}
        z_r = float(material.z_r[c])
        sigma_tr = float(material.sigma_tr[c])
        diff_len = 1.0 / sigma_tr if sigma_tr > 0 else math.inf
        valid99 = curvature_validity(rho99[c] * st, kmax / st, tol=tol, **kw)
        valid_bake = curvature_validity(rho_bake[c] * st, kmax / st, tol=tol, **kw)
        a, b = curvature_ratios(rho99[c] * st, **kw)
        k_lim_opt = tol / (abs(float(a)) + abs(float(b)) + 1.0)
        # per vertex: the distance up to which first order holds (grid to the bake cutoff, monotone envelope)
        grid = np.linspace(0.0, rho_bake[c] * st, 65)
        ga, gb = curvature_ratios(grid, **kw)
        env = np.maximum.accumulate(np.abs(ga) + np.abs(gb) + 1.0)
        with np.errstate(divide="ignore"):
            idx = np.searchsorted(env, tol / kmax * st, side="right")
        valid_dist = np.where(idx > 0, grid[np.maximum(idx - 1, 0)], 0.0) / st
        channels.append({
            "channel": name, "sigma_t_prime_per_mm": st, "albedo_prime": ch["albedo_prime"],
            "transport_length_mm": 1.0 / st, "z_r_mm": z_r, "diffusion_length_mm": diff_len,
            "size_in_transport_lengths": (size * st).tolist(),
            "largest_extent_in_transport_lengths": float(size.max() * st),
            "validity_rho_mm": float(rho99[c]), "bake_cutoff_mm": float(rho_bake[c]),
            "fraction_first_order_valid": float(np.mean(valid99)),
            "fraction_first_order_valid_at_bake_cutoff": float(np.mean(valid_bake)),
            "min_valid_radius_of_curvature_mm": 1.0 / (k_lim_opt * st),
            "first_order_distance_mm": _stats(valid_dist),
            "mean_edge_over_z_r": h / z_r, "mean_edge_over_diffusion_length": h / diff_len,
            "resolution": _resolution(h, z_r, diff_len),
        })
    report["channels"] = channels
    report["validity_tol"] = float(tol)
    return report


def volume_report(mesh, material: Material | None = None) -> dict:
    """What the default bake (the volume transport, docs/physics.md §15) will do with ``mesh``: whether it can
    (a flat sheet encloses nothing: the surface transport instead), its inside (closed, or holes closed by the
    winding number), parts (baked as their union), vertices buried in other parts (reported as 0) and, with a
    material, the lattice's spacing and the surface it samples."""
    d = mesh.defects
    out = {"closed": bool(d.is_closed), "parts": int(d.n_components), "buried_vertices": 0}
    flat = not (float(np.min(mesh.bbox_size_mm)) > 0.0)
    out["transport"] = "surface (the mesh is flat: a sheet encloses no volume)" if flat else "volume"
    if not flat and d.n_components > 1:
        inside = SurfaceVolume(mesh.vertices, mesh.nondegenerate_faces)
        offset = min(BURIED_OFFSET_MM, 0.1 * float(mesh.mean_edge_length))
        out["buried_vertices"] = int(inside.buried(mesh.vertices, mesh.vertex_normals, offset).sum())
    if material is not None and not flat:
        res = volume_resolution(material, float(mesh.total_area), mesh.bbox_size_mm)
        spacing = SAMPLE_SPACING_OVER_H0 * res.h0
        S = SamplingSurface(mesh, spacing).samples
        # where the lattice is finer (physics §15.2): the thin parts as the bake finds them, and the edges of light
        # where the material calls for it
        _, _, thin_fraction = thin_parts(S, res, make_scene(S.vertices, S.faces))
        out.update({"lattice_mm": float(res.h0), "lattice_limited_by": res.limited_by, "lattice_reason": res.reason,
                    "sample_spacing_mm": float(spacing), "sampling_vertices": int(S.n_vertices),
                    "thin_below_mm": float(res.thin_below),
                    "thin_fraction": thin_fraction,
                    "edges_refined_mm": float(res.refine_radius)})
    return out


def _g(x) -> str:
    return f"{x:.4g}" if isinstance(x, (int, float)) else str(x)


def format_check(report: dict) -> str:
    """Human-readable multi-line rendering of :func:`check_mesh`'s report."""
    m, d, c = report["mesh"], report["defects"], report["curvature"]
    sx, sy, sz = m["size_mm"]
    lines = [f"mesh: {m['source'] or '(in memory)'}: {m['n_vertices']} vertices, {m['n_faces']} faces, "
             f"{sx:.4g} x {sy:.4g} x {sz:.4g} mm (mm_per_unit {m['mm_per_unit']:g}), mean edge "
             f"{m['mean_edge_mm']:.4g} mm, area {m['surface_area_mm2']:.4g} mm^2"]
    state = "closed" if d["closed"] else "NOT closed"
    lines.append(f"defects: {state}, {d['n_components']} component(s)"
                 + ("" if d["warnings"] or d["fixed"] else ", none found"))
    lines += [f"  warning: {w}" for w in d["warnings"]] + [f"  fixed: {f}" for f in d["fixed"]]
    k1, k2 = c["k1_per_mm"], c["k2_per_mm"]
    lines.append(f"curvature (1/mm, fit radius {c['radius_mm']:.4g} mm): k1 {k1['min']:.4g} .. {k1['max']:.4g} "
                 f"(median {k1['percentiles']['50']:.4g}), k2 {k2['min']:.4g} .. {k2['max']:.4g} (median "
                 f"{k2['percentiles']['50']:.4g}); smallest radius {_g(c['min_radius_of_curvature_mm'])} mm; "
                 f"convex {100 * c['fraction_convex']:.1f}%, concave {100 * c['fraction_concave']:.1f}%, "
                 f"saddle {100 * c['fraction_saddle']:.1f}%"
                 + (f"; {c['n_fallback']} vertices filled from neighbours" if c["n_fallback"] else "")
                 + (f" ({c['n_no_plane']} without a tangent plane: the normals cancel there, e.g. a bow-tie vertex; "
                    "libigl's fit was not run on them)" if c.get("n_no_plane") else ""))
    v = report["volume"]
    line = f"default bake: {v['transport']} transport"
    if v["transport"] == "volume":
        line += (", closed" if v["closed"] else ", holes closed by the winding number") + (
            f", {v['parts']} parts baked as their union" if v["parts"] > 1 else "")
        if v["buried_vertices"]:
            line += f", {v['buried_vertices']} vertices buried inside other parts (reported as 0)"
        if "lattice_mm" in v:
            half = 0.5 * v["lattice_mm"]
            finer = [f"on {100 * v['thin_fraction']:.1f}% of the surface (parts thinner than "
                     f"{v['thin_below_mm']:.3g} mm)"]
            if v["edges_refined_mm"] > 0:
                finer.insert(0, f"within {v['edges_refined_mm']:.3g} mm of edges of light")
            line += (f"; lattice {v['lattice_mm']:.3g} mm ({v.get('lattice_reason', v['lattice_limited_by'])}), "
                     f"{half:.3g} mm {' and '.join(finer)}; light sampled every "
                     f"{v['sample_spacing_mm']:.3g} mm on {v['sampling_vertices']} points")
    lines.append(line)
    if "channels" not in report:
        lines.append("material: none given (add --material NAME or --sigma-s-prime/--sigma-a for sizes in "
                     "transport lengths, resolution and first-order validity)")
        return "\n".join(lines)
    mat = report["material"]
    lines.append(f"material: {mat['name']} (sigma_s' {mat['sigma_s_prime_per_mm']}, sigma_a "
                 f"{mat['sigma_a_per_mm']} 1/mm, eta {mat['eta']:g})")
    for ch in report["channels"]:
        lines.append(
            f"  {ch['channel']}: largest extent {ch['largest_extent_in_transport_lengths']:.4g} transport lengths "
            f"(1/sigma_t' = {ch['transport_length_mm']:.4g} mm); z_r {ch['z_r_mm']:.4g} mm, diffusion length "
            f"{_g(ch['diffusion_length_mm'])} mm; mean edge = {ch['mean_edge_over_z_r']:.3g} z_r "
            f"({ch['resolution']}); first order holds at {100 * ch['fraction_first_order_valid']:.1f}% of "
            f"vertices (rho {ch['validity_rho_mm']:.4g} mm, radius of curvature >= "
            f"{ch['min_valid_radius_of_curvature_mm']:.4g} mm), "
            f"{100 * ch['fraction_first_order_valid_at_bake_cutoff']:.1f}% "
            f"at the bake cutoff {ch['bake_cutoff_mm']:.4g} mm; it holds out to a distance of "
            f"{ch['first_order_distance_mm']['percentiles']['50']:.3g} mm from the median vertex "
            f"(5th percentile {ch['first_order_distance_mm']['percentiles']['5']:.3g} mm)")
    return "\n".join(lines)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def report_to_json(report: dict) -> str:
    """The report as JSON text (non-finite numbers become ``null``)."""
    return json.dumps(_jsonable(report), indent=2, allow_nan=False) + "\n"
