"""Monte Carlo tallies: radial exitance profiles, beam radial power, the summary (files: output/mc_file.py).

Every estimate comes with its batch-means standard error (:func:`meshshade.montecarlo.simulation.batch_stats`).
No file I/O here: :func:`meshshade.output.mc_file.write_mc` writes a run's files.
"""
from __future__ import annotations

import numpy as np

from meshshade.errors import ParameterError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import BeamLight
from meshshade.materials import Material
from meshshade.montecarlo.simulation import MCOptions, MCResult, batch_stats, simulate

__all__ = ["radial_exitance", "mc_profile", "beam_radial_power", "summary_dict", "describe_mc"]


def radial_exitance(exit_distance, weight, batch, distances_mm, *, halfwidth_mm, annulus_area, n_batches,
                    entering_power):
    """Exitance per unit entering power [mm^-2] in annuli [s - h, s + h] (clipped at 0) around each distance.

    exit_distance, weight, batch : (k,) exit geodesic distance (mm), power (W), batch index
    annulus_area : callable (a, b) -> area (mm^2) of the surface between geodesic distances a and b
    Returns (value (n,), stderr (n,)).
    """
    s = np.asarray(distances_mm, dtype=np.float64)
    h = np.broadcast_to(np.asarray(halfwidth_mm, dtype=np.float64), s.shape)
    lo, hi = np.maximum(s - h, 0.0), s + h
    per = np.zeros((n_batches, s.size))
    for j in range(s.size):
        sel = (exit_distance >= lo[j]) & (exit_distance < hi[j])
        per[:, j] = np.bincount(batch[sel], weights=weight[sel], minlength=n_batches) / annulus_area(lo[j], hi[j])
    per /= entering_power
    return batch_stats(per)


def mc_profile(material: Material, distances_mm, *, shape, photons: int = 200_000, seed: int = 0,
               subdivisions: int | None = None, return_stderr: bool = False):
    """Monte Carlo reflectance profile [mm^-2] per unit entering power, (3, n), for a unit beam at a sphere's pole.

    The sphere is an icosphere of ``shape.radius_mm`` (subdivision chosen so edges are <= ~R/30, at most 6);
    the beam enters at normal incidence at the north pole; exit points are tallied against their great-circle
    distance from the pole in annuli of half-width max(0.1 s, 0.05/sigma_t'_min) (exact spherical annulus area).
    """
    if shape is None or shape.kind != "sphere":
        raise ParameterError("the Monte Carlo profile is implemented for --shape sphere only "
                             "(use `meshshade mc` on a mesh for other geometry)")
    R = float(shape.radius_mm)
    s = np.asarray(distances_mm, dtype=np.float64)
    level = subdivisions if subdivisions is not None else 5 if R <= 20 else 6
    V, F = icosphere(R, level)
    # rotate so that no vertex sits on the pole: the beam then enters inside a face
    ang = 0.0123
    rot = np.array([[1, 0, 0], [0, np.cos(ang), -np.sin(ang)], [0, np.sin(ang), np.cos(ang)]])
    mesh = Mesh.from_arrays(V @ rot.T, F)
    beam = BeamLight((0.0, 0.0, 2.0 * R + 1.0), (0.0, 0.0, -1.0), 1.0)
    res = simulate(mesh, material, [beam], MCOptions(photons=photons, seed=seed, beam_distances=False))
    h = np.maximum(0.1 * s, 0.05 / float(np.min(material.sigma_t_prime)))
    area = lambda a, b: 2.0 * np.pi * R * R * (np.cos(a / R) - np.cos(min(b / R, np.pi)))  # noqa: E731
    out = np.zeros((3, s.size))
    err = np.zeros((3, s.size))
    for c in range(3):
        ex = res.beam_exits[c]
        if ex is None:
            continue
        p = np.einsum("ij,ijk->ik", ex["bary"], mesh.vertices[mesh.faces[ex["face"]]])
        dist = R * np.arctan2(np.linalg.norm(p[:, :2], axis=1), p[:, 2])
        out[c], err[c] = radial_exitance(dist, ex["weight"], ex["batch"], s, halfwidth_mm=h, annulus_area=area,
                                         n_batches=res.n_batches, entering_power=float(res.entering_power[c]))
    return (out, err) if return_stderr else out


#: exits within this many mean edge lengths (chord) of the beam's entry point take the chord as their distance
NEAR_EXIT_EDGES = 4.0


