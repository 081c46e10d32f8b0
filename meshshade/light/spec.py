"""Text specifications of lights (the CLI's ``--light``): ``beam:...``, ``directional:...``, ``point:...``,
``spot:...``."""
from __future__ import annotations

import math

import numpy as np

from meshshade.errors import LightError, UnitsError
from meshshade.light.sources import BeamLight, DirectionalLight, Light, PointLight, Spot

__all__ = ["parse_light_spec", "SPOT_CONE_DEG", "SPOT_BLEND"]

#: a spot's cone (full angle, degrees) and edge softness when the spec leaves them out (Blender's defaults)
SPOT_CONE_DEG = 45.0
SPOT_BLEND = 0.15

_SPEC_SYNTAX = {
    "beam": "beam:ox,oy,oz:dx,dy,dz[:power[:radius]]",
    "directional": "directional:dx,dy,dz[:irradiance]",
    "point": "point:x,y,z[:intensity]",
    "spot": "spot:x,y,z:dx,dy,dz[:intensity[:cone_deg[:blend]]]",
}


def _spec_vec3(text: str, what: str) -> np.ndarray:
    """(3,) float64 from ``"x,y,z"``; LightError unless 3 finite comma-separated numbers."""
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
    """One number; LightError if ``text`` is not one (range checks are the light constructors')."""
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
        spot:x,y,z:dx,dy,dz[:intensity[:cone_deg[:blend]]]
                                                a point light shining along dx,dy,dz inside a cone of full
                                                angle cone_deg (default 45) with edge softness blend in [0, 1]
                                                (default 0.15), as Blender's spot; intensity in W/sr on its axis

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
        raise LightError(f"unknown light type {fields[0]!r} in {spec!r} (expected beam, directional, point or spot)")
    n_vec = 2 if kind in ("beam", "spot") else 1
    n_more = {"beam": 2, "directional": 1, "point": 1, "spot": 3}[kind]
    if not n_vec <= len(fields) - 1 <= n_vec + n_more:
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
        if kind == "spot":
            position = _spec_vec3(fields[1], "spot light position") * scale
            axis = _spec_vec3(fields[2], "spot light direction")
            intensity = _spec_scalar(fields[3], "spot light intensity") if len(fields) >= 4 else 1.0
            cone = _spec_scalar(fields[4], "spot cone angle") if len(fields) >= 5 else SPOT_CONE_DEG
            blend = _spec_scalar(fields[5], "spot blend") if len(fields) == 6 else SPOT_BLEND
            if not 0.0 < cone <= 180.0:
                raise LightError(f"spot cone angle must be in (0, 180] degrees, got {cone!r}")
            return PointLight(position, intensity, spot=Spot(axis, math.radians(cone), blend))
        position = _spec_vec3(fields[1], "point light position") * scale
        intensity = _spec_scalar(fields[2], "point light intensity") if len(fields) == 3 else 1.0
        return PointLight(position, intensity)
    except LightError as exc:
        raise LightError(f"light spec {spec!r}: {exc}") from None
