"""Light sources: beam, directional, point, environment and area lights, validated when they are built.

Positions are in mm, directions are unit vectors stored as tuples (normalised on construction), powers in W,
irradiance in W/mm^2, intensity in W/sr, radiance W/(mm^2 sr). An :class:`EnvironmentLight` (an equirectangular
map, or ``uniform:L``) and an :class:`AreaLight` (a Lambertian rectangle or disc) light the surface from many
directions; what they deposit is estimated by :mod:`meshshade.light.incidence` (the map's directions and
importance sampling: :mod:`meshshade.light.environment`; the emitter's points: :mod:`meshshade.light.area`).

A light that exists is valid: its constructor rejects non-finite or malformed vectors, zero directions, and a
power/irradiance/intensity/radiance that is not a finite number in (0, ``MAX_LIGHT_STRENGTH``] = (0, 1e20], with a
:class:`~meshshade.errors.LightError`. What depends on the mesh (a beam, point or area light inside it) is checked
by :func:`check_outside_mesh`.

Why 1e20: no physical source comes near it in any of the three units (the Sun emits 3.8e26 W in all directions,
i.e. 3e25 W/sr; the most intense focused lasers reach ~1e21 W/mm^2 for femtoseconds), and it keeps every result
finite: exitance is at most the entering power times the largest kernel value, ~sigma_t'^2 <= 1e12 /mm^2 for the
coefficients materials allow (``materials.SIGMA_MAX``), so radiance stays below ~1e32, within float32 (3.4e38) of
the PLY and EXR outputs. Zero is refused: a light that carries nothing would give an all-zero result.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Union

import numpy as np

from meshshade.errors import LightError
from meshshade.geometry.topology import winding_number

__all__ = ["BEAM_SAMPLES", "MAX_LIGHT_STRENGTH", "BeamLight", "DirectionalLight", "PointLight", "Spot",
           "EnvironmentLight", "AreaLight", "Light", "LIGHT_TYPES", "light_list", "check_outside_mesh",
           "describe_light", "MAX_DIRECTIONS", "ENV_UP_AXES", "AREA_SHAPES"]

#: upper bound of a light's power [W], irradiance [W/mm^2] or intensity [W/sr] (module docstring)
MAX_LIGHT_STRENGTH = 1e20


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


def _number(value, what: str) -> float:
    if isinstance(value, bool):
        raise LightError(f"{what} must be a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise LightError(f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise LightError(f"{what} must be finite, got {x!r}")
    return x


def _nonnegative(value, what: str) -> float:
    x = _number(value, what)
    if x < 0.0:
        raise LightError(f"{what} must be >= 0, got {x!r}")
    return x


def _strength(value, what: str, unit: str) -> float:
    """A power, irradiance or intensity: a finite number in (0, MAX_LIGHT_STRENGTH]."""
    x = _number(value, what)
    if not 0.0 < x <= MAX_LIGHT_STRENGTH:
        raise LightError(f"{what} must be > 0 and at most {MAX_LIGHT_STRENGTH:.0e} {unit}, got {x!r}"
                         .replace("e+", "e"))
    return x


#: rays that sample a beam of finite width (a sunflower pattern over its disc)
BEAM_SAMPLES = 64


@dataclass(frozen=True)
class BeamLight:
    """A beam of ``power`` W from ``origin`` (mm) along ``direction`` (normalised).

    ``radius`` = 0 (default) is a pencil beam: one entry point. ``radius`` > 0 [mm] is a collimated beam of uniform
    power over a disc: ``BEAM_SAMPLES`` parallel rays on a sunflower (Vogel) pattern, each carrying an equal share
    of the power; rays that miss the mesh carry their share away. When more mesh vertices than rays lie lit in its
    cylinder (a beam wide compared with the mesh), the bake samples it at those vertices instead, with irradiance
    ``power / (pi radius^2)`` (:func:`meshshade.light.samples.beam_footprint`); Monte Carlo draws its photons
    uniformly over the disc. ``power`` in (0, 1e20] W; ``radius`` finite and >= 0.
    """

    origin: tuple[float, float, float]
    direction: tuple[float, float, float]
    power: float = 1.0
    radius: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "origin", _vec3(self.origin, "beam origin"))
        object.__setattr__(self, "direction", _direction(self.direction, "beam direction"))
        object.__setattr__(self, "power", _strength(self.power, "beam power", "W"))
        object.__setattr__(self, "radius", _nonnegative(self.radius, "beam radius"))

    def disc_basis(self) -> tuple[np.ndarray, np.ndarray]:
        """(u, v): orthonormal (3,) vectors spanning the beam's start plane (perpendicular to ``direction``)."""
        d = np.array(self.direction)
        u = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        return u, np.cross(d, u)

    def ray_origins(self) -> np.ndarray:
        """(k, 3) mm: one origin for a pencil beam, ``BEAM_SAMPLES`` over the disc otherwise."""
        o = np.array(self.origin)
        if self.radius == 0.0:
            return o[None, :]
        u, v = self.disc_basis()
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
        object.__setattr__(self, "irradiance", _strength(self.irradiance, "directional irradiance", "W/mm^2"))