def exit_distances(result: MCResult, mesh, face, bary) -> np.ndarray:
    """Geodesic distances [mm] of exit points (``face`` (k,), ``bary`` (k, 3)) from the first beam's entry point.

    Far from the entry point: the barycentric interpolation of ``result.beam_distance`` (the vertices' exact
    polyhedral geodesic distances). Within ``NEAR_EXIT_EDGES`` mean edge lengths: the chord, which is the geodesic
    distance to O((k s)^2 / 24) on a smooth surface (below 1e-3 there for meshes with edges under R/30), where the
    interpolation of a cone-shaped distance between vertices is not (it reads up to several times the true
    distance inside the entry face). Across a fold, where the interpolated distance exceeds twice the chord plus
    an edge, the interpolation is kept.
    """
    interp = np.einsum("ij,ij->i", bary, result.beam_distance[mesh.faces[face]])
    f0, b0 = result.beam_entry
    entry = b0 @ mesh.vertices[mesh.faces[f0]]
    points = np.einsum("ij,ijk->ik", bary, mesh.vertices[mesh.faces[face]])
    chord = np.linalg.norm(points - entry, axis=1)
    edge = mesh.mean_edge_length
    near = (chord < NEAR_EXIT_EDGES * edge) & (interp < 2.0 * chord + edge)
    return np.where(near, chord, interp)


def beam_radial_power(result: MCResult, mesh, edges_mm):
    """Exit power of the first beam's photons against geodesic distance from its entry point, per channel.

    The distance of an exit point is :func:`exit_distances` (exact polyhedral geodesic distances of the vertices
    interpolated, and the chord near the entry point). edges_mm : (k + 1,) increasing bin edges [mm].
    Returns (power (3, k) W, stderr (3, k) W).
    """
    edges = np.asarray(edges_mm, dtype=np.float64)
    out, err = np.zeros((3, edges.size - 1)), np.zeros((3, edges.size - 1))
    if result.beam_distance is None:
        raise ParameterError("no beam light (or beam_distances=False): no geodesic distance tally")
    for c, ex in enumerate(result.beam_exits):
        if ex is None:
            continue
        dist = exit_distances(result, mesh, ex["face"], ex["bary"])
        k = np.searchsorted(edges, dist, side="right") - 1
        ok = (k >= 0) & (k < edges.size - 1)
        per = np.zeros((result.n_batches, edges.size - 1))
        np.add.at(per, (ex["batch"][ok], k[ok]), ex["weight"][ok])
        out[c], err[c] = batch_stats(per)
    return out, err


# ------------------------------------------------------------------------------------------------ output
def summary_dict(result: MCResult) -> dict:
    """The JSON summary: totals (three values, or one for a grey material) with stderrs, photons, events, seconds
    (and the null collisions of a walk in a varying medium);
    for a mesh whose walk surface is not the mesh itself, ``walk_surface``: the holes closed, rims left open, lid,
    transparent and reversed faces, and the fraction of the incident power that left through the lids."""
    grey = bool(getattr(result.material, "is_grey", False))   # a painted or parted material: three values
    out = {}
    for key, val in result.totals.items():
        out[key] = float(val[0]) if grey else [float(x) for x in val]
    out.update(lost=float(result.lost[0]) if grey else [float(x) for x in result.lost],
               photons=int(result.photons), events=int(result.events),
               photons_per_channel=_per_channel(result),
               boundary_events=int(result.boundary_events), boundary_tests=int(result.boundary_tests),
               seconds=float(result.seconds), cpu_seconds=float(result.cpu_seconds),
               events_per_second=float(result.events_per_second), n_batches=int(result.n_batches),
               material=result.material.to_dict())
    if result.null_collisions:      # a varying medium's delta tracking (montecarlo/varying_walk.py)
        out["null_collisions"] = int(result.null_collisions)
    surf = result.surface
    if surf is not None and not surf.identity:   # what the walk did beyond the mesh's faces (boundary.py)
        inc = np.where(result.incident_power > 0, result.incident_power, np.nan)
        lid = result.lid_power / inc
        out["walk_surface"] = {"holes_closed": int(surf.holes), "rims_left_open": int(surf.open_loops),
                               "lid_faces": int(np.count_nonzero(surf.lid)),
                               "transparent_faces": int(surf.transparent), "reversed_faces": int(surf.reversed),
                               "lid_exit": float(lid[0]) if grey else [float(x) for x in lid]}
    return out


def _per_channel(result: MCResult) -> list[int]:
    """Photons emitted for each channel (r, g, b); every channel's tallies are normalised by its own count."""
    per = result.photons_per_channel
    return [int(result.photons)] * 3 if per is None else [int(x) for x in per]


def describe_mc(result: MCResult) -> str:
    """One line for the terminal: photons (per channel where a time budget made them differ), events, rate and the
    channel-r totals with their standard errors."""
    t = result.totals
    f = lambda k: f"{t[k][0]:.5f}±{t[k + '_stderr'][0]:.5f}"  # noqa: E731
    per = _per_channel(result)
    photons = f"{per[0]}" if len(set(per)) == 1 else "/".join(map(str, per)) + " (r/g/b)"
    return (f"mc: {photons} photons, {result.events} scattering events in {result.seconds:.2f} s "
            f"({result.events_per_second:.3g}/s); R_spec {f('specular_reflectance')}, "
            f"R_diffuse {f('diffuse_reflectance')}, T {f('transmittance')}, A {f('absorbed')} (channel r)")
