"""Lights (beam, directional, point) and the power they transmit into the medium at entry points on the mesh.

Positions are in mm, directions are unit vectors stored as tuples, powers in W. ``entry_samples`` turns a list
of lights into :class:`EntrySamples`: points on the surface where light enters, each with the power (W) that
crosses the boundary after specular Fresnel reflection (:mod:`meshshade.kernels.fresnel`). Fresnel here is
channel-independent, so one power per sample serves every colour channel.

Only what is needed is simulated: a beam is one ray; a directional or point light considers only vertices that
face it (and have area), and casts a shadow ray only where the mesh *could* occlude it (see
:class:`_ShadowCuller` for the rule and its proof).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Union

import numpy as np

from meshshade.errors import LightError, MaterialError, MeshValidationError, UnitsError
from meshshade.geometry.topology import winding_number
from meshshade.kernels.fresnel import fresnel_reflectance, fresnel_transmittance_entry

# ----------------------------------------------------------------------------------------------------------------
# light types
# ----------------------------------------------------------------------------------------------------------------


def _vec3(value, what: str) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise LightError(f"{what} must be 3 numbers, got {value!r}") from None
    if arr.shape != (3,):
        raise LightError(f"{what} must be 3 numbers, got {value!r}")
    if not np.all(np.isfinite(arr)):
        raise LightError(f"{what} must be finite, got {tuple(float(x) for x in arr)}")
    return tuple(float(x) for x in arr)


def _direction(value, what: str = "direction") -> tuple[float, float, float]:
    d = np.array(_vec3(value, what))
    big = float(np.max(np.abs(d)))
    if big > 0.0:
        d = d / big  # scale first: the norm of (1e308, 1e308, 1e308) overflows
    norm = float(np.linalg.norm(d))
    if not norm > 0.0:
        raise LightError(f"{what} must be non-zero, got {tuple(float(x) for x in d)}")
    return tuple(float(x) for x in d / norm)


def _nonnegative(value, what: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise LightError(f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise LightError(f"{what} must be finite, got {x!r}")
    if x < 0.0:
        raise LightError(f"{what} must be >= 0, got {x!r}")
    return x


#: rays that sample a beam of finite width (a sunflower pattern over its disc)
BEAM_SAMPLES = 64


@dataclass(frozen=True)
class BeamLight:
    """A beam of ``power`` W from ``origin`` (mm) along ``direction`` (normalised).

    ``radius`` = 0 (default) is a pencil beam: one entry point. ``radius`` > 0 [mm] is a collimated beam of uniform
    power over a disc: ``BEAM_SAMPLES`` parallel rays on a sunflower (Vogel) pattern, each carrying an equal share
    of the power; rays that miss the mesh carry their share away.
    """

    origin: tuple[float, float, float]
    direction: tuple[float, float, float]
    power: float = 1.0
    radius: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "origin", _vec3(self.origin, "beam origin"))
        object.__setattr__(self, "direction", _direction(self.direction, "beam direction"))
        object.__setattr__(self, "power", _nonnegative(self.power, "beam power"))
        object.__setattr__(self, "radius", _nonnegative(self.radius, "beam radius"))

    def ray_origins(self) -> np.ndarray:
        """(k, 3) mm: one origin for a pencil beam, ``BEAM_SAMPLES`` over the disc otherwise."""
        o = np.array(self.origin)
        if self.radius == 0.0:
            return o[None, :]
        d = np.array(self.direction)
        u = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(d, u)
        j = np.arange(BEAM_SAMPLES)
        r = self.radius * np.sqrt((j + 0.5) / BEAM_SAMPLES)  # equal-area rings
        a = j * np.pi * (3.0 - np.sqrt(5.0))  # golden angle
        return o + r[:, None] * (np.cos(a)[:, None] * u + np.sin(a)[:, None] * v)


@dataclass(frozen=True)
class DirectionalLight:
    """Parallel light travelling along ``direction`` (normalised), ``irradiance`` W/mm^2 on a surface facing it."""

    direction: tuple[float, float, float]
    irradiance: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "direction", _direction(self.direction, "directional light direction"))
        object.__setattr__(self, "irradiance", _nonnegative(self.irradiance, "directional irradiance"))


@dataclass(frozen=True)
class PointLight:
    """An isotropic point source at ``position`` (mm) of radiant ``intensity`` W/sr."""

    position: tuple[float, float, float]
    intensity: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "position", _vec3(self.position, "point light position"))
        object.__setattr__(self, "intensity", _nonnegative(self.intensity, "point light intensity"))


Light = Union[BeamLight, DirectionalLight, PointLight]

_SPEC_SYNTAX = {
    "beam": "beam:ox,oy,oz:dx,dy,dz[:power[:radius]]",
    "directional": "directional:dx,dy,dz[:irradiance]",
    "point": "point:x,y,z[:intensity]",
}


def _spec_vec3(text: str, what: str) -> np.ndarray:
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 3:
        raise LightError(f"{what} needs 3 comma-separated numbers, got {text!r}")
    try:
        vals = np.array([float(p) for p in parts])
    except ValueError:
        raise LightError(f"{what} needs 3 comma-separated numbers, got {text!r}") from None
    if not np.all(np.isfinite(vals)):
        raise LightError(f"{what} must be finite, got {text!r}")
    return vals


def _spec_scalar(text: str, what: str) -> float:
    try:
        x = float(text.strip())
    except ValueError:
        raise LightError(f"{what} must be a number, got {text!r}") from None
    return x


def parse_light_spec(spec: str, mm_per_unit: float = 1.0) -> Light:
    """Parse a CLI light specification.

    Syntax (positions in the mesh's units, converted to mm with ``mm_per_unit``; directions unitless)::

        beam:ox,oy,oz:dx,dy,dz[:power[:radius]] power in W (default 1); radius of a finite-width beam in the
                                                mesh's units (default 0: a pencil beam)
        directional:dx,dy,dz[:irradiance]       irradiance in W/mm^2 (default 1)
        point:x,y,z[:intensity]                 intensity in W/sr (default 1)

    Raises
    ------
    LightError
        One line naming the problem: unknown type, wrong number of fields, a vector that is not 3 finite
        numbers, a zero direction, a negative or non-finite power/irradiance/intensity.
    UnitsError
        ``mm_per_unit`` not a positive finite number.
    """
    scale = float(mm_per_unit)
    if not (math.isfinite(scale) and scale > 0.0):
        raise UnitsError(f"mm_per_unit must be a positive finite number, got {mm_per_unit!r}")
    if not isinstance(spec, str) or not spec.strip():
        raise LightError(f"empty light spec {spec!r} (expected one of {', '.join(_SPEC_SYNTAX.values())})")
    fields = [f.strip() for f in spec.strip().split(":")]
    kind = fields[0].lower()
    if kind not in _SPEC_SYNTAX:
        raise LightError(f"unknown light type {fields[0]!r} in {spec!r} (expected beam, directional or point)")
    n_vec = 2 if kind == "beam" else 1
    if len(fields) - 1 not in ((n_vec, n_vec + 1, n_vec + 2) if kind == "beam" else (n_vec, n_vec + 1)):
        raise LightError(f"light spec {spec!r} must look like {_SPEC_SYNTAX[kind]}")
    try:
        if kind == "beam":
            origin = _spec_vec3(fields[1], "beam origin") * scale
            direction = _spec_vec3(fields[2], "beam direction")
            power = _spec_scalar(fields[3], "beam power") if len(fields) >= 4 else 1.0
            radius = _spec_scalar(fields[4], "beam radius") * scale if len(fields) == 5 else 0.0
            return BeamLight(origin, direction, power, radius)
        if kind == "directional":
            direction = _spec_vec3(fields[1], "directional light direction")
            irradiance = _spec_scalar(fields[2], "directional irradiance") if len(fields) == 3 else 1.0
            return DirectionalLight(direction, irradiance)
        position = _spec_vec3(fields[1], "point light position") * scale
        intensity = _spec_scalar(fields[2], "point light intensity") if len(fields) == 3 else 1.0
        return PointLight(position, intensity)
    except LightError as exc:
        raise LightError(f"light spec {spec!r}: {exc}") from None


# ----------------------------------------------------------------------------------------------------------------
# entry samples
# ----------------------------------------------------------------------------------------------------------------


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
        needed), ``hull_rule`` (whether the convex-hull rule was tried; see ``_ShadowCuller``).
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


def _is_convex(vertices, faces) -> bool:
    """Whether a triangle mesh bounds a convex body, certified in O(faces) without a convex hull.

    Checks: (1) closed and consistently oriented (every directed edge once, its reverse once); (2) connected;
    (3) Euler characteristic V - E + F = 2 (a sphere); (4) every edge locally convex (the neighbour's opposite
    vertex at most 1e-9 x bbox diagonal in front of the face's plane); (5) every vertex's face-angle sum at most
    2 pi (+1e-9; flat is allowed); (6) positive signed volume (outward faces). (4) and (5) make the surface locally
    convex everywhere unless a vertex star wraps around its vertex more than once, which only a self-intersecting
    mesh can do; a closed, connected, locally convex surface bounds a convex body (Tietze-Nakajima theorem;
    van Heijenoort 1952 for immersed surfaces). A self-intersecting mesh is outside meshshade's domain anyway.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    m, n = F.shape[0], np.int64(V.shape[0])
    if m < 4 or (3 * m) % 2:
        return False
    a = F.reshape(-1)
    b = np.roll(F, -1, axis=1).reshape(-1)
    # (1) sort the directed edges by their undirected key: each key must appear exactly twice, once each way
    key = np.minimum(a, b) * n + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    first, second = order[0::2], order[1::2]
    if not (np.all(key[first] == key[second]) and np.all(key[second[:-1]] != key[first[1:]])):
        return False
    if not (np.all(a[first] == b[second]) and np.all(b[first] == a[second])):
        return False
    twin = np.empty_like(order)
    twin[first], twin[second] = second, first                                  # index of the reverse edge
    used_mask = np.bincount(a, minlength=V.shape[0]) > 0
    graph = coo_matrix((np.ones(first.size), (a[first], b[first])), shape=(V.shape[0], V.shape[0]))
    _, labels = connected_components(graph, directed=False)
    if np.any(labels[a] != labels[a[0]]):                                      # (2)
        return False
    if int(used_mask.sum()) - (3 * m) // 2 + m != 2:                           # (3)
        return False
    tri = V[F]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(cross, axis=1, keepdims=True)
    if np.any(length == 0.0):
        return False
    unit = cross / length
    opposite = F[twin // 3, (twin % 3 + 2) % 3]
    scale = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    height = np.einsum("ij,ij->i", np.repeat(unit, 3, axis=0), V[opposite] - V[a])
    if np.any(height > 1e-9 * scale):                                          # (4)
        return False
    angle_sum = np.zeros(V.shape[0])
    for k in range(3):
        e1 = tri[:, (k + 1) % 3] - tri[:, k]
        e2 = tri[:, (k + 2) % 3] - tri[:, k]
        ang = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=1), np.einsum("ij,ij->i", e1, e2))
        angle_sum += np.bincount(F[:, k], weights=ang, minlength=V.shape[0])
    if np.any(angle_sum[used_mask] > 2.0 * np.pi + 1e-9):                      # (5)
        return False
    return float(np.einsum("ij,ij->i", tri[:, 0], cross).sum()) > 0.0          # (6)


class _ShadowCuller:
    """Decides which shadow rays can be skipped, and casts the rest.

    Rule: the ray from a surface vertex ``p`` toward the light (unit ``L``) cannot meet the mesh if ``p`` lies on a
    *supporting plane* of the mesh (the whole mesh on its back side, outward normal ``n``) with ``n . L > 1e-6``:
    every point ``p + t L``, ``t > 0``, is then strictly in front of that plane, hence off the mesh. This holds for
    a directional light and for the segment to a point light alike. Supporting planes come from:

    * a convex mesh: every face plane supports it, so a vertex is skipped if an adjacent face has
      ``n_f . L > 1e-6``. With vertex normals that are positive combinations of the adjacent face normals (area-
      or angle-weighted), every vertex with ``n_v . L > 0`` has one unless all its faces are within 1e-6 of
      grazing. Convexity is certified in O(faces), see :func:`_is_convex`;
    * the convex hull (scipy/qhull): a hull vertex is skipped if an incident hull facet has ``n . L > 1e-6``.
      Used only with the brute-force ``NumpyScene``, where a ray costs O(faces): with Embree a shadow ray costs
      ~0.3 us while qhull needs seconds on a 1e5-vertex near-spherical mesh, so computing the hull to save rays
      would be a loss.

    Everything else is cast with the scene's ``occluded`` from the vertex, offset along its normal.
    """

    COS_TOL = 1e-6

    def __init__(self, vertices, faces, get_scene, use_hull: bool):
        self.V, self.F = vertices, faces
        self._get_scene = get_scene
        self.use_hull = bool(use_hull)
        self._ready = False
        self.convex: bool | None = None
        self.stats = {"shadow_rays_cast": 0, "shadow_rays_skipped": 0, "skipped_convex": 0, "skipped_hull": 0}

    def _prepare(self):
        if self._ready:
            return
        V, F = self.V, self.F
        tri = V[F]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(cross, axis=1)
        self.face_normals = np.divide(cross, length[:, None], out=np.zeros_like(cross), where=length[:, None] > 0)
        self.convex = _is_convex(V, F)
        self.hull_simplices = np.zeros((0, 3), dtype=np.int64)
        self.hull_normals = np.zeros((0, 3))
        if self.use_hull and not self.convex:
            from scipy.spatial import ConvexHull, QhullError

            try:
                hull = ConvexHull(V)
                self.hull_simplices = hull.simplices.astype(np.int64)
                self.hull_normals = hull.equations[:, :3]
            except (QhullError, ValueError):  # flat or degenerate point sets: no hull, cast every ray
                pass
        self._ready = True

    def _supported(self, idx, L, simplices, normals):
        """(k,) bool: vertex idx[j] lies on a plane in (simplices, normals) with normal . L[j] > COS_TOL."""
        if simplices.shape[0] == 0:
            return np.zeros(idx.size, dtype=bool)
        pos = np.full(self.V.shape[0], -1, dtype=np.int64)
        pos[idx] = np.arange(idx.size)
        pv = pos[simplices.reshape(-1)]
        pf = np.repeat(np.arange(simplices.shape[0]), 3)
        keep = pv >= 0
        pv, pf = pv[keep], pf[keep]
        best = np.full(idx.size, -np.inf)
        np.maximum.at(best, pv, np.einsum("ij,ij->i", normals[pf], L[pv]))
        return best > self.COS_TOL

    def visible(self, idx, normals, target=None, direction=None) -> np.ndarray:
        """(k,) bool: vertex idx[j] sees the light (a point ``target`` (3,) mm, or a unit ``direction`` (3,)).

        normals : (k, 3) unit vertex normals (shadow rays start offset along them).
        """
        k = idx.size
        if k == 0:
            return np.zeros(0, dtype=bool)
        self._prepare()
        p = self.V[idx]
        if target is not None:
            L = target - p
            L /= np.linalg.norm(L, axis=1, keepdims=True)
        else:
            L = np.broadcast_to(direction, (k, 3))
        if self.convex:
            skip = self._supported(idx, L, self.F, self.face_normals)
            self.stats["skipped_convex"] += int(skip.sum())
        else:
            skip = self._supported(idx, L, self.hull_simplices, self.hull_normals)
            self.stats["skipped_hull"] += int(skip.sum())
        self.stats["shadow_rays_skipped"] += int(skip.sum())
        visible = np.ones(k, dtype=bool)
        cast = np.flatnonzero(~skip)
        if cast.size:
            scene = self._get_scene()
            origins = scene.offset_origins(p[cast], normals[cast], +1.0)
            if target is not None:
                to_light = target - origins
                t_max = np.linalg.norm(to_light, axis=1)
                visible[cast] = ~scene.occluded(origins, to_light, t_max)
            else:
                visible[cast] = ~scene.occluded(origins, L[cast], np.inf)
            self.stats["shadow_rays_cast"] += int(cast.size)
        return visible


def _check_mesh_arrays(vertices, faces, vertex_normals, vertex_areas):
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
    from meshshade.raycast.scene import make_scene

    V, F, N, A = _check_mesh_arrays(vertices, faces, vertex_normals, vertex_areas)
    eta = float(eta)
    if not (math.isfinite(eta) and eta > 0.0):
        raise MaterialError(f"eta must be a positive finite number, got {eta!r}")
    if isinstance(lights, (BeamLight, DirectionalLight, PointLight)):
        lights = [lights]
    lights = list(lights)

    cache = {"scene": scene}

    def get_scene():
        if cache["scene"] is None:
            cache["scene"] = make_scene(V, F)
        return cache["scene"]

    # the hull rule pays only where rays are expensive (the brute-force backend), see _ShadowCuller
    culler = _ShadowCuller(V, F, get_scene, use_hull=getattr(scene, "backend", None) == "numpy")
    stats = {"beam_rays": 0, "candidates": 0}
    parts: list[dict] = []
    incident = np.zeros(len(lights))
    specular = np.zeros(len(lights))

    for i, light in enumerate(lights):
        if isinstance(light, BeamLight):
            part = _beam_sample(light, i, V, F, get_scene, eta)
            stats["beam_rays"] += 1
        elif isinstance(light, (DirectionalLight, PointLight)):
            part = _vertex_samples(light, i, V, F, N, A, culler, eta, stats)
        else:
            raise LightError(f"light {i} is not a BeamLight, DirectionalLight or PointLight: {light!r}")
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


def _unit_face_normal(V, F, f: int) -> np.ndarray:
    tri = V[F[f]]
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    return n / np.linalg.norm(n)


def _front_hit(hits, V, F, d) -> bool:
    f = int(hits.face[0])
    return f >= 0 and float(_unit_face_normal(V, F, f) @ d) < 0.0


def _beam_sample(light: BeamLight, i: int, V, F, get_scene, eta) -> dict:
    origins = light.ray_origins()
    k = origins.shape[0]
    d = np.array(light.direction)
    if abs(winding_number(np.array(light.origin), V, F)) > 0.5:
        raise LightError(f"beam light {i} starts inside the mesh (origin {light.origin} mm)")
    scene = get_scene()
    D = np.broadcast_to(d, (k, 3))
    hits = scene.first_hit(origins, D)
    face = hits.face.copy()
    points, bary = hits.points.copy(), hits.bary.copy()
    for j in range(k):  # a miss or a back-facing hit can be a float32 crack at a vertex (Embree): float64 retry
        if not (face[j] >= 0 and float(_unit_face_normal(V, F, int(face[j])) @ d) < 0.0):
            h = scene.first_hit(origins[j], d, exact=True)
            face[j], points[j], bary[j] = h.face[0], h.points[0], h.bary[0]
    hit = face >= 0
    if not np.any(hit):
        raise LightError(f"beam light {i} from {light.origin} mm along {light.direction} misses the mesh")
    n = np.array([_unit_face_normal(V, F, int(f)) for f in face[hit]])
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
    if isinstance(light, DirectionalLight):
        toward = -np.array(light.direction)
        cos_all = N @ toward
        target = None
    else:
        target = np.array(light.position)
        if abs(winding_number(target, V, F)) > 0.5:
            raise LightError(f"point light {i} at {light.position} mm is inside the mesh")
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
