"""The bake: per-vertex radiant exitance M(x_o) = sum_i Phi_i R(x_o; x_i) over the light's entry samples.

The kernel is expanded at the entry point x_i (docs/physics.md §1.3; pair_kernel.py). Models
(:data:`meshshade.surface.models.MODELS`):

* ``dipole``: Jensen's usage, R_d(|x_o - x_i|) (chord distance);
* ``curved``: the first-order k1/k2 kernel with its positivity policy (kernels/curvature.py);
* ``exact-sphere``: the exact sphere series with the local radius 2/(k1 + k2) (for validation on spheres;
  where the surface is not convex it falls back to the dipole and counts it);
* ``auto``: per entry sample the cheapest of these that the scene calls for, and exact or arc geodesics
  (meshshade/surface/auto.py; the decisions are counted in ``stats``).

:func:`bake` runs the stages in order: validate the options, principal curvatures, entry samples (rays), then the
volume transport (meshshade/volume), the hierarchical transport (hierarchical.py) or the direct sum (direct_sum.py:
the near/far split, the auto plan, the zones, the gather per zone, the clustered far field and the first beam's
distance field); :class:`BakeResult` holds the outcome.
"""
from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from meshshade import memo
from meshshade.errors import MaterialError, MeshshadeError, NoVolumeError, ParameterError
from meshshade.geometry.curvature import principal_curvatures
from meshshade.geometry.mesh import Mesh
from meshshade.light import entry_samples
from meshshade.light.samples import check_exitance
from meshshade.light.sources import light_list
from meshshade.materials import Material
from meshshade.preview import mesh_preview
from meshshade.progress import Progress
from meshshade.raycast import make_scene
from meshshade.surface.farfield import (DEFAULT_FAR_TOL)
from meshshade.surface.hierarchical import (VERIFY_TOL, FarFieldUnsupported, SurfaceTransport, verify_far_field,
                                              vertex_drift, vertex_power)
from meshshade.surface.gather import Stopwatch, cutoff_radii
from meshshade.surface.direct_sum import SumOptions, direct_sum, merge_plans, subset_samples
from meshshade.surface.models import DEFAULT_MODEL, MODELS
from meshshade.surface.source_factors import (check_source_model, near_field_factors, source_model_keyword)
from meshshade.volume.transport import VolumeTransport

log = logging.getLogger("meshshade")

FAR_FIELD_METHODS = ("off", "clustered", "pairwise")
GEODESIC_METHODS = ("exact", "arc")
TRANSPORTS = ("auto", "hierarchical", "direct")
#: former spellings of option values (still accepted, with a DeprecationWarning): far_field="direct" (the far
#: field pair by pair, not the direct-sum transport) and far_geodesic="cluster" (sample groups, not source clusters)
RENAMED_FAR_FIELD = {"direct": "pairwise"}
RENAMED_FAR_GEODESIC = {"cluster": "shared"}


def renamed_value(name: str, value, renamed: dict):
    """``value``, or its new spelling if it is a former one of option ``name`` (with a DeprecationWarning
    attributed to the caller of the function that calls this)."""
    if isinstance(value, str) and value in renamed:
        warnings.warn(f"{name}={value!r} is deprecated; use {name}={renamed[value]!r}", DeprecationWarning,
                      stacklevel=3)
        return renamed[value]
    return value


