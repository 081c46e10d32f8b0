"""The direct sum of the bake: every (entry sample, vertex) pair within the cutoff, by zones.

:func:`direct_sum` runs, for the entry samples it is given: the near/far split of the far field, the auto plan,
the zones (zones.py), the gather per zone (gather.py), the clustered far field (farfield.py) and the first beam's
distance field. :func:`~meshshade.surface.baking.surface_bake` calls it for ``transport="direct"``, where the
hierarchical transport does not hold, and for the beams' point samples.
"""
from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from meshshade.light import BeamLight
from meshshade.progress import Progress, kernel_interrupts
from meshshade.surface.auto import AutoPlan, neighbourhood_curvature, plan_sources
from meshshade.surface.farfield import far_field_exitance, far_field_exitance_pairwise
from meshshade.surface.gather import PairStream, chunk_size, gather
from meshshade.surface.medium import SurfaceMedium
from meshshade.surface.options import SurfaceOptions
from meshshade.surface.source_factors import drift_angles, refracted_drift
from meshshade.surface.pair_kernel import PairKernel, source_frames
from meshshade.surface.patch_average import PATCH_AVERAGE_RADII, source_patch_radius
from meshshade.surface.zones import NEAR_MARGIN, ZONES, assign_zones, groups_pay, neighbourhood_solver

log = logging.getLogger("meshshade")


def direct_sum(mesh, medium: SurfaceMedium, lights, samples, curv, cut, clock, model: str, options: SurfaceOptions,
               progress: bool | str = False):
    """The direct sum of model ``model`` in ``medium`` (the bake's SurfaceMedium) with ``options`` over
    ``samples``: (M, beam distance, stats, AutoPlan or None, kernel stats)."""
    far_geodesic, geodesic, rtol = options.far_geodesic, options.geodesic, options.rtol
    source_model = options.source_model_of(model)
    frames = source_frames(samples, curv, mesh.faces)
    far_field, near = _near_radius(mesh, medium, samples, cut, options.far_field_of(model))
    plan = None
    if model == "auto":
        plan = _auto_plan(mesh, medium, samples, curv, frames, cut, near, far_field, geodesic, options.auto)
        clock.lap("auto")
    if plan is not None and far_geodesic == "shared" and not groups_pay(mesh, cut):
        far_geodesic = "none"  # small mesh or short cutoff: shared far-zone geodesics would not save work
    zone = assign_zones(len(samples), samples.vertex >= 0, far_field, geodesic, plan, far_geodesic)
    clustered, src_cut, chord_cut = _gather_radii(zone, cut, near)
    groups = _zone_groups(zone)
    factors = medium.near                          # the near field's factors with the beam source model, else None
    kernel = PairKernel(model, medium, frames, rtol=rtol, plan=plan, near=factors, sphere=medium.sphere,
                        reach_mm=cut)
    kernel.pair_points = (samples.positions, mesh.vertices, mesh.vertex_normals, curv.k1, curv.k2, curv.d1)
    if factors is not None:
        kernel.source_scale = factors.incidence_scale(samples.cos_incidence)
        kernel.source_drift = drift_angles(refracted_drift(frames.normals, samples.directions, medium.eta),
                                           frames.d1, frames.d2)
    methods = {m for z, _ in groups for m in ZONES[z].solver_methods}
    solvers = {m: neighbourhood_solver(m, mesh) for m in methods}
    clock.lap("neighbourhoods")
    stats = {"entry_samples": len(samples), "cutoff_mm": cut.tolist(), **samples.stats,
             **{f"zone_{ZONES[z].name}": int(idx.size) for z, idx in groups}}
    if plan is not None:
        stats.update(plan.counts())
        log.info(plan.describe())
    M, beam_distance = np.zeros((mesh.n_vertices, 3)), None
    if len(samples):
        stream = PairStream(mesh, samples, frames, solvers, cut, near, src_cut, chunk_size(mesh, src_cut), clock)
        M, gstats = _gather_near(kernel, stream, groups, chord_cut, progress)
        stats.update(gstats)
        if np.any(clustered):
            M_far, fstats = _far_field(samples, clustered, mesh, medium, near, cut, far_field, options.far_rel_tol,
                                       None if factors is None else kernel.source_scale,
                                       None if factors is None else (factors.log_ratio_table(),
                                                                     *factors.slope_table(0)[1:]))
            M += M_far
            stats.update(fstats)
            clock.lap("far field")
        beam_distance = _beam_distance(mesh, samples, lights, zone, solvers, src_cut)
        if beam_distance is not None:
            clock.lap("neighbourhoods")
    return M, beam_distance, stats, plan, kernel.stats


