"""Entry samples: where each light enters the medium and the power it transmits there.

Positions are in mm, powers in W. ``entry_samples`` turns a list of lights (:mod:`meshshade.light.sources`) into
:class:`EntrySamples`: points on the surface where light enters, each with the power (W) that crosses the
boundary after specular Fresnel reflection (:mod:`meshshade.kernels.fresnel`). Fresnel here is
channel-independent, so one power per sample serves every colour channel.

Only what is needed is simulated: a beam is one ray (or ``BEAM_SAMPLES`` for a finite-width beam); a directional
or point light considers only vertices that face it (and have area), and casts a shadow ray only where the mesh
*could* occlude it (see :class:`meshshade.light.shadows.ShadowCuller` for the rule and its proof).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from meshshade.errors import LightError, MaterialError, MeshValidationError
from meshshade.geometry.mesh import face_normals
from meshshade.kernels.fresnel import fresnel_reflectance, fresnel_transmittance_entry
from meshshade.light.shadows import ShadowCuller
from meshshade.light.sources import BeamLight, DirectionalLight, check_outside_mesh, light_list
from meshshade.raycast import make_scene

__all__ = ["EntrySamples", "entry_samples"]


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
    eta : float > 0, relative index of the medium (outside is index 1)

    Returns
    -------
    EntrySamples
        * beam: one sample at the first hit, power ``P F_t(cos)``, ``cos`` from the geometric face normal;
        * directional: one sample per vertex facing the light (``n . (-d) > 0``) and not shadowed, power
          ``E cos F_t(cos) A_v``;
        * point: likewise with ``E = I / dist**2`` (the irradiance across the ray; ``E cos`` on the surface) and
          the shadow ray stopped at the light.

    Raises
    ------
    LightError
        A beam that misses the mesh or starts inside it; a point light inside the mesh.

    Warns
    -----
    UserWarning
        A directional or point light that reaches no vertex (all facing away or shadowed).
    """
    V, F, N, A = _check_mesh_arrays(vertices, faces, vertex_normals, vertex_areas)
    eta = float(eta)
    if not (math.isfinite(eta) and eta > 0.0):
        raise MaterialError(f"eta must be a positive finite number, got {eta!r}")
    lights = light_list(lights)

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
            part = _beam_sample(light, i, V, F, get_scene, eta)
            stats["beam_rays"] += 1
        else:
            part = _vertex_samples(light, i, V, F, N, A, culler, eta, stats)
        incident[i] = part.pop("incident")
        specular[i] = part.pop("specular")
        parts.append(part)

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
        incident_power=incident,
        specular_power=specular,
        stats=stats,
    )


def _beam_sample(light: BeamLight, i: int, V, F, get_scene, eta) -> dict:
    """Entry samples of beam ``i``: one per ray that hits the front of a face (dict of arrays, see entry_samples)."""
    origins = light.ray_origins()
    k = origins.shape[0]
    d = np.array(light.direction)
    check_outside_mesh(light, i, V, F)
    scene = get_scene()
    D = np.broadcast_to(d, (k, 3))
    hits = scene.first_hit(origins, D)
    face = hits.face.copy()
    points, bary = hits.points.copy(), hits.bary.copy()
    hit_normals = face_normals(V, F[np.maximum(face, 0)])      # (k, 3) unit; rows of misses unused
    for j in range(k):  # a miss or a back-facing hit can be a float32 crack at a vertex (Embree): float64 retry
        if not (face[j] >= 0 and float(hit_normals[j] @ d) < 0.0):
            h = scene.first_hit(origins[j], d, exact=True)
            face[j], points[j], bary[j] = h.face[0], h.points[0], h.bary[0]
    hit = face >= 0
    if not np.any(hit):
        raise LightError(f"beam light {i} from {light.origin} mm along {light.direction} misses the mesh")
    n = face_normals(V, F[face[hit]])
    cos = -(n @ d)
    if np.any(cos <= 0.0):
        raise LightError(f"beam light {i} reaches the back of a face: the faces are wound inward, "
                         f"or the origin {light.origin} mm is inside the mesh")
    share = light.power / k
    m = int(hit.sum())
    return {
        "positions": points[hit], "face": face[hit], "bary": bary[hit], "vertex": np.full(m, -1),
        "normals": n, "power": share * fresnel_transmittance_entry(cos, eta), "cos": cos,
        "light_index": np.full(m, i), "incident": share * m,
        "specular": float(np.sum(share * fresnel_reflectance(cos, 1.0, eta))),
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
    cos = cos_all[idx]
    if target is None:
        irradiance = np.full(idx.size, light.irradiance)          # W/mm^2 across the beam
    else:
        irradiance = light.intensity / dist_all[idx] ** 2          # W/sr / mm^2
    incident_v = irradiance * cos * A[idx]
    power = incident_v * fresnel_transmittance_entry(cos, eta)
    if idx.size == 0:
        warnings.warn(f"light {i} ({light!r}) reaches no vertex of the mesh "
                      "(every vertex faces away or is shadowed)", UserWarning, stacklevel=3)
    return {
        "positions": V[idx], "face": np.full(idx.size, -1), "bary": np.full((idx.size, 3), np.nan),
        "vertex": idx, "normals": N[idx], "power": np.asarray(power, dtype=np.float64).reshape(-1),
        "cos": cos, "light_index": np.full(idx.size, i), "incident": float(incident_v.sum()),
        "specular": float(np.sum(incident_v * fresnel_reflectance(cos, 1.0, eta))),
    }
