"""The surface models' bake: principal curvatures, the lights' entry samples on the mesh, then the hierarchical
transport of the vertex samples (hierarchical.py) where it holds, else the direct sum (direct_sum.py: the near/far
split, the auto plan, the zones, the gather per zone, the clustered far field), and the direct sum of the beams'
point samples.

:func:`meshshade.transport.bake` runs :class:`SurfaceModel` (:func:`surface_bake`) for the models ``dipole``, ``curved``,
``exact-sphere``, ``fitted`` and ``auto`` (and for the volume's fallback on a mesh that encloses nothing) and
makes its result of what this returns (:class:`SurfaceBake`).
"""
from __future__ import annotations

import logging
import time
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from meshshade import memo
from meshshade.errors import ParameterError
from meshshade.geometry.curvature import principal_curvatures
from meshshade.light import entry_samples
from meshshade.raycast import make_scene
from meshshade.surface.direct_sum import direct_sum, merge_plans, subset_samples
from meshshade.surface.hierarchical import (VERIFY_TOL, FarFieldUnsupported, SurfaceTransport, verify_far_field,
                                            vertex_drift, vertex_power)
from meshshade.surface.medium import surface_medium
from meshshade.surface.options import SurfaceOptions

log = logging.getLogger("meshshade")

__all__ = ["SurfaceModel", "SurfaceBake", "surface_bake"]


class SurfaceBake(NamedTuple):
    """What :func:`surface_bake` returns: ``radiance`` (n, 3) W/mm^2, the mesh's ``curvature``
    (PrincipalCurvatures), the ``samples`` (EntrySamples), ``beam_distance`` (n,) mm or None, ``cutoff_mm`` (3,),
    ``stats`` and the ``plan`` (AutoPlan of ``auto``, else None)."""

    radiance: np.ndarray
    curvature: object
    samples: object
    beam_distance: np.ndarray | None
    cutoff_mm: np.ndarray
    stats: dict
    plan: object


class SurfaceModel:
    """The surface models as a model of :func:`meshshade.transport.bake`: ``name`` one of "dipole", "curved",
    "exact-sphere", "fitted", "auto" (module docstring)."""

    def __init__(self, name: str):
        self.name = name

    def run(self, mesh, material, lights, options, clock, reuse=None):
        """``(SurfaceBake, None)``: :func:`surface_bake` with the bake's ``options``
        (:class:`~meshshade.transport.options.BakeOptions`: its ``surface`` record, backend and progress)."""
        return surface_bake(mesh, material, lights, self.name, options.surface, clock, backend=options.backend,
                            progress=options.progress, reuse=reuse), None