@dataclass(frozen=True)
class BakeResult:
    """Per-vertex result of :func:`bake`.

    radiance : (n, 3) float64 W/mm^2 — linear radiant exitance per channel (r, g, b)
    k1, k2 : (n,) 1/mm; d1, d2 : (n, 3) — principal curvatures and directions of the mesh (None for the volume
                model, which needs none)
    samples : EntrySamples — where light entered and how much
    beam_distance : (n,) mm or None — geodesic distance of each vertex from the first beam's entry point
                    (inf beyond the neighbourhood)
    cutoff_mm : (3,) — neighbourhood radius per channel
    timings : dict stage -> seconds; stats : dict of counts (pairs, skipped work, fallbacks, auto decisions)
    plan : meshshade.surface.auto.AutoPlan or None — the per-sample decisions of ``model="auto"``
    volume : meshshade.volume.transport.VolumeTransport or None — the volume transport of ``model="volume"``
             (reuse it for further lights: ``bake(..., volume=result.volume)``; per-pixel renders use its near field)
    sample_exitance : (n_s, 3) W/mm^2 or None — the volume model's solution at the vertices of the surface it
             samples (``volume.surface``; P1 between them), which textures and per-pixel renders interpolate
    """

    radiance: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    samples: object
    beam_distance: np.ndarray | None
    cutoff_mm: np.ndarray
    model: str
    material: Material
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    plan: object = None
    volume: object = None
    sample_exitance: np.ndarray | None = None

    def __repr__(self) -> str:
        n = self.radiance.shape[0]
        peak = self.radiance.max(axis=0)
        total = sum(self.timings.values())
        transport = str(self.stats.get("transport", "")).split(" (")[0]
        return (f"<BakeResult {self.model}, {self.material.name}: {n} vertices, {len(self.samples)} entry samples"
                + (f", {transport} transport" if transport else "")
                + f"; peak exitance {peak[0]:.4g}/{peak[1]:.4g}/{peak[2]:.4g} W/mm^2 (r/g/b); {total:.3g} s>")

    def plot(self, mesh, **kwargs):
        """A matplotlib figure of ``mesh`` (the mesh that was baked) coloured by the exitance
        (:func:`meshshade.preview.mesh_preview`; keyword arguments go there)."""
        kwargs.setdefault("title", f"{self.model}, {self.material.name}")
        return mesh_preview(mesh.vertices, mesh.faces, self.radiance, **kwargs)


def describe_scale(mesh, material: Material) -> str:
    """One line: mesh size in mm and in transport mean free paths (per channel), so unit mistakes show."""
    size = mesh.bbox_size_mm
    mfp = size.max() * material.sigma_t_prime
    return (f"mesh: {mesh.n_vertices} vertices, {mesh.n_faces} faces, {size[0]:.4g} x {size[1]:.4g} x "
            f"{size[2]:.4g} mm (largest extent = {mfp[0]:.4g}/{mfp[1]:.4g}/{mfp[2]:.4g} transport mean free "
            f"paths r/g/b; mean edge {mesh.mean_edge_length:.4g} mm); material {material.describe()}")


