"""The bake: per-vertex radiant exitance of a mesh in a material under lights, by the transport its options choose.

:func:`bake` is the one place that chooses: the volume (``model="volume"``, the default: diffusion inside the
object, :mod:`meshshade.volume`) or a surface model (:mod:`meshshade.surface`: the paper's kernels summed over
geodesic neighbourhoods; also the volume's fallback on a mesh that encloses nothing). Both answer with the same
record, :class:`~meshshade.transport.result.BakeResult`; their options are one record,
:class:`~meshshade.transport.options.BakeOptions`.
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import replace

from meshshade.errors import MaterialError, MeshshadeError, ParameterError
from meshshade.geometry.mesh import Mesh
from meshshade.light.samples import check_exitance
from meshshade.light.sources import light_list
from meshshade.materials import Material
from meshshade.painted import PaintedMaterial
from meshshade.names import MODELS
from meshshade.parts import PartedMaterial
from meshshade.progress import Stopwatch
from meshshade.surface.baking import SurfaceModel
from meshshade.surface.hierarchical import SurfaceTransport
from meshshade.surface.options import (FAR_FIELD_METHODS, GEODESIC_METHODS, RTOL_RANGE,  # noqa: F401 (re-exported)
                                       TRANSPORTS)
from meshshade.transport.options import BakeOptions, bake_options_from_keywords
from meshshade.transport.result import BakeResult, describe_result, describe_scale, mesh_note  # noqa: F401
from meshshade.volume.baking import VOLUME_STAGES, VolumeBake, VolumeModel  # noqa: F401 (VOLUME_STAGES re-exported)
from meshshade.volume.transport import VolumeTransport

log = logging.getLogger("meshshade")

__all__ = ["bake", "check_bake_options", "VOLUME_STAGES", "MODELS_BY_NAME"]

#: each model's name -> the model :func:`bake` runs (``run(mesh, material, lights, options, clock, reuse)``): the
#: volume (:mod:`meshshade.volume.baking`) or a surface model (:mod:`meshshade.surface.baking`)
MODELS_BY_NAME = {"volume": VolumeModel(), **{m: SurfaceModel(m) for m in MODELS if m != "volume"}}


def bake(mesh, material: Material, lights, options: BakeOptions | None = None, *, reuse=None,
         **deprecated) -> BakeResult:
    """Per-vertex radiant exitance of ``mesh`` (a :class:`~meshshade.geometry.mesh.Mesh` in mm) in ``material`` lit
    by ``lights`` (a light or a list), baked as ``options`` says (:class:`~meshshade.transport.options.BakeOptions`;
    None: the default, the volume).

    Returns a :class:`~meshshade.transport.result.BakeResult`; ``radiance`` is W/mm^2 per unit light power (beam,
    W), irradiance (directional, W/mm^2) or intensity (point, W/sr). Stages are timed in ``result.timings``.

    ``model="volume"`` (the default): diffusion inside the object's own volume, solved on a graded lattice
    anchored in world coordinates (cut by the surface; the inside by the generalised winding number, so open,
    overlapping and defective meshes have one), from sources along the refracted light, with the analytic near
    field (the beam's near-field model less what the lattice carries) on top
    (:class:`meshshade.volume.transport.VolumeTransport`, docs/physics.md §15); ``options.volume``: its lattice's
    resolution and the solve's tolerance. It always takes the beam source model. A mesh that encloses nothing the
    lattice resolves (a lone sheet) takes ``model="auto"`` with the beam source model, saying why in
    ``stats["transport"]``.

    The surface models ("dipole", "curved", "exact-sphere", "fitted", "auto"; :mod:`meshshade.surface`) read
    ``options.surface`` (:class:`~meshshade.surface.options.SurfaceOptions`):

    * ``geodesic``: "exact" (polyhedral window propagation, the reference; default) or "arc" (curvature-corrected
      chords over an edge-path search: 1e-4 on smooth meshes such as spheres and tori and about 5x faster, but
      1-11 % low on average on bumpy scanned meshes; see geometry/geodesics/arc.py). With ``model="auto"`` the
      geodesic method is chosen per entry sample ("arc" restricts it to arc) and ``auto`` may override the
      tolerances of :func:`meshshade.surface.auto.plan_sources`.
    * ``far_field``: "off", "clustered" or "pairwise" (default: "clustered" for ``auto``, "off" otherwise; "off"
      with ``auto`` also turns off the shared far-zone geodesics, leaving exact or arc geodesics per sample). When
      on, the pairs of *vertex* entry samples (directional and point lights; beams have few samples and keep the
      full geodesic neighbourhood) are split at the chord radius ``r_near`` per channel beyond which the dipole's
      tail holds ``far_tol`` of its energy (farfield.far_field_radius): closer pairs are gathered over geodesic
      neighbourhoods with the model's kernel, farther ones are summed with the planar dipole of the chord distance
      by a source tree with relative error <= ``far_rel_tol`` on that part (farfield.py; "pairwise" sums them pair
      by pair, exactly, for validation). Pairs whose chord is within r_near but whose geodesic distance is not
      (across a fold) are dropped, as the geodesic neighbourhood drops them without the far field.
      ``far_geodesic`` ("shared" or "arc"): how ``auto`` finds the far-zone geodesics of curved vertex samples:
      one exact query per group of nearby samples, each member's distance from the centre's by the law of cosines
      in the tangent plane (sample_groups.py), or the arc method.
    * ``transport``: how the vertex samples of directional and point lights are summed: "direct" (every pair
      within the cutoff, the reference; the options above), "hierarchical" (surface/hierarchical.py: a near zone of
      a few patch radii and source clusters beyond, cost near-linear in the vertex count), "auto" (default:
      hierarchical where its distance check passes on this mesh, else direct; ``stats["transport"]`` says which
      and why). Beam samples always use the direct sum.
    * ``source_model``: what enters the medium at each entry sample. "point" (default; "beam" for ``volume``):
      each kernel's point source at depth z_r. "beam": the near-field model, exact single scattering plus
      diffusion sources along the beam fitted to exact transport (docs/physics.md §13), carried by every model as
      the factor of eq. (79): pairs are multiplied by the ratio of the near-field model to the planar dipole
      (patch-averaged near the source; for beams over the receiver's patch), and the far field by the ratio of
      their tails (surface/source_factors.py, eq. (80)).
    * ``cutoff_tol``, ``curvature_radius_mm``, ``rtol``: the neighbourhood, the curvature fit's, the exact series'.

    ``options.progress``: False (default), True or the task named in the progress lines ("bake"; ``render`` and
    ``compare`` pass their own name): as a bar on a terminal and as periodic lines on stderr otherwise
    (:class:`meshshade.progress.Progress`). Whatever it is, a Ctrl-C (KeyboardInterrupt) is acted upon within a
    few tenths of a second.

    ``reuse``: a transport an earlier bake of this mesh and material built, used again for these lights: the
    volume's (``result.volume``, a VolumeTransport) or a surface model's
    (:class:`~meshshade.surface.hierarchical.SurfaceTransport`, for its model and source model).

    The former keyword arguments (``model=``, ``geodesic=``, ``far_field=``, ``transport=``, ``source_model=``,
    ``cutoff_tol=``, ``backend=``, ``progress=``... and ``volume=``, now ``reuse=``) are accepted for one release
    with a DeprecationWarning; ``volume_cache`` is ignored (with one).
    """
    options, reuse = _options(options, reuse, deprecated)
    if not isinstance(mesh, Mesh):
        raise MeshshadeError(f"bake needs a meshshade Mesh (mm), got {type(mesh).__name__}")
    if not isinstance(material, (Material, PaintedMaterial, PartedMaterial)):
        raise MaterialError(f"bake needs a Material, a PaintedMaterial or a PartedMaterial, got "
                            f"{type(material).__name__}")
    varying = isinstance(material, (PaintedMaterial, PartedMaterial))
    if varying:
        kind = "a painted material" if isinstance(material, PaintedMaterial) else "a material of parts"
        if options.model != "volume":
            raise ParameterError(f"model {options.model!r} takes one medium; {kind} (a medium varying over the "
                                 "object) needs the volume model (docs/physics.md §17)")
        material.check_mesh(mesh)
        if isinstance(material, PartedMaterial):
            material.check_one_index()
            mesh = material.oriented(mesh)      # each part a solid (a nested part is no cavity)
    _check_reuse(reuse, mesh, material, options.model)
    lights = light_list(lights)   # every element a light; none at all is refused by entry_samples
    clock = Stopwatch()
    model = MODELS_BY_NAME[options.model]
    part, why = model.run(mesh, material, lights, options, clock, reuse)
    if part is None:                       # the volume, on a mesh that encloses nothing it resolves
        if varying:
            raise MeshshadeError(f"{why}; {kind} needs the volume model")
        log.warning("%s; using the surface transport (model auto, beam source model)", why)
        model = MODELS_BY_NAME["auto"]
        options = replace(options, surface=replace(options.surface, source_model="beam"))
        part, _ = model.run(mesh, material, lights, options, clock)
        part.stats["transport"] += f" [volume transport not used: {why}]"
    _close_stats(part.stats, part.radiance, mesh, part.samples, lights)
    if isinstance(part, VolumeBake):
        return BakeResult(part.radiance, None, None, None, None, part.samples, None, part.cutoff_mm, model.name,
                          material, clock.timings, part.stats, None, part.transport, part.sample_radiance)
    curv = part.curvature
    return BakeResult(part.radiance, curv.k1, curv.k2, curv.d1, curv.d2, part.samples, part.beam_distance,
                      part.cutoff_mm, model.name, material, clock.timings, part.stats, part.plan)


def _options(options, reuse, deprecated: dict):
    """``(BakeOptions, reuse)`` of a call of :func:`bake`: ``options`` with the former keyword arguments applied
    (a DeprecationWarning), ``volume=`` and a SurfaceTransport given as ``transport=`` taken as ``reuse``."""
    kw = dict(deprecated)
    if kw.pop("volume_cache", None) is not None:
        warnings.warn("bake(volume_cache=...) is deprecated and unused: the lattice volume keeps no asset cache",
                      DeprecationWarning, stacklevel=3)
    for name in ("volume", "transport"):
        if isinstance(kw.get(name), (VolumeTransport, SurfaceTransport)):
            warnings.warn(f"bake({name}=<built transport>) is deprecated; pass it as reuse=", DeprecationWarning,
                          stacklevel=3)
            reuse = kw.pop(name)
    kw = {k: v for k, v in kw.items() if not (k == "volume" and v is None)}
    return bake_options_from_keywords(options, kw, "bake", stacklevel=4), reuse


def _check_reuse(reuse, mesh, material, model):
    """ParameterError unless ``reuse`` is None or a transport of the options' kind built for this mesh and
    material."""
    if reuse is None:
        return
    if isinstance(reuse, VolumeTransport):
        if model != "volume" or reuse.mesh is not mesh or reuse.material.describe() != material.describe():
            raise ParameterError("the VolumeTransport passed as reuse was built for another mesh or material (or the "
                                 "model is not volume)")
    elif not isinstance(reuse, SurfaceTransport) or model == "volume":
        raise ParameterError("reuse must be a VolumeTransport (model volume) or a SurfaceTransport (a surface model) "
                             f"built by an earlier bake, got {type(reuse).__name__}")


def _close_stats(stats, M, mesh, samples, lights):
    """The powers every bake reports, and its check: finite and >= 0, or a one-line error naming the lights'
    strengths."""
    stats["exitant_power"] = (M * mesh.vertex_areas[:, None]).sum(axis=0).tolist()
    stats["entering_power"] = float(samples.power.sum())
    check_exitance(M, lights)


# ------------------------------------------------------------------------------------------------ deprecated
def check_bake_options(model="volume", *args, **keywords) -> str:
    """Deprecated: build :class:`~meshshade.transport.options.BakeOptions` (checked where it is made) instead.

    Checks the former options of :func:`bake` (``model``, then ``cutoff_tol``, ``curvature_radius_mm``,
    ``geodesic``, ``far_field`` positionally, the rest by keyword) and returns the far-field method with its
    default resolved; a DeprecationWarning."""
    warnings.warn("check_bake_options is deprecated; build the options as BakeOptions(...) (checked where it is "
                  "made)", DeprecationWarning, stacklevel=2)
    names = ("cutoff_tol", "curvature_radius_mm", "geodesic", "far_field")
    if len(args) > len(names):
        raise TypeError(f"check_bake_options takes at most {len(names) + 1} positional arguments")
    kw = {**dict(zip(names, args)), **keywords}
    kw = {k: v for k, v in kw.items() if not (v is None and k in ("curvature_radius_mm", "far_field", "near_field",
                                                                   "source_model", "auto_options"))}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)   # one warning: this function's
        surface_kw = {k: v for k, v in kw.items() if k not in ("backend", "progress")}
        options = bake_options_from_keywords(None, {"model": model, **surface_kw,
                                                    **{k: kw[k] for k in ("backend", "progress") if k in kw}})
    return options.far_field