def surface_bake(mesh, material, lights, model: str, options: SurfaceOptions, clock, *, backend: str = "embree",
                 progress: bool | str = False, reuse: SurfaceTransport | None = None) -> SurfaceBake:
    """The exitance of ``mesh`` (mm) in ``material`` lit by ``lights`` (a list) with surface model ``model`` and
    ``options``; stages timed on ``clock`` (:class:`meshshade.progress.Stopwatch`). ``reuse``: a
    :class:`SurfaceTransport` built for this mesh, material, model and source model (reused across lights)."""
    source_model = options.source_model_of(model)
    # inside memo.reuse() (a batch worker) the mesh's curvature and scene are kept for the next job on this mesh
    curv = memo.cached("curvature", (id(mesh), options.curvature_radius_mm),
                       lambda: principal_curvatures(mesh.vertices, mesh.faces, radius_mm=options.curvature_radius_mm),
                       pins=(mesh,))
    clock.lap("curvature")
    scene = memo.cached("scene", (id(mesh), backend),  # face ids must index mesh.faces
                        lambda: make_scene(mesh.vertices, mesh.faces, backend=backend), pins=(mesh,))
    options = replace(options, source_model=source_model)
    # what every stage reads of the material: the cutoff radii, the near field's factors, the sphere's tables
    medium = surface_medium(material, options)
    samples = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, lights, scene=scene,
                            eta=medium.eta)
    clock.lap("rays")
    cut = np.minimum(medium.cutoff_mm, mesh.scale)
    factors = medium.near
    core, why, built = _transport(reuse, mesh, medium, model, samples, curv, options, progress)
    verified = None
    if core is not None:
        pv = vertex_power(samples, mesh.n_vertices)
        pv_c = pv
        if factors is not None:   # per channel: each sample's power times its incidence scale
            pv_c = vertex_power(samples, mesh.n_vertices, factors.incidence_scale(samples.cos_incidence))
        drift = vertex_drift(samples, mesh.n_vertices, medium.eta) if factors is not None else None
        M, hstats = core.exitance(pv_c, drift=drift, progress=progress)
        if options.transport == "auto" and reuse is None:  # the far field's distances on this light, or direct
            t_v = time.perf_counter()
            verified = verify_far_field(core, M, pv)
            hstats["timings"]["far-field check"] = time.perf_counter() - t_v
            if verified["mean"] > VERIFY_TOL[0] or verified["max"] > VERIFY_TOL[1]:
                why = (f"hierarchical far field not accurate for this light: arc-distance error of M at "
                       f"{verified['receivers']} receivers mean {verified['mean']:.2g}, max {verified['max']:.2g}")
                log.info("meshshade: %s; using the direct sum", why)
                core = None
    if core is None:
        M, beam_distance, stats, plan, kstats = direct_sum(mesh, medium, lights, samples, curv, cut, clock, model,
                                                           options, progress)
        stats["transport"] = "direct" + (f" ({why})" if why else "")
    else:
        if built:  # built by this bake (not passed in or reused): its stages count here
            clock.charge(core.timings)
        clock.charge(hstats.pop("timings"))
        point = samples.vertex < 0
        stats = {"entry_samples": len(samples), "cutoff_mm": cut.tolist(), **samples.stats, **core.stats, **hstats,
                 "transport": "hierarchical", **({"far_field_verified": verified} if verified else {})}
        plan, beam_distance, kstats = core.sample_plan(samples), None, {}
        if np.any(point):  # beams: few samples, the direct sum over their whole neighbourhoods
            sub = subset_samples(samples, point)
            Mb, beam_distance, bstats, bplan, kstats = direct_sum(mesh, medium, lights, sub, curv, cut, clock,
                                                                  model, replace(options, far_field="off"), progress)
            M = M + Mb
            stats.update({f"beam_{k}": v for k, v in bstats.items() if k in ("pairs_found", "pairs_evaluated")})
            if plan is not None and bplan is not None:
                plan = merge_plans(plan, bplan, point)
    stats.update(kstats)
    stats["near_field"] = source_model   # the stats key keeps its name: outputs and reports read it
    if factors is not None and factors.clamped:
        stats["near_field_clamped"] = True   # a channel outside the fitted domain: its nearest node is used
    return SurfaceBake(M, curv, samples, beam_distance, cut, stats, plan)


def _transport(reuse, mesh, medium, model, samples, curv, options: SurfaceOptions, progress):
    """``(SurfaceTransport or None, reason, built)``: the hierarchical transport of the vertex samples in ``medium``
    (SurfaceMedium), or None for the direct sum (asked for, no vertex samples, or ``transport="auto"`` on a mesh
    where it is not accurate); ``built``: whether this call built it (not passed in, nor reused from
    :mod:`meshshade.memo`)."""
    if reuse is not None:
        if (reuse.mesh is not mesh or reuse.material.describe() != medium.describe() or reuse.model != model
                or reuse.source_model != options.source_model):
            raise ParameterError("the SurfaceTransport passed as reuse was built for another mesh, material, "
                                 "model or source model")
        return reuse, None, False
    if options.transport == "direct":
        return None, None, False
    if options.transport == "auto" and options.direct_options:
        return None, "direct-sum options given", False
    if not np.any(samples.vertex >= 0):
        return None, "no vertex samples", False
    # inside memo.reuse() (a batch worker) the transport (or the verdict that it does not apply) is kept for
    # further lights on this mesh, material, model and options
    key = (id(mesh), medium.describe(), model, id(curv), options)
    built = []

    def build():
        built.append(True)
        return _build(mesh, medium, model, curv, options, progress)

    core, why = memo.cached("transport", key, build, pins=(mesh, curv))
    return core, why, bool(built)


def _build(mesh, medium, model, curv, options: SurfaceOptions, progress):
    if options.transport == "hierarchical":
        try:
            return SurfaceTransport.build(mesh, medium, model, options, curvature=curv, progress=progress), None
        except FarFieldUnsupported as e:
            worst = e.check["errors"][-1]
            log.warning("meshshade: %s; transport='hierarchical' was asked for: using %g patch radii anyway",
                        e, worst["near_patch_radii"])
            return SurfaceTransport.build(mesh, medium, model, options, curvature=curv, progress=progress,
                                          near_patch_radii=worst["near_patch_radii"]), None
    try:
        return SurfaceTransport.build(mesh, medium, model, options, curvature=curv, progress=progress), None
    except FarFieldUnsupported as e:
        w = e.check["errors"][-1]
        return None, (f"hierarchical far field not accurate on this mesh: distance error mean {w['mean']:.2g}, "
                      f"max {w['max']:.2g}")