def bake(mesh, material: Material, lights, *, model: str = DEFAULT_MODEL, cutoff_tol: float = 1e-4,
         curvature_radius_mm: float | None = None, backend: str = "embree", progress: bool | str = False,
         rtol: float = 1e-10, geodesic: str = "exact", auto_options: dict | None = None,
         far_field: str | None = None, far_tol: float = DEFAULT_FAR_TOL, far_rel_tol: float = 1e-2,
         far_geodesic: str = "shared", transport="auto", source_model: str | None = None,
         volume=None, volume_cache=None, near_field: str | None = None) -> BakeResult:
    """Per-vertex radiant exitance of ``mesh`` (a :class:`~meshshade.geometry.mesh.Mesh` in mm) lit by ``lights``.

    Returns a :class:`BakeResult`; ``radiance`` is W/mm^2 per unit light power (beam, W), irradiance
    (directional, W/mm^2) or intensity (point, W/sr). Stages are timed in ``result.timings``.

    ``model="volume"`` (the default): diffusion inside the object's own volume, solved on a graded lattice
    anchored in world coordinates (cut by the surface; the inside by the generalised winding number, so open,
    overlapping and defective meshes have one), from sources along the refracted light, with the analytic near
    field (the beam's near-field model less what the lattice carries) on top
    (:class:`meshshade.volume.transport.VolumeTransport`, docs/physics.md §15). It always takes the beam
    source model. ``volume``: a VolumeTransport built for this mesh and material (reused across lights);
    ``volume_cache``: deprecated and unused (the tetrahedral mesh it kept is gone; the lattice is built in seconds
    and depends on the light's edges): a DeprecationWarning when given. A mesh that encloses nothing the lattice resolves (a lone sheet) takes ``model="auto"`` with
    the beam source model, saying why in ``stats["transport"]``. The options below (geodesics, far field,
    transport, cutoff) are the surface models'.

    ``geodesic``: "exact" (polyhedral window propagation, the reference; default) or "arc" (curvature-corrected
    chords over an edge-path search: 1e-4 on smooth meshes such as spheres and tori and about 5x faster, but
    1-11 % low on average on bumpy scanned meshes; see geometry/geodesics/arc.py). With ``model="auto"``
    the geodesic method is chosen per entry sample ("arc" restricts it to arc) and ``auto_options`` may override
    the tolerances of :func:`meshshade.surface.auto.plan_sources`.

    ``far_field``: "off", "clustered" or "pairwise" (default: "clustered" for ``auto``, "off" otherwise; "off" with
    ``auto`` also turns off the shared far-zone geodesics, leaving exact or arc geodesics per sample). When on,
    the pairs of *vertex* entry samples (directional and point lights; beams have few samples and keep the full
    geodesic neighbourhood) are split at the chord radius ``r_near`` per channel beyond which the dipole's tail
    holds ``far_tol`` of its energy (farfield.far_field_radius): closer pairs are gathered over geodesic
    neighbourhoods with the model's kernel, farther ones are summed with the planar dipole of the chord distance
    by a source tree with relative error <= ``far_rel_tol`` on that part (farfield.py; "pairwise" sums them
    pair by pair, exactly, for validation). Pairs whose chord is within r_near but whose geodesic distance is not
    (across a fold) are dropped, as the geodesic neighbourhood drops them without the far field.
    ``far_geodesic`` ("shared" or "arc"): how ``auto`` finds the far-zone geodesics of curved vertex samples:
    one exact query per group of nearby samples, each member's distance from the centre's by the law of
    cosines in the tangent plane (sample_groups.py), or the arc method.

    ``transport``: how the vertex samples of directional and point lights are summed: "direct" (every pair
    within the cutoff, the reference; the options above), "hierarchical" (surface/hierarchical.py: a
    near zone of a few patch radii and source clusters beyond, cost near-linear in the vertex count), "auto"
    (default: hierarchical where its distance check passes on this mesh, else direct; ``stats["transport"]``
    says which and why), or a :class:`~meshshade.surface.hierarchical.SurfaceTransport` built for this
    mesh, material and model (reused across lights and frames). Beam samples always use the direct sum.

    ``source_model``: what enters the medium at each entry sample. "point" (default; "beam" for ``volume``): each
    kernel's point source at depth z_r. "beam": the near-field model, exact single scattering plus diffusion
    sources along the beam fitted to exact transport (docs/physics.md §13), carried by every model as the factor
    of eq. (79): pairs are multiplied by the ratio of the near-field model to the planar dipole (patch-averaged
    near the source; for beams over the receiver's patch), and the far field by the ratio of their tails
    (surface/source_factors.py, eq. (80)). ``near_field``: the former name of ``source_model`` (deprecated: a
    DeprecationWarning).

    ``progress``: False (default), True or the task named in the progress lines ("bake"; ``render`` and
    ``compare`` pass their own name): the gather's sources done, as a bar on a terminal and as periodic lines
    on stderr otherwise (:class:`meshshade.progress.Progress`). Whatever it is, a Ctrl-C (KeyboardInterrupt)
    is acted upon within a few tenths of a second: the geodesic queries run in calls of about
    :data:`meshshade.geometry.geodesics.neighbourhoods.BLOCK_SECONDS` each.
    """
    if not isinstance(mesh, Mesh):
        raise MeshshadeError(f"bake needs a meshshade Mesh (mm), got {type(mesh).__name__}")
    if not isinstance(material, Material):
        raise MaterialError(f"bake needs a Material, got {type(material).__name__}")
    source_model = source_model_keyword(source_model, near_field)
    far_field = renamed_value("far_field", far_field, RENAMED_FAR_FIELD)
    far_geodesic = renamed_value("far_geodesic", far_geodesic, RENAMED_FAR_GEODESIC)
    far_field_given = far_field is not None
    check_bake_options(model, cutoff_tol, curvature_radius_mm, geodesic, far_field, rtol=rtol, far_tol=far_tol,
                       far_rel_tol=far_rel_tol, far_geodesic=far_geodesic, backend=backend,
                       auto_options=auto_options, transport=transport, source_model=source_model)
    source_model = check_source_model("beam" if source_model is None and model == "volume"
                                      else source_model or "point")
    if volume is not None and (model != "volume" or not isinstance(volume, VolumeTransport) or volume.mesh is not mesh
                               or volume.material.describe() != material.describe()):
        raise ParameterError("the VolumeTransport passed as volume was built for another mesh or material (or the "
                             "model is not volume)")
    if volume_cache is not None:
        warnings.warn("bake(volume_cache=...) is deprecated and unused: the lattice volume keeps no asset cache",
                      DeprecationWarning, stacklevel=2)
    lights = light_list(lights)   # every element a light; none at all is refused by entry_samples
    clock = Stopwatch()
    volume_why = None
    if model == "volume":
        bar, on_stage = _volume_progress(progress)
        try:
            vt, volume_why = _volume_transport(mesh, material, volume, clock, on_stage)
            if vt is not None:
                vt.on_stage = on_stage
                try:
                    return _volume_bake(vt, mesh, material, lights, backend, clock, on_stage)
                except NoVolumeError as e:     # found when the lattice is built for the light: nothing inside
                    volume_why = f"the volume transport cannot be built ({str(e).splitlines()[0]})"
                finally:
                    vt.on_stage = None
        finally:
            if bar is not None:
                bar.close()
        log.warning("%s; using the surface transport (model auto, beam source model)", volume_why)
        model = "auto"
    far_field = check_bake_options(model, cutoff_tol, curvature_radius_mm, geodesic, far_field, rtol=rtol,
                                   far_tol=far_tol, far_rel_tol=far_rel_tol, far_geodesic=far_geodesic,
                                   backend=backend, auto_options=auto_options, transport=transport)
    # inside memo.reuse() (a batch worker) the mesh's curvature and scene are kept for the next job on this mesh
    curv = memo.cached("curvature", (id(mesh), curvature_radius_mm),
                       lambda: principal_curvatures(mesh.vertices, mesh.faces, radius_mm=curvature_radius_mm),
                       pins=(mesh,))
    clock.lap("curvature")
    scene = memo.cached("scene", (id(mesh), backend),  # face ids must index mesh.faces
                        lambda: make_scene(mesh.vertices, mesh.faces, backend=backend), pins=(mesh,))
    samples = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, lights, scene=scene,
                            eta=material.eta)
    clock.lap("rays")
    cut = np.minimum(cutoff_radii(material, cutoff_tol), mesh.scale)
    direct_options = far_field_given or far_geodesic != "shared"
    core, why, built = _surface_transport(transport, mesh, material, model, samples, curv, geodesic=geodesic,
                                   direct_options=direct_options, source_model=source_model,
                                   cutoff_tol=cutoff_tol, auto_options=auto_options, rtol=rtol, progress=progress)
    opts = SumOptions(model, far_field, far_tol, far_rel_tol, far_geodesic, geodesic, rtol, auto_options, progress,
                      source_model)
    verified = None
    if core is not None:
        pv = vertex_power(samples, mesh.n_vertices)
        pv_c = pv
        if source_model == "beam":   # per channel: each sample's power times its incidence scale
            pv_c = vertex_power(samples, mesh.n_vertices,
                                near_field_factors(material).incidence_scale(samples.cos_incidence))
        drift = vertex_drift(samples, mesh.n_vertices, material.eta) if source_model == "beam" else None
        M, hstats = core.exitance(pv_c, drift=drift, progress=progress)
        if transport == "auto":  # the far field's distances on this light's configuration, or the direct sum
            t_v = time.perf_counter()
            verified = verify_far_field(core, M, pv)
            hstats["timings"]["far-field check"] = time.perf_counter() - t_v
            if verified["mean"] > VERIFY_TOL[0] or verified["max"] > VERIFY_TOL[1]:
                why = (f"hierarchical far field not accurate for this light: arc-distance error of M at "
                       f"{verified['receivers']} receivers mean {verified['mean']:.2g}, max {verified['max']:.2g}")
                log.info("meshshade: %s; using the direct sum", why)
                core = None
    if core is None:
        M, beam_distance, stats, plan, kstats = direct_sum(mesh, material, lights, samples, curv, cut, clock, opts)
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
            Mb, beam_distance, bstats, bplan, kstats = direct_sum(mesh, material, lights, sub, curv, cut, clock,
                                                               opts._replace(far_field="off"))
            M = M + Mb
            stats.update({f"beam_{k}": v for k, v in bstats.items() if k in ("pairs_found", "pairs_evaluated")})
            if plan is not None and bplan is not None:
                plan = merge_plans(plan, bplan, point)
    stats.update(kstats)
    if volume_why:
        stats["transport"] += f" [volume transport not used: {volume_why}]"
    stats["near_field"] = source_model   # the stats key keeps its name: outputs and reports read it
    if source_model == "beam" and near_field_factors(material).clamped:
        stats["near_field_clamped"] = True   # a channel outside the fitted domain: its nearest node is used
    stats["exitant_power"] = (M * mesh.vertex_areas[:, None]).sum(axis=0).tolist()
    stats["entering_power"] = float(samples.power.sum())
    check_exitance(M, lights)  # finite and >= 0, or a one-line error naming the lights' strengths
    return BakeResult(M, curv.k1, curv.k2, curv.d1, curv.d2, samples, beam_distance, cut, model, material,
                      clock.timings, stats, plan)


