"""Entry samples: where each light enters the medium and the power it transmits there.

Positions are in mm, powers in W. ``entry_samples`` turns a list of lights (:mod:`meshshade.light.sources`) into
:class:`EntrySamples`: points on the surface where light enters, each with the power (W) that crosses the
boundary after specular Fresnel reflection (:mod:`meshshade.kernels.fresnel`). Fresnel here is
channel-independent, so one power per sample serves every colour channel.

Only what is needed is simulated: a beam is one ray (or ``BEAM_SAMPLES`` for a finite-width beam, or its lit
vertices when they outnumber the rays that hit); a directional or point light considers only vertices that face it
(and have area), and casts a shadow ray only where the mesh *could* occlude it (see
:class:`meshshade.light.shadows.ShadowCuller` for the rule and its proof).

Whether a light reaches the mesh at all is decided here for the bake and for Monte Carlo alike
(:func:`check_lights_reach`, :func:`beam_footprint`): no light reaching it is an error, one light among several a
warning.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from meshshade.errors import LightError, MeshValidationError
from meshshade.geometry.mesh import face_normals
from meshshade.kernels.fresnel import fresnel_reflectance, fresnel_transmittance_entry
from meshshade.kernels.optics import check_eta
from meshshade.light.incidence import incidence_part
from meshshade.light.shadows import ShadowCuller
from meshshade.light.sources import (AreaLight, BeamLight, DirectionalLight, EnvironmentLight, PointLight,
                                     check_outside_mesh, describe_light, light_list)
from meshshade.raycast import make_scene

__all__ = ["EntrySamples", "entry_samples", "beam_footprint", "check_lights_reach", "check_exitance"]


@dataclass(frozen=True)
class EntrySamples:
    """Points where light enters the medium, ``k`` samples from ``n_lights`` lights (float64, mm, W).

    Attributes
    ----------
    positions : (k, 3) float64 mm
        Entry points (the hit point for a beam, the vertex position otherwise).
    face : (k,) int64
        Hit face of a beam sample; -1 for a vertex sample.
    bary : (k, 3) float64
        Barycentric weights of the hit face's vertices 0, 1, 2 for a beam sample; NaN for a vertex sample
        (which has no face: use ``vertex``).
    vertex : (k,) int64
        Vertex index of a vertex sample; -1 for a beam hit inside a triangle.
    normals : (k, 3) float64
        Unit normal used for the angle of incidence: the geometric face normal for a beam, the vertex normal
        for directional and point lights.
    power : (k,) float64 W
        Power entering the medium: incident power x Fresnel transmittance F_t(cos_incidence).
    cos_incidence : (k,) float64 in (0, 1]
        Cosine between the reversed light direction and ``normals``.
    light_index : (k,) int64
        Index of the light in the list passed to :func:`entry_samples`.
    directions : (k, 3) float64
        Unit direction in which the light travels when it reaches the sample (the beam's or directional light's
        direction; from a point light to the vertex). Inside, it refracts to the direction whose tangential part
        is that of ``directions`` over eta (the near field's lateral shift, docs/physics.md eq. (87)).
    incident_power : (n_lights,) float64 W
        Power arriving on the sampled surface from each light (before Fresnel), shadowed parts excluded.
    specular_power : (n_lights,) float64 W
        Power reflected specularly at entry, per light (``incident_power - entering_power``).
    stats : dict
        ``beam_rays``, ``candidates`` (vertices facing a light, summed over lights), ``shadow_rays_cast``,
        ``shadow_rays_skipped`` (= ``skipped_convex`` + ``skipped_hull``), ``mesh_convex`` (None if never
        needed), ``hull_rule`` (whether the convex-hull rule was tried; see
        :class:`~meshshade.light.shadows.ShadowCuller`).
    """

    positions: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    vertex: np.ndarray
    normals: np.ndarray
    power: np.ndarray
    cos_incidence: np.ndarray
    light_index: np.ndarray
    directions: np.ndarray
    incident_power: np.ndarray
    specular_power: np.ndarray
    stats: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.power.shape[0])

    @property
    def entering_power(self) -> np.ndarray:
        """(n_lights,) float64 W entering the medium per light."""
        return np.bincount(self.light_index, weights=self.power, minlength=self.incident_power.shape[0])

    def __repr__(self) -> str:
        return (f"EntrySamples(k={len(self)}, lights={self.incident_power.shape[0]}, "
                f"entering={float(self.power.sum()):.6g} W, specular={float(self.specular_power.sum()):.6g} W, "
                f"stats={self.stats})")



def _check_mesh_arrays(vertices, faces, vertex_normals, vertex_areas):
    """(V (n, 3) float64, F (m, 3) int64, unit vertex normals (n, 3), areas (n,)); MeshValidationError if malformed."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces)
    N = np.asarray(vertex_normals, dtype=np.float64)
    A = np.asarray(vertex_areas, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or not np.issubdtype(F.dtype, np.integer):
        raise MeshValidationError(f"expected vertices (n, 3) and integer faces (m, 3), got {V.shape}, {F.shape}")
    if N.shape != V.shape or A.shape != V.shape[:1]:
        raise MeshValidationError(f"vertex_normals must be {V.shape} and vertex_areas {V.shape[:1]}, "
                                  f"got {N.shape} and {A.shape}")
    if F.size and (F.min() < 0 or F.max() >= V.shape[0]):
        raise MeshValidationError(f"face indices must lie in [0, {V.shape[0] - 1}]")
    if not (np.all(np.isfinite(V)) and np.all(np.isfinite(N)) and np.all(np.isfinite(A)) and np.all(A >= 0)):
        raise MeshValidationError("vertices, vertex normals and vertex areas must be finite (areas >= 0)")
    length = np.linalg.norm(N, axis=1, keepdims=True)
    unit = np.divide(N, length, out=np.zeros_like(N), where=length > 0)
    return V, F.astype(np.int64), unit, A


def entry_samples(vertices, faces, vertex_normals, vertex_areas, lights, scene=None, eta=1.0) -> EntrySamples:
    """Entry points and transmitted power of every light on the mesh.

    Parameters
    ----------
    vertices : (n, 3) float64 mm
    faces : (m, 3) int, outward-facing (counter-clockwise seen from outside)
    vertex_normals : (n, 3) float64, outward (normalised here)
    vertex_areas : (n,) float64 mm^2, the area each vertex represents (sums to the surface area)
    lights : a light or a sequence of :class:`BeamLight`, :class:`DirectionalLight`, :class:`PointLight`
    scene : EmbreeScene or NumpyScene of the same mesh, or None to build an Embree scene only if a ray is needed
    eta : float in [1, 2.5], relative index of the medium
        (outside is index 1; :func:`~meshshade.kernels.optics.check_eta`)

    Returns
    -------
    EntrySamples
        * pencil beam: one sample at the first hit, power ``P F_t(cos)``, ``cos`` from the geometric face normal;
        * beam of radius R > 0: ``BEAM_SAMPLES`` parallel rays over its disc, each carrying ``P / BEAM_SAMPLES``
          (rays that miss carry their share away); when more vertices than rays lie lit in the beam's cylinder
          (a beam wide compared with the mesh's vertex spacing), one sample per such vertex instead, as for a
          directional light of irradiance ``P / (pi R^2)`` (see :func:`beam_footprint`);
        * directional: one sample per vertex facing the light (``n . (-d) > 0``) and not shadowed, power
          ``E cos F_t(cos) A_v``;
        * point: likewise with ``E = I / dist**2`` (the irradiance across the ray; ``E cos`` on the surface) and
          the shadow ray stopped at the light;
        * environment and area lights: up to four samples per lit vertex carrying the power of the vertex's whole
          fan of directions, or one per (vertex, direction) (:func:`meshshade.light.incidence.incidence_part`);
          ``stats["quadrature"]`` lists, per such light, the directions per vertex and the error left.

    Raises
    ------
    LightError
        No light; a beam or point light inside the mesh; a beam that reaches the back of a face; a beam that misses
        the mesh (:func:`beam_miss_error`, alone or among other lights); **no light at all reaching
        the mesh** (:func:`check_lights_reach`: one line naming each light and why, with a hint for a reversed
        direction); a light whose entering power overflows float64.

    Warns
    -----
    UserWarning
        A light that reaches nothing while another light of the scene does ("light i ... reaches no vertex of the
        mesh: why").
    """
    V, F, N, A = _check_mesh_arrays(vertices, faces, vertex_normals, vertex_areas)
    eta = float(check_eta(eta))
    lights = light_list(lights)
    if not lights:
        raise LightError("no light given: a scene needs at least one beam, directional or point light")

    cache = {"scene": scene}

    def get_scene():
        if cache["scene"] is None:
            cache["scene"] = make_scene(V, F)
        return cache["scene"]

    # the hull rule pays only where rays are expensive (the brute-force backend), see ShadowCuller
    culler = ShadowCuller(V, F, get_scene, use_hull=getattr(scene, "backend", None) == "numpy")
    stats = {"beam_rays": 0, "candidates": 0}
    parts: list[dict] = []
    incident = np.zeros(len(lights))
    specular = np.zeros(len(lights))

    for i, light in enumerate(lights):
        if isinstance(light, BeamLight):
            part = _beam_samples(light, i, V, F, N, A, get_scene, eta)
            stats["beam_rays"] += int(part.pop("rays"))
        elif isinstance(light, (EnvironmentLight, AreaLight)):   # many directions per vertex: light.incidence
            check_outside_mesh(light, i, V, F)
            part = incidence_part(light, i, V, F, N, A, get_scene, eta, stats)
        else:
            part = _vertex_samples(light, i, V, F, N, A, culler, eta, stats)
        incident[i] = part.pop("incident")
        specular[i] = part.pop("specular")
        parts.append(part)
    check_lights_reach(lights, [p["vertex"].size > 0 for p in parts], V, N, A, get_scene)
    for i, part in enumerate(parts):  # guaranteed finite (sources.MAX_LIGHT_STRENGTH); checked all the same
        if not (np.all(np.isfinite(part["power"])) and math.isfinite(incident[i])):
            raise LightError(f"{describe_light(lights[i], i)}: the power entering the mesh overflows float64; "
                             "use a smaller power, irradiance or intensity")

    def cat(key, shape, dtype):
        arrays = [p[key] for p in parts]
        return np.concatenate(arrays).astype(dtype) if arrays else np.zeros(shape, dtype=dtype)

    stats.update(culler.stats)
    stats["mesh_convex"] = culler.convex
    stats["hull_rule"] = culler.use_hull
    return EntrySamples(
        positions=cat("positions", (0, 3), np.float64),
        face=cat("face", (0,), np.int64),
        bary=cat("bary", (0, 3), np.float64),
        vertex=cat("vertex", (0,), np.int64),
        normals=cat("normals", (0, 3), np.float64),
        power=cat("power", (0,), np.float64),
        cos_incidence=cat("cos", (0,), np.float64),
        light_index=cat("light_index", (0,), np.int64),
        directions=cat("directions", (0, 3), np.float64),
        incident_power=incident,
        specular_power=specular,
        stats=stats,
    )


# ------------------------------------------------------------------------------------------------ reaching the mesh
def _fmt(v) -> str:
    return ",".join(f"{0.0 + float(x):.6g}" for x in v)  # 0.0 + x: no "-0"


def _unreached_reason(light, V, N, A, get_scene) -> str:
    """Why ``light`` deposits nothing on the mesh, with a hint when the opposite direction would reach it."""
    if isinstance(light, DirectionalLight):
        d = np.array(light.direction)
        why = "every vertex faces away from it or is shadowed"
        if np.any((N @ d > 0.0) & (A > 0.0)):   # the reversed light would face part of the mesh
            why += (f"; directional lights give the direction the light travels: did you mean "
                    f"directional:{_fmt(-d)}?")
        return why
    if isinstance(light, PointLight):
        return "every vertex faces away from it or is shadowed"
    if isinstance(light, AreaLight):
        return "every vertex lies behind the emitter, faces away from it or is shadowed from it"
    if isinstance(light, EnvironmentLight):
        return "every vertex is shadowed from every direction the map lights"
    why = "" if light.radius == 0.0 else ": no part of it lies unshadowed in the beam's cylinder"
    o, d = np.array(light.origin), np.array(light.direction)
    back = get_scene().first_hit(o, -d)
    if back.face[0] >= 0:
        why += (f"; a beam travels from its origin along dx,dy,dz and the mesh lies behind the origin: did you "
                f"mean direction {_fmt(-d)}?")
    return why


def check_lights_reach(lights, reached, vertices, vertex_normals, vertex_areas, get_scene) -> None:
    """The one rule for lights that deposit nothing on the mesh, shared by the bake and Monte Carlo.

    ``reached[i]`` says whether light ``i`` enters the mesh anywhere (here: whether it has an entry sample).
    If **no** light does, the result would be all zeros: :class:`~meshshade.errors.LightError`, one line naming
    each light and why (every vertex faces away from a directional or point light or is shadowed from it), with a
    hint when the reversed direction would reach the mesh. A light that reaches nothing while another does is a
    ``UserWarning``. A beam that misses never gets here: it is an error at once, alone or among other lights
    (:func:`beam_miss_error`; a beam is aimed, so a miss is a wrong origin or direction, never a scene that is
    meant to be partly dark). ``get_scene``: callable returning the ray scene (for the hints).
    """
    V = np.asarray(vertices, dtype=np.float64)
    N = np.asarray(vertex_normals, dtype=np.float64)
    A = np.asarray(vertex_areas, dtype=np.float64)
    missing = [i for i, ok in enumerate(reached) if not ok]
    if not missing:
        return
    notes = [f"{describe_light(lights[i], i)} reaches no vertex of the mesh: "
             f"{_unreached_reason(lights[i], V, N, A, get_scene)}" for i in missing]
    if len(missing) == len(lights):
        head = "" if len(lights) == 1 else "no light reaches the mesh (the result would be all zeros): "
        raise LightError(head + "; ".join(notes))
    for note in notes:
        warnings.warn(note, UserWarning, stacklevel=3)


def beam_miss_error(light: BeamLight, index: int, vertices, vertex_normals, vertex_areas, get_scene) -> LightError:
    """The error of a beam that misses the mesh: one line naming the beam (and, for a wide one, that nothing lies
    lit in its cylinder), with a hint when the mesh lies behind its origin."""
    why = _unreached_reason(light, np.asarray(vertices, np.float64), np.asarray(vertex_normals, np.float64),
                            np.asarray(vertex_areas, np.float64), get_scene)
    return LightError(f"{describe_light(light, index)} misses the mesh{why}")


def check_exitance(radiance, lights, what: str = "radiance") -> None:
    """Guard on a result computed from entry samples: every value finite and >= 0, else a one-line LightError naming
    the lights' strengths (the result is linear in them). With the documented domains (sources.MAX_LIGHT_STRENGTH,
    materials.SIGMA_MAX, eta in [1, 2.5]) it never fires; it turns any overflow into an error instead of an inf
    written with exit 0."""
    M = np.asarray(radiance, dtype=np.float64)
    if M.size and not (np.all(np.isfinite(M)) and M.min() >= 0.0):
        bad = "not finite" if not np.all(np.isfinite(M)) else "negative"
        names = "; ".join(describe_light(light, i) for i, light in enumerate(light_list(lights)))
        raise LightError(f"the {what} is {bad} for {names}: use a smaller power, irradiance or intensity "
                         "(the result scales with it)")


# ------------------------------------------------------------------------------------------------ beams
def _beam_rays(scene, origins, d, V, F):
    """First front-face hits of the parallel rays ``origins`` along ``d``: (face (k,), points, bary), face -1 for
    a miss. A miss or back-facing hit can be a float32 crack at a vertex (Embree): those rays are cast again in
    float64 (one batched call)."""
    hits = scene.first_hit(origins, np.broadcast_to(d, origins.shape))
    face, points, bary = hits.face.copy(), hits.points.copy(), hits.bary.copy()
    front = (face >= 0) & (face_normals(V, F[np.maximum(face, 0)]) @ d < 0.0)
    retry = np.flatnonzero(~front)
    if retry.size:
        h = scene.first_hit(origins[retry], d, exact=True)
        face[retry], points[retry], bary[retry] = h.face, h.points, h.bary
    return face, points, bary


def beam_footprint(light: BeamLight, V, N, A, scene) -> tuple[np.ndarray, np.ndarray]:
    """Vertices lit by a beam of radius > 0: ``(idx, cos)``, the vertices inside its cylinder and in front of its
    start plane (``(v - o) . d > 0``, distance from the axis <= radius), facing it (``cos = -n . d > 0``), with
    area, whose ray back to the start plane (``-d``, up to that plane) meets no other part of the mesh; nearest
    the axis first.

    This is what decides, with the beam's own rays, whether a wide beam reaches the mesh (bake and Monte Carlo):
    the ``BEAM_SAMPLES`` rays alone can all pass beside a mesh that is small, thin or off-axis in a wide beam.
    """
    o, d = np.array(light.origin), np.array(light.direction)
    rel = V - o
    t = rel @ d
    perp = rel - t[:, None] * d
    r2 = np.einsum("ij,ij->i", perp, perp)
    cos = -(N @ d)
    cand = np.flatnonzero((t > 0.0) & (r2 <= light.radius ** 2) & (cos > 0.0) & (A > 0.0))
    cand = cand[np.argsort(r2[cand], kind="stable")]   # nearest the axis first (the first beam's distance field)
    if cand.size:
        origins = scene.offset_origins(V[cand], N[cand], +1.0)
        cand = cand[~scene.occluded(origins, np.broadcast_to(-d, origins.shape), t[cand])]
    return cand, cos[cand]


def _beam_samples(light: BeamLight, i: int, V, F, N, A, get_scene, eta) -> dict:
    """Entry samples of beam ``i`` (dict of arrays, see entry_samples; no sample when it misses)."""
    check_outside_mesh(light, i, V, F)
    scene = get_scene()
    origins = light.ray_origins()
    k = origins.shape[0]
    d = np.array(light.direction)
    face, points, bary = _beam_rays(scene, origins, d, V, F)
    hit = face >= 0
    n = face_normals(V, F[face[hit]])
    cos = -(n @ d)
    if np.any(cos <= 0.0):
        raise LightError(f"beam light {i} reaches the back of a face: the faces are wound inward, "
                         f"or the origin {light.origin} mm is inside the mesh")
    if light.radius > 0.0:
        idx, cos_v = beam_footprint(light, V, N, A, scene)
        if idx.size > int(hit.sum()):  # the vertices resolve the beam's footprint better than its rays
            irradiance = light.power / light.radius / light.radius / math.pi   # W/mm^2, without overflow
            return {**_vertex_part(i, V, N, A, idx, cos_v, np.full(idx.size, irradiance), eta,
                                   np.broadcast_to(d, (idx.size, 3))), "rays": k}
    m = int(hit.sum())
    if m == 0:
        raise beam_miss_error(light, i, V, N, A, get_scene)
    share = light.power / k
    return {
        "positions": points[hit], "face": face[hit], "bary": bary[hit], "vertex": np.full(m, -1),
        "normals": n, "power": share * fresnel_transmittance_entry(cos, eta), "cos": cos,
        "light_index": np.full(m, i), "directions": np.broadcast_to(d, (m, 3)), "incident": share * m,
        "specular": float(np.sum(share * fresnel_reflectance(cos, 1.0, eta))), "rays": k,
    }


# ------------------------------------------------------------------------------------------------ area lights
def _vertex_part(i, V, N, A, idx, cos, irradiance, eta, directions) -> dict:
    """Vertex samples ``idx`` of light ``i`` with incidence cosines ``cos``, ``irradiance`` W/mm^2 across the
    light and unit ``directions`` of travel (per sample): power ``irradiance cos A_v F_t(cos)``."""
    incident_v = irradiance * cos * A[idx]
    power = incident_v * fresnel_transmittance_entry(cos, eta)
    return {
        "positions": V[idx], "face": np.full(idx.size, -1), "bary": np.full((idx.size, 3), np.nan),
        "vertex": idx, "normals": N[idx], "power": np.asarray(power, dtype=np.float64).reshape(-1),
        "cos": cos, "light_index": np.full(idx.size, i), "directions": np.asarray(directions, dtype=np.float64),
        "incident": float(incident_v.sum()),
        "specular": float(np.sum(incident_v * fresnel_reflectance(cos, 1.0, eta))),
    }


def _vertex_samples(light, i, V, F, N, A, culler, eta, stats) -> dict:
    """Entry samples of directional or point light ``i``: one per vertex facing it, with area, not shadowed."""
    if isinstance(light, DirectionalLight):
        toward = -np.array(light.direction)
        cos_all = N @ toward
        target = None
    else:
        target = np.array(light.position)
        check_outside_mesh(light, i, V, F)
        delta = target - V
        dist_all = np.linalg.norm(delta, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            cos_all = np.einsum("ij,ij->i", N, delta) / dist_all
    idx = np.flatnonzero((cos_all > 0.0) & (A > 0.0))
    stats["candidates"] += int(idx.size)
    if target is None:
        seen = culler.visible(idx, N[idx], direction=toward)
    else:
        seen = culler.visible(idx, N[idx], target=target)
    idx = idx[seen]
    if target is None:
        irradiance = np.full(idx.size, light.irradiance)          # W/mm^2 across the beam
    else:
        irradiance = light.emission(V[idx] - target) / dist_all[idx] ** 2   # W/sr / mm^2
        keep = irradiance > 0.0        # outside a spot's cone: no sample
        idx, irradiance = idx[keep], irradiance[keep]
    if target is None:
        directions = np.broadcast_to(-toward, (idx.size, 3))
    else:
        directions = -delta[idx] / dist_all[idx, None]
    return _vertex_part(i, V, N, A, idx, cos_all[idx], irradiance, eta, directions)