@dataclass(frozen=True)
class Spot:
    """The cone of a spot light: ``axis`` (normalised), full cone ``angle`` in (0, pi] rad and edge ``blend`` in
    [0, 1], as Blender's ``spot_size`` and ``spot_blend``.

    :meth:`falloff` is the fraction of the axial intensity emitted at an angle theta from the axis: with
    c = cos(angle / 2) and t = (cos theta - c) / ((1 - c) blend), smoothstep(t) = 3t^2 - 2t^3 clamped to [0, 1]
    (1 inside the cone and 0 outside when ``blend`` = 0): Cycles' spot attenuation, so a Blender spot bakes as
    Cycles renders it (checked against a Cycles render in tests/blender/test_addon.py).
    """

    axis: tuple[float, float, float]
    angle: float = math.pi
    blend: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "axis", _direction(self.axis, "spot axis"))
        angle = _number(self.angle, "spot cone angle")
        if not 0.0 < angle <= math.pi:
            raise LightError(f"spot cone angle must be in (0, pi] rad, got {angle!r}")
        blend = _number(self.blend, "spot blend")
        if not 0.0 <= blend <= 1.0:
            raise LightError(f"spot blend must be in [0, 1], got {blend!r}")
        object.__setattr__(self, "angle", angle)
        object.__setattr__(self, "blend", blend)

    def falloff(self, cos_theta):
        """Fraction in [0, 1] of the axial intensity at ``cos_theta`` (array) from the axis."""
        x = np.asarray(cos_theta, dtype=np.float64)
        c = math.cos(0.5 * self.angle)
        width = (1.0 - c) * self.blend   # 0 also for a blend so small that the product underflows: a hard edge
        if not width > 0.0:
            return np.where(x >= c, 1.0, 0.0)
        with np.errstate(over="ignore"):   # a width near the underflow: x - c over it saturates, as it should
            t = np.clip((x - c) / width, 0.0, 1.0)
        return t * t * (3.0 - 2.0 * t)

    def towards(self, delta):
        """:meth:`falloff` for the (k, 3) vectors ``delta`` from the light to the lit points."""
        d = np.asarray(delta, dtype=np.float64)
        n = np.linalg.norm(d, axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            cos = np.where(n > 0.0, d @ np.array(self.axis) / n, 1.0)
        return self.falloff(cos)


@dataclass(frozen=True)
class PointLight:
    """A point source at ``position`` (mm) of radiant ``intensity`` W/sr: isotropic, or, with ``spot`` (a
    :class:`Spot`), ``intensity`` along the spot's axis times :meth:`Spot.falloff` away from it."""

    position: tuple[float, float, float]
    intensity: float = 1.0
    spot: Spot | None = None

    def __post_init__(self):
        object.__setattr__(self, "position", _vec3(self.position, "point light position"))
        object.__setattr__(self, "intensity", _strength(self.intensity, "point light intensity", "W/sr"))
        if self.spot is not None and not isinstance(self.spot, Spot):
            raise LightError(f"a point light's spot must be a Spot, got {self.spot!r}")

    def emission(self, delta):
        """W/sr towards the (k, 3) vectors ``delta`` from the light: ``intensity``, times the spot's falloff."""
        k = np.asarray(delta).shape[0]
        if self.spot is None:
            return np.full(k, self.intensity)
        return self.intensity * self.spot.towards(delta)


#: the most directions (environment) or emitter points (area light) a lit vertex's estimate may take
MAX_DIRECTIONS = 4096
#: the up axes an environment map may be given in: ``y`` (glTF, OBJ and meshshade's meshes), ``z`` (Blender's world)
ENV_UP_AXES = ("y", "z")
AREA_SHAPES = ("rect", "disc")


def _quadrature_knobs(light, what: str) -> None:
    """Check (and store as plain numbers) the ``error``, ``max_directions``, ``seed`` and ``aggregate`` of an
    environment or area light."""
    error = _number(light.error, f"{what} error")
    if not 1e-4 <= error <= 0.5:
        raise LightError(f"{what} error must be in [1e-4, 0.5] (a relative standard error), got {error!r}")
    k = light.max_directions
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 16 <= int(k) <= MAX_DIRECTIONS:
        raise LightError(f"{what} max_directions must be a whole number in [16, {MAX_DIRECTIONS}], got {k!r}")
    seed = light.seed
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or int(seed) < 0:
        raise LightError(f"{what} seed must be a whole number >= 0, got {seed!r}")
    object.__setattr__(light, "error", error)
    object.__setattr__(light, "max_directions", int(k))
    object.__setattr__(light, "seed", int(seed))
    object.__setattr__(light, "aggregate", bool(light.aggregate))


@dataclass(frozen=True)
class EnvironmentLight:
    """Light arriving from every direction, as an equirectangular map of radiance (an HDRI; ``uniform:L``).

    ``radiance`` (H, W) float64 with W = 2H, >= 0, finite, not all zero: radiance in W/(mm^2 sr) per unit
    ``strength`` (so the light's radiance is ``strength x radiance``), row 0 at the zenith, piecewise constant over
    the pixels (:mod:`meshshade.light.environment`: which direction each pixel covers, ``up``, ``rotation_deg``
    about the up axis as Blender's Mapping node). A light read from a file keeps its ``path`` (for messages and
    specs); :meth:`uniform` is a constant sky of radiance L (the furnace test).

    The light a lit vertex receives is estimated from ``max_directions`` directions at most, as many as needed
    for a relative standard ``error`` of its entering power (:mod:`meshshade.light.incidence`), drawn from random
    streams keyed by ``seed``. ``aggregate``: one entry sample per lit vertex (its power along the power-weighted
    mean refracted direction) rather than one per (vertex, direction).
    """

    radiance: np.ndarray = field(repr=False, compare=False)
    strength: float = 1.0
    rotation_deg: float = 0.0
    up: str = "y"
    path: str | None = None
    error: float = 0.005
    max_directions: int = 1024
    seed: int = 0
    aggregate: bool = True
    digest: str = field(init=False, repr=False, default="")

    def __post_init__(self):
        try:
            Y = np.array(self.radiance, dtype=np.float64)
        except (TypeError, ValueError):
            raise LightError("an environment map must be an (H, 2H) array of numbers") from None
        if Y.ndim != 2 or Y.shape[0] < 1 or Y.shape[1] != 2 * Y.shape[0]:
            raise LightError(f"an environment map must be an (H, 2H) array (360 by 180 degrees), got shape {Y.shape}")
        if not np.all(np.isfinite(Y)) or Y.min() < 0.0:
            raise LightError("an environment map's radiance must be finite and >= 0")
        if not Y.max() > 0.0:
            raise LightError("an environment map that is black everywhere lights nothing")
        Y.setflags(write=False)
        object.__setattr__(self, "radiance", Y)
        strength = _strength(self.strength, "environment strength", "W/(mm^2 sr)")
        if strength * float(Y.max()) > MAX_LIGHT_STRENGTH:
            raise LightError(f"environment radiance must be at most {MAX_LIGHT_STRENGTH:.0e} W/(mm^2 sr): strength "
                             f"{strength:.6g} x the map's brightest pixel {float(Y.max()):.6g}".replace("e+", "e"))
        object.__setattr__(self, "strength", strength)
        object.__setattr__(self, "rotation_deg", _number(self.rotation_deg, "environment rotation"))
        if self.up not in ENV_UP_AXES:
            raise LightError(f"environment up axis must be one of {', '.join(ENV_UP_AXES)}, got {self.up!r}")
        if self.path is not None:
            object.__setattr__(self, "path", str(self.path))
        _quadrature_knobs(self, "environment")
        h = hashlib.sha256(np.ascontiguousarray(Y).tobytes() + repr(Y.shape).encode()).hexdigest()[:16]
        object.__setattr__(self, "digest", h)

    @classmethod
    def uniform(cls, radiance: float = 1.0, **knobs) -> "EnvironmentLight":
        """A constant sky of ``radiance`` W/(mm^2 sr) from every direction (``uniform:L``)."""
        return cls(np.ones((1, 2)), strength=_strength(radiance, "uniform radiance", "W/(mm^2 sr)"), **knobs)

    @property
    def is_uniform(self) -> bool:
        """Whether the sky is the same radiance in every direction."""
        return bool(self.radiance.min() == self.radiance.max())


@dataclass(frozen=True)
class AreaLight:
    """A one-sided Lambertian emitter of ``power`` W: a rectangle or a disc (ellipse) centred at ``position`` (mm),
    emitting into the half-space its unit ``normal`` points to, with radiance ``power / (pi area)`` W/(mm^2 sr).

    ``shape`` "rect": ``size`` = (width, height) mm along its axes u and v; "disc": ``size`` = (radius along u,
    radius along v) mm (a circle when equal). The axes (:meth:`axes`): v is ``up`` projected on the emitter's
    plane (default +Y, or +Z for a normal along +-Y), u = v x normal (so u, v, normal are right-handed). ``error``,
    ``max_directions`` (emitter points per lit vertex), ``seed`` and ``aggregate`` as for
    :class:`EnvironmentLight`.
    """

    position: tuple[float, float, float]
    normal: tuple[float, float, float]
    shape: str = "rect"
    size: tuple = (1.0, 1.0)
    power: float = 1.0
    up: tuple | None = None
    error: float = 0.005
    max_directions: int = 1024
    seed: int = 0
    aggregate: bool = True

    def __post_init__(self):
        object.__setattr__(self, "position", _vec3(self.position, "area light position"))
        object.__setattr__(self, "normal", _direction(self.normal, "area light normal"))
        if self.shape not in AREA_SHAPES:
            raise LightError(f"area light shape must be rect or disc, got {self.shape!r}")
        try:
            size = tuple(float(x) for x in np.atleast_1d(np.asarray(self.size, dtype=np.float64)))
        except (TypeError, ValueError):
            raise LightError(f"area light size must be 1 or 2 numbers, got {self.size!r}") from None
        size = size * 2 if len(size) == 1 else size
        if len(size) != 2 or not all(math.isfinite(x) and x > 0.0 for x in size):
            raise LightError(f"area light size must be 1 or 2 finite numbers > 0 (mm), got {self.size!r}")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "power", _strength(self.power, "area light power", "W"))
        if self.up is not None:
            up = _direction(self.up, "area light up")
            if abs(float(np.dot(up, self.normal))) > 1.0 - 1e-9:
                raise LightError("area light up must not be parallel to its normal")
            object.__setattr__(self, "up", up)
        _quadrature_knobs(self, "area light")

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """(u, v): the emitter's in-plane unit axes (width/first radius along u, height/second radius along v)."""
        n = np.array(self.normal)
        if self.up is not None:
            ref = np.array(self.up)
        else:
            ref = np.array([0.0, 0.0, 1.0]) if abs(n[1]) > 1.0 - 1e-9 else np.array([0.0, 1.0, 0.0])
        v = ref - (ref @ n) * n
        v /= np.linalg.norm(v)
        return np.cross(v, n), v

    @property
    def area(self) -> float:
        """Emitting area in mm^2."""
        a, b = self.size
        return a * b if self.shape == "rect" else math.pi * a * b

    @property
    def radiance(self) -> float:
        """Radiance of the Lambertian emitter, W/(mm^2 sr): power / (pi area)."""
        return self.power / (math.pi * self.area)