#: the volume bake's stages in order, with their rough shares of its time (the progress bar's units)
VOLUME_STAGES = {"volume sampling": 1, "near-field tables": 1, "rays": 1, "volume lattice": 3, "volume operator": 2,
                 "volume multigrid": 2, "volume sources": 1, "volume solve": 3, "near field": 3}


def _volume_progress(progress):
    """(Progress or None, on_stage callback or None) of a volume bake: a bar over its stages, named as they run."""
    if not progress:
        return None, None
    bar = Progress(progress if isinstance(progress, str) else "bake", sum(VOLUME_STAGES.values()), "")
    order = list(VOLUME_STAGES)
    bar.set_stage(order[0])

    def on_stage(name):                                   # ``name`` has ended: the next one runs now
        if name in order and order.index(name) + 1 < len(order):
            bar.set_stage(order[order.index(name) + 1])
        bar.update(VOLUME_STAGES.get(name, 0))
    return bar, on_stage


def _volume_transport(mesh, material, volume, clock, on_stage=None):
    """``(VolumeTransport or None, why not)``: the one passed in, the one kept for this mesh and material inside
    :func:`meshshade.memo.reuse`, or a new one (its stages charged to ``clock``); None where the mesh encloses no
    volume the lattice can resolve (a flat sheet: :class:`~meshshade.errors.NoVolumeError`)."""
    if volume is not None:
        return volume, None
    built = []

    def build():
        built.append(True)
        try:
            return VolumeTransport.build(mesh, material, on_stage=on_stage), None
        except NoVolumeError as e:
            return None, f"the volume transport cannot be built ({str(e).splitlines()[0]})"

    vt, why = memo.cached("volume", (id(mesh), material.describe()), build, pins=(mesh,))
    if vt is not None and built:
        clock.charge(vt.timings)
    return vt, why