def subset_samples(samples, mask):
    """The EntrySamples rows ``mask`` (per-light totals unchanged)."""
    return replace(samples, **{k: getattr(samples, k)[mask] for k in
                               ("positions", "face", "bary", "vertex", "normals", "power", "cos_incidence",
                                "light_index", "directions")})


def merge_plans(vertex_plan, point_plan, point):
    """The AutoPlan of all entry samples from that of the vertex samples (``~point``) and of the others."""
    out = {}
    for name in ("kernel", "exact_geodesic", "far_dipole"):
        a, b = getattr(vertex_plan, name), getattr(point_plan, name)
        arr = np.array(a, copy=True)
        arr[point] = b
        out[name] = arr
    return AutoPlan(**out)


def _near_radius(mesh, medium, samples, cut, far_field: str) -> tuple[str, np.ndarray]:
    """``(far_field, near)``: r_near (3,) mm per channel, the chord radius beyond which the pairs of vertex
    samples go to the far-field sum (the cutoff ``cut`` when there is none); far_field becomes "off" when r_near
    reaches the cutoff in every channel. The far radius is the medium's (SurfaceMedium.far_mm, at its far_tol)."""
    area = samples.vertex >= 0  # vertex samples of directional and point lights
    near = cut.copy()
    if far_field != "off" and np.any(area):
        # the far field is a point-to-point sum: keep every pair that needs the source-patch average near
        a_max = float(source_patch_radius(samples, mesh.vertex_areas)[area].max())
        near = np.minimum(np.maximum(medium.far_mm, PATCH_AVERAGE_RADII * a_max), cut)
    if not np.any(near < cut):
        far_field = "off"
    return far_field, near


def _auto_plan(mesh, medium, samples, curv, frames, cut, near, far_field, geodesic, tolerances):
    """The AutoPlan of the entry samples: curvature maxima within each sample's near radius and cutoff, then
    :func:`~meshshade.surface.auto.plan_sources` (exact geodesics switched off when ``geodesic`` is "arc")."""
    k = len(samples)
    area = samples.vertex >= 0
    near_radius = (np.where(area, NEAR_MARGIN * near.max(), cut.max()) if far_field != "off"
                   else np.full(k, cut.max()))
    # per sample: max |k| within the near radius, and max |k| and max (-k2) within the cutoff
    vals = np.stack([np.maximum(np.abs(curv.k1), np.abs(curv.k2)), -curv.k2], axis=1)
    kn_near, kn_far = neighbourhood_curvature(samples, vals, mesh.vertices, mesh.faces, [near_radius, cut.max()],
                                              mesh.mean_edge_length)
    k_near, k_far, kmin_far = kn_near[:, 0], kn_far[:, 0], -kn_far[:, 1]
    plan = plan_sources(frames.k1, frames.k2, k_near, k_far, medium, near_radius, cut, kmin_far=kmin_far,
                        **tolerances.keywords())
    if geodesic != "exact":
        plan = replace(plan, exact_geodesic=np.zeros(k, dtype=bool))
    return plan


def _gather_radii(zone, cut, near):
    """Per source: ``clustered`` (k,) bool (its pairs beyond r_near go to the far sum), the geodesic gather
    radius ``src_cut`` (k, 3) mm and the chord limit ``chord_cut`` (k, 3) mm per channel.

    Clustered sources keep the near pairs by *chord* <= r_near (the far-field sum takes chord > r_near, so nothing
    is counted twice), found within a geodesic radius NEAR_MARGIN r_near (pairs with a short chord but a longer
    geodesic lie across a fold or gap and are dropped; README: 0.4-2.5 % of near pairs on bumpy scans, none on
    flat surroundings)."""
    clustered = np.array([z.far_field for z in ZONES])[zone]
    src_cut = np.where(clustered[:, None], NEAR_MARGIN * near[None, :], cut[None, :])
    chord_cut = np.where(clustered[:, None], near[None, :], np.inf)
    return clustered, src_cut, chord_cut