Light = Union[BeamLight, DirectionalLight, PointLight, EnvironmentLight, AreaLight]

#: the light classes, for ``isinstance`` checks
LIGHT_TYPES = (BeamLight, DirectionalLight, PointLight, EnvironmentLight, AreaLight)


def light_list(lights) -> list[Light]:
    """``lights`` (one light or an iterable of them) as a list, every element checked to be a light.

    The constructors have validated every field already, so only the type is checked here.

    Raises
    ------
    LightError
        An element that is not a light (:data:`LIGHT_TYPES`).
    """
    if isinstance(lights, LIGHT_TYPES):
        return [lights]
    out = list(lights)
    for i, light in enumerate(out):
        if not isinstance(light, LIGHT_TYPES):
            raise LightError(f"light {i} is not a BeamLight, DirectionalLight, PointLight, EnvironmentLight or "
                             f"AreaLight: {light!r}")
    return out


def _fmt_vec(v) -> str:
    return "(" + ", ".join(f"{float(x):.6g}" for x in v) + ")"


def describe_light(light: Light, index: int) -> str:
    """Short one-line name of light ``index`` for messages, e.g. ``directional light 0 (travelling along (0, 0, 1),
    irradiance 1 W/mm^2)``."""
    if isinstance(light, BeamLight):
        width = f", radius {light.radius:.6g} mm" if light.radius > 0 else ""
        return (f"beam light {index} (from {_fmt_vec(light.origin)} mm along {_fmt_vec(light.direction)}, "
                f"power {light.power:.6g} W{width})")
    if isinstance(light, DirectionalLight):
        return (f"directional light {index} (travelling along {_fmt_vec(light.direction)}, "
                f"irradiance {light.irradiance:.6g} W/mm^2)")
    if isinstance(light, EnvironmentLight):
        if light.is_uniform and light.path is None:
            return f"uniform light {index} (radiance {light.strength * float(light.radiance.max()):.6g} W/(mm^2 sr))"
        h, w = light.radiance.shape
        name = repr(light.path) if light.path is not None else f"a {w}x{h} map"
        return (f"environment light {index} ({name}, strength {light.strength:.6g}, rotated "
                f"{light.rotation_deg:.6g} deg about +{light.up})")
    if isinstance(light, AreaLight):
        a, b = light.size
        shape = f"rect {a:.6g} x {b:.6g} mm" if light.shape == "rect" else f"disc of radii {a:.6g}, {b:.6g} mm"
        return (f"area light {index} ({shape} at {_fmt_vec(light.position)} mm facing {_fmt_vec(light.normal)}, "
                f"power {light.power:.6g} W)")
    if light.spot is not None:
        sp = light.spot
        return (f"spot light {index} (at {_fmt_vec(light.position)} mm along {_fmt_vec(sp.axis)}, intensity "
                f"{light.intensity:.6g} W/sr, cone {math.degrees(sp.angle):.6g} deg, blend {sp.blend:.6g})")
    return f"point light {index} (at {_fmt_vec(light.position)} mm, intensity {light.intensity:.6g} W/sr)"


def check_outside_mesh(light: Light, index: int, vertices, faces) -> None:
    """Raise if a beam's origin or a point light's position lies inside the closed mesh (|winding number| > 1/2).

    light : a validated light (directional lights have no position and always pass); index : its position in
    the caller's light list (for the message); vertices : (n, 3) float64 mm; faces : (m, 3) int.

    Raises
    ------
    LightError
        "beam light {index} starts inside the mesh ..." or "point light {index} at ... is inside the mesh".
    """
    if isinstance(light, BeamLight):
        if abs(winding_number(np.array(light.origin), vertices, faces)) > 0.5:
            raise LightError(f"beam light {index} starts inside the mesh (origin {light.origin} mm)")
    elif isinstance(light, PointLight):
        if abs(winding_number(np.array(light.position), vertices, faces)) > 0.5:
            raise LightError(f"point light {index} at {light.position} mm is inside the mesh")
    elif isinstance(light, AreaLight):
        if abs(winding_number(np.array(light.position), vertices, faces)) > 0.5:
            raise LightError(f"area light {index} at {light.position} mm is inside the mesh")