def _volume_bake(vt, mesh, material, lights, backend, clock, on_stage=None) -> BakeResult:
    """The bake's result by the volume transport (``model="volume"``): the lights' entry samples on the surface
    the transport samples, then its exitance; no curvature (the volume needs none)."""
    S = vt.surface.samples
    scene = memo.cached("scene", (id(S), backend), lambda: make_scene(S.vertices, S.faces, backend=backend),
                        pins=(S,))
    samples = entry_samples(S.vertices, S.faces, S.vertex_normals, S.vertex_areas, lights, scene=scene,
                            eta=material.eta)
    clock.lap("rays")
    if on_stage is not None:
        on_stage("rays")
    Ms, vstats = vt.sample_exitance(samples)
    M = vt.to_vertices(Ms)
    clock.charge(vstats.pop("timings"))
    stats = {"entry_samples": len(samples), "cutoff_mm": vt.tables.radius_mm.tolist(), **samples.stats,
             **vt.stats, **vstats, "transport": "volume", "near_field": "beam"}
    stats["exitant_power"] = (M * mesh.vertex_areas[:, None]).sum(axis=0).tolist()
    stats["entering_power"] = float(samples.power.sum())
    check_exitance(M, lights)
    return BakeResult(M, None, None, None, None, samples, None, vt.tables.radius_mm.copy(), "volume", material,
                      clock.timings, stats, None, vt, Ms)


def _surface_transport(transport, mesh, material, model, samples, curv, *, direct_options=False, **kw):
    """``(SurfaceTransport or None, reason, built)``: the hierarchical transport of the vertex samples, or None for
    the direct sum (asked for, no vertex samples, or ``transport="auto"`` on a mesh where it is not accurate);
    ``built``: whether this call built it (not passed in, nor reused from :mod:`meshshade.memo`)."""
    if isinstance(transport, SurfaceTransport):
        if (transport.mesh is not mesh or transport.material.describe() != material.describe()
                or transport.model != model or transport.source_model != kw.get("source_model", "point")):
            raise ParameterError("the SurfaceTransport passed as transport was built for another mesh, material, "
                                 "model or source model")
        return transport, None, False
    if transport == "direct":
        return None, None, False
    if transport == "auto" and direct_options:
        return None, "direct-sum options given", False
    if not np.any(samples.vertex >= 0):
        return None, "no vertex samples", False
    # inside memo.reuse() (a batch worker) the transport (or the verdict that it does not apply) is kept for
    # further lights on this mesh, material and model
    key = (id(mesh), material.describe(), model, transport, id(curv), repr(sorted(kw.items(), key=str)))
    built = []

    def build():
        built.append(True)
        return _build_transport(transport, mesh, material, model, curv, **kw)

    core, why = memo.cached("transport", key, build, pins=(mesh, curv))
    return core, why, bool(built)