def _zone_groups(zone) -> list:
    """``(zone index, source indices)`` of every zone that has sources, in zone order."""
    groups = [(z, np.flatnonzero(zone == z)) for z in range(len(ZONES))]
    return [(z, idx) for z, idx in groups if idx.size]


def _gather_near(kernel, stream: PairStream, groups, chord_cut, progress) -> tuple[np.ndarray, dict]:
    """The geodesic gather of every zone (the near zone of clustered sources): M (n, 3) W/mm^2 and counts.

    ``progress``: False, True or the task named in the progress lines (default "bake"); the sources done are
    counted in :class:`~meshshade.progress.Progress` (a bar on a terminal, periodic lines otherwise)."""
    mesh, samples = stream.mesh, stream.samples
    stream.bar = Progress(progress if isinstance(progress, str) else "bake", len(samples), "sources",
                          enabled=bool(progress))
    with stream.bar:  # also on KeyboardInterrupt: the bar clears its line before the error message is printed
        M, stats = gather(kernel, mesh.n_vertices, samples.power, stream.src_cut, stream.pairs(groups),
                          source_radius=source_patch_radius(samples, mesh.vertex_areas), chord_cutoff_mm=chord_cut,
                          receiver_radius=np.sqrt(mesh.vertex_areas / np.pi))
    return M, {**stats, "pairs_found": stream.pairs_found, "geodesic_pairs_computed": stream.geodesic_pairs}


def _far_field(samples, clustered, mesh, medium, near, cut, far_field: str, far_rel_tol: float, scale=None,
               near_ratio=None):
    """The far field of the clustered sources (pairs with chord beyond r_near): M (n, 3) W/mm^2 and stats.
    ``scale`` (k, 3) or None: per-sample, per-channel power factors (the near field's incidence scale); channels
    whose factors differ are summed in separate passes; ``near_ratio``: the near field's factor N(r) per pair
    (farfield.far_field_exitance). The planar dipole of the chord from each entry point: the light's sideways drift
    (docs/physics.md §13.4) is left out here, beyond r_near, where the far field carries the kernel's faint tail
    (``far_tol``)."""
    fn = far_field_exitance if far_field == "clustered" else far_field_exitance_pairwise
    pos = samples.positions[clustered]
    columns = [None] if scale is None else [0, 1, 2]
    M = np.zeros((mesh.n_vertices, 3))
    done: list = []
    for c in columns:
        power = samples.power[clustered] * (1.0 if c is None else scale[clustered, c])
        if c is not None:
            j = next((k for k in done if np.array_equal(scale[clustered, k], scale[clustered, c])), None)
            if j is not None:
                M[:, c] = M[:, j]
                continue
            done.append(c)
        with kernel_interrupts():  # numba in this thread: a Ctrl-C is a KeyboardInterrupt, not a SystemError
            Mc, fstats = fn((pos, power), mesh.vertices, medium, near, cut, rel_tol=far_rel_tol,
                            near_ratio=near_ratio)
        if c is None:
            M = Mc
        else:
            same = [k for k in range(3) if np.array_equal(scale[clustered, k], scale[clustered, c])]
            M[:, same] = Mc[:, same]
    return M, {"far_field": far_field, "near_mm": near.tolist(), "far_field_rel_tol": far_rel_tol,
               "far_pairs_exact": fstats["pairs_exact"], "far_clusters_accepted": fstats.get("clusters_accepted", 0)}


def _beam_distance(mesh, samples, lights, zone, solvers, src_cut):
    """(n,) mm geodesic distance of every vertex from the first beam's entry point (inf beyond its gather radius),
    by the geodesic method of that sample's zone; None without a beam."""
    first_beam = next((i for i, L in enumerate(lights) if isinstance(L, BeamLight)), None)
    if first_beam is None:
        return None
    j = int(np.flatnonzero(samples.light_index == first_beam)[0])
    nb = solvers[ZONES[zone[j]].inner_method].query(samples.positions[j:j + 1], samples.face[j:j + 1],
                                                    samples.bary[j:j + 1], samples.vertex[j:j + 1],
                                                    samples.normals[j:j + 1], src_cut[j].max())
    out = np.full(mesh.n_vertices, np.inf)
    out[nb.vertex] = nb.distance
    return out


# ------------------------------------------------------------------------------------------------ reporting
