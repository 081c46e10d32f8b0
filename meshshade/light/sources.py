"""Light sources: beam, directional and point lights, validated when they are built.

Positions are in mm, directions are unit vectors stored as tuples (normalised on construction), powers in W,
irradiance in W/mm^2, intensity in W/sr. A light that exists is valid: its constructor rejects non-finite or
malformed vectors, zero directions and negative or non-finite powers with a :class:`~meshshade.errors.LightError`.
What depends on the mesh (a beam or point light inside it) is checked by :func:`check_outside_mesh`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

import numpy as np

from meshshade.errors import LightError
from meshshade.geometry.topology import winding_number

__all__ = ["BEAM_SAMPLES", "BeamLight", "DirectionalLight", "PointLight", "Light", "LIGHT_TYPES", "light_list",
           "check_outside_mesh"]


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

#: the light classes, for ``isinstance`` checks
LIGHT_TYPES = (BeamLight, DirectionalLight, PointLight)


def light_list(lights) -> list[Light]:
    """``lights`` (one light or an iterable of them) as a list, every element checked to be a light.

    The constructors have validated every field already, so only the type is checked here.

    Raises
    ------
    LightError
        An element that is not a :class:`BeamLight`, :class:`DirectionalLight` or :class:`PointLight`.
    """
    if isinstance(lights, LIGHT_TYPES):
        return [lights]
    out = list(lights)
    for i, light in enumerate(out):
        if not isinstance(light, LIGHT_TYPES):
            raise LightError(f"light {i} is not a BeamLight, DirectionalLight or PointLight: {light!r}")
    return out


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