def _build_transport(transport, mesh, material, model, curv, **kw):
    if transport == "hierarchical":
        try:
            return SurfaceTransport.build(mesh, material, model, curvature=curv, **kw), None
        except FarFieldUnsupported as e:
            worst = e.check["errors"][-1]
            log.warning("meshshade: %s; transport='hierarchical' was asked for: using %g patch radii anyway",
                        e, worst["near_patch_radii"])
            return SurfaceTransport.build(mesh, material, model, curvature=curv,
                                          near_patch_radii=worst["near_patch_radii"], **kw), None
    try:
        return SurfaceTransport.build(mesh, material, model, curvature=curv, **kw), None
    except FarFieldUnsupported as e:
        w = e.check["errors"][-1]
        return None, (f"hierarchical far field not accurate on this mesh: distance error mean {w['mean']:.2g}, "
                      f"max {w['max']:.2g}")


# ------------------------------------------------------------------------------------------------ bake's stages
def _real(value) -> float:
    """``value`` as a float, NaN when it is not a real number (so that every range check below refuses it)."""
    try:
        return float(value) if not isinstance(value, (bool, str)) else math.nan
    except (TypeError, ValueError):
        return math.nan


#: the documented range of ``rtol`` (relative tolerance of the exact series) in bake and profiles
RTOL_RANGE = (1e-15, 0.1)


def check_bake_options(model=DEFAULT_MODEL, cutoff_tol=1e-4, curvature_radius_mm=None, geodesic="exact",
                       far_field=None, *, rtol=1e-10, far_tol=DEFAULT_FAR_TOL, far_rel_tol=1e-2, far_geodesic="shared",
                       backend="embree", auto_options=None, transport="auto", source_model=None,
                       near_field=None) -> str:
    """Reject bad options of :func:`bake` (MeshshadeError, one line naming the option, its value and what is
    allowed) before any work; returns the far-field method with its default resolved. Also used by
    :func:`meshshade.output.compare.run_comparison` to check everything up front. ``near_field``, and the
    far-field and far-geodesic values ``"direct"`` and ``"cluster"``: the former spellings of ``source_model``,
    ``"pairwise"`` and ``"shared"`` (deprecated: a DeprecationWarning)."""
    source_model = source_model_keyword(source_model, near_field)
    far_field = renamed_value("far_field", far_field, RENAMED_FAR_FIELD)
    far_geodesic = renamed_value("far_geodesic", far_geodesic, RENAMED_FAR_GEODESIC)
    if model not in MODELS:
        raise MeshshadeError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
    if model == "volume":   # options of the surface models that the volume model cannot honour
        if source_model is not None and source_model != "beam":
            raise ParameterError("the volume model takes the beam source model; source model 'point' applies to the "
                                 "surface models (dipole, curved, exact-sphere, fitted, auto)")
        if not (isinstance(transport, str) and transport == "auto"):
            raise ParameterError(f"transport {transport if isinstance(transport, str) else 'SurfaceTransport'!r} "
                                 "applies to the surface models; the volume model has its own")
        if far_field is not None:
            raise ParameterError("the far-field option applies to the surface models; the volume model solves the "
                                 "far field inside the volume")
    if not 0.0 < _real(cutoff_tol) < 1.0:
        raise MeshshadeError(f"cutoff tolerance (cutoff_tol) must lie in (0, 1), got {cutoff_tol!r}")
    if curvature_radius_mm is not None and not 0.0 < _real(curvature_radius_mm) < math.inf:
        raise MeshshadeError(f"curvature radius must be a positive finite number of mm, got {curvature_radius_mm!r}")
    if geodesic not in GEODESIC_METHODS:
        raise MeshshadeError(f"unknown geodesic method {geodesic!r}; choose exact or arc")
    far_field = far_field or ("clustered" if model in ("auto", "volume") else "off")
    if far_field not in FAR_FIELD_METHODS:
        raise MeshshadeError(f"unknown far-field method {far_field!r}; choose off, clustered or pairwise")
    if not RTOL_RANGE[0] <= _real(rtol) <= RTOL_RANGE[1]:
        raise MeshshadeError(f"rtol (relative tolerance of the exact series) must lie in [{RTOL_RANGE[0]:g}, "
                             f"{RTOL_RANGE[1]:g}], got {rtol!r}")
    for name, value in (("far_tol", far_tol), ("far_rel_tol", far_rel_tol)):
        if not 0.0 < _real(value) < 1.0:
            raise MeshshadeError(f"{name} must lie in (0, 1), got {value!r}")
    if far_geodesic not in ("shared", "arc"):
        raise MeshshadeError(f"unknown far_geodesic {far_geodesic!r}; choose shared or arc")
    if backend not in ("embree", "numpy"):
        raise MeshshadeError(f"unknown ray backend {backend!r}; choose embree or numpy")
    if not (isinstance(transport, SurfaceTransport) or (isinstance(transport, str) and transport in TRANSPORTS)):
        raise MeshshadeError(f"unknown transport {transport!r}; choose {', '.join(TRANSPORTS)} (or pass a "
                             "SurfaceTransport)")
    if auto_options is not None and not isinstance(auto_options, dict):
        raise MeshshadeError(f"auto_options must be a dict or None, got {type(auto_options).__name__}")
    return far_field


def mesh_note(result: BakeResult) -> str | None:
    """One line on what the bake made of a mesh that is not one closed part (None for one closed part): the
    volume over an open or many-part mesh, buried vertices, or why the surface transport was used instead."""
    s = result.stats
    if s.get("transport") == "volume":
        closed, parts = s.get("volume_closed", True), s.get("volume_parts", 1)
        buried = s.get("volume_buried_vertices", 0)
        if closed and parts <= 1 and not buried:
            return None
        what = [] if closed else ["holes closed by the winding number"]
        if parts > 1:
            what.append(f"{parts} parts baked as their union (overlapping parts share light)")
        if buried:
            what.append(f"{buried} vertices buried inside other parts report 0")
        return "volume transport on " + ("a closed" if closed else "an open") + " mesh: " + "; ".join(what)
    why = str(s.get("transport", ""))
    if "[volume transport not used:" in why:
        return "surface transport: " + why.split("[volume transport not used:", 1)[1].rstrip("]").strip()
    return None


def describe_result(result: BakeResult) -> str:
    """One line: entry samples, pairs, far field and zones, entering and exitant power, timings."""
    s = result.stats
    t = ", ".join(f"{k} {v:.3g} s" for k, v in result.timings.items())
    ex = s["exitant_power"]
    if s.get("transport") == "volume":
        cells = s.get("volume_cells_per_level", [])
        return (f"volume: {s['entry_samples']} entry samples; diffusion on {sum(cells)} cubes of "
                f"{s['volume_resolution_mm']:.3g} mm ({s['volume_resolution_limited_by']}; "
                f"{cells[0] if cells else 0} of half that at edges of light), {s['volume_unknowns']} unknowns; "
                f"near field within {max(s['cutoff_mm']):.3g} mm ({s['near_field_pairs']} evaluations); entering "
                f"{s['entering_power']:.4g} W, exitant {ex[0]:.4g}/{ex[1]:.4g}/{ex[2]:.4g} W (r/g/b); {t}")
    far = (f" (area lights: geodesic near zone within {max(s['near_mm']):.3g} mm, {s['far_field']} far field "
           f"beyond)" if "near_mm" in s else "")
    if s.get("geodesic_pairs_computed", s.get("pairs_found")) != s.get("pairs_found"):
        far += f", {s['geodesic_pairs_computed']} geodesic distances computed"
    zones = ", ".join(f"{k[5:]} {v}" for k, v in s.items() if k.startswith("zone_"))
    far += f" [zones: {zones}]" if zones and result.model == "auto" else ""
    return (f"{result.model}: {s['entry_samples']} entry samples, {s.get('pairs_found', 0)} pairs within "
            f"{max(s['cutoff_mm']):.3g} mm{far}; entering {s['entering_power']:.4g} W, exitant "
            f"{ex[0]:.4g}/{ex[1]:.4g}/{ex[2]:.4g} W (r/g/b); {t}")
