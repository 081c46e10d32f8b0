"""Text specifications of lights (the CLI's ``--light``): ``beam:...``, ``directional:...``, ``point:...``,
``spot:...``, ``env:...``, ``uniform:...``, ``area:...``."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from meshshade.errors import LightError, UnitsError
from meshshade.io import read_environment_map
from meshshade.light.environment import environment_from_rgb
from meshshade.light.sources import (ENV_UP_AXES, AreaLight, BeamLight, DirectionalLight, EnvironmentLight, Light,
                                     PointLight, Spot)

__all__ = ["parse_light_spec", "SPOT_CONE_DEG", "SPOT_BLEND", "LIGHT_KINDS"]

#: a spot's cone (full angle, degrees) and edge softness when the spec leaves them out (Blender's defaults)
SPOT_CONE_DEG = 45.0
SPOT_BLEND = 0.15

_SPEC_SYNTAX = {
    "beam": "beam:ox,oy,oz:dx,dy,dz[:power[:radius]]",
    "directional": "directional:dx,dy,dz[:irradiance]",
    "point": "point:x,y,z[:intensity]",
    "spot": "spot:x,y,z:dx,dy,dz[:intensity[:cone_deg[:blend]]]",
    "env": "env:FILE[:strength[:rotation_deg[:up]]]",
    "uniform": "uniform[:radiance]",
    "area": "area:x,y,z:nx,ny,nz:rect:w,h[:power[:ux,uy,uz]] or area:x,y,z:nx,ny,nz:disc:r[,r2][:power[:ux,uy,uz]]",
}
#: the light types of a spec, in the order messages name them
LIGHT_KINDS = tuple(_SPEC_SYNTAX)


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


def _numbers(text: str, what: str, counts: tuple[int, ...]) -> list[float]:
    """Comma-separated finite numbers, as many as one of ``counts``; LightError otherwise."""
    try:
        vals = [float(p) for p in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) not in counts or not all(map(math.isfinite, vals)):
        raise LightError(f"{what} needs {' or '.join(map(str, counts))} comma-separated finite number(s), got {text!r}")
    return vals


def _env_spec(rest: str, spec: str) -> EnvironmentLight:
    """``FILE[:strength[:rotation_deg[:up]]]``: the path is what remains once the longest tail of valid optional
    fields is taken off (so a path may hold colons, ``C:/maps/studio.exr``)."""
    parts = rest.split(":")

    def tail_ok(extra):
        if len(extra) == 3 and extra[2].strip().lower() not in ENV_UP_AXES:
            return False
        try:
            [float(x) for x in extra[:2]]
        except ValueError:
            return False
        return True

    for n_extra in range(min(3, len(parts) - 1), -1, -1):
        extra = parts[len(parts) - n_extra:] if n_extra else []
        if tail_ok(extra):
            break
    path = ":".join(parts[:len(parts) - n_extra]).strip()
    if not path:
        raise LightError(f"light spec {spec!r} must look like {_SPEC_SYNTAX['env']}")
    if not Path(path).exists():
        for k in range(1, len(parts)):            # a bad optional field after an existing file: say which
            head = ":".join(parts[:k]).strip()
            if head and Path(head).is_file():
                raise LightError(f"light spec {spec!r}: after the map {head!r} come strength, rotation (numbers) "
                                 f"and up ({' or '.join(ENV_UP_AXES)}): {_SPEC_SYNTAX['env']}")
    strength = _spec_scalar(extra[0], "environment strength") if n_extra >= 1 else 1.0
    rotation = _spec_scalar(extra[1], "environment rotation") if n_extra >= 2 else 0.0
    up = extra[2].strip().lower() if n_extra == 3 else "y"
    rgb = read_environment_map(path)
    return environment_from_rgb(rgb, path=path, strength=strength, rotation_deg=rotation, up=up)


def _area_spec(fields: list[str], spec: str, scale: float) -> AreaLight:
    """``area:x,y,z:nx,ny,nz:rect:w,h[:power[:ux,uy,uz]]`` or ``...:disc:r[,r2][:power[:ux,uy,uz]]``."""
    if not 5 <= len(fields) <= 7:
        raise LightError(f"light spec {spec!r} must look like {_SPEC_SYNTAX['area']}")
    position = _spec_vec3(fields[1], "area light position") * scale
    normal = _spec_vec3(fields[2], "area light normal")
    shape = fields[3].lower()
    if shape not in ("rect", "disc"):
        raise LightError(f"area light shape must be rect or disc, got {fields[3]!r}")
    size = _numbers(fields[4], "a rect's width,height" if shape == "rect" else "a disc's radius (or two radii)",
                    (2,) if shape == "rect" else (1, 2))
    power = _spec_scalar(fields[5], "area light power") if len(fields) >= 6 else 1.0
    up = _spec_vec3(fields[6], "area light up") if len(fields) == 7 else None
    return AreaLight(position, normal, shape, tuple(x * scale for x in size), power, up=up)


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
        env:FILE[:strength[:rotation_deg[:up]]] an equirectangular HDR map (EXR, HDR: anything OpenImageIO reads),
                                                radiance W/(mm^2 sr) per unit strength (default 1), rotated by
                                                rotation_deg (default 0) about the up axis, y (default: glTF, OBJ)
                                                or z (Blender's world); meshshade.light.environment
        uniform[:radiance]                      the same radiance W/(mm^2 sr) from every direction (default 1)
        area:x,y,z:nx,ny,nz:rect:w,h[:power[:ux,uy,uz]]
        area:x,y,z:nx,ny,nz:disc:r[,r2][:power[:ux,uy,uz]]
                                                a one-sided Lambertian emitter of power W (default 1) centred at
                                                x,y,z facing nx,ny,nz: a w x h rectangle (mesh units), its height
                                                along up (default +Y, +Z for a normal along +-Y), or a disc of
                                                radius r (an ellipse with r2 along up)

    Raises
    ------
    LightError
        One line naming the problem: unknown type, wrong number of fields, a vector that is not 3 finite
        numbers, a zero direction, a negative or non-finite power/irradiance/intensity/radiance; an environment
        map that is missing, unreadable, not 2:1, or holds negative or non-finite values.
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
        raise LightError(f"unknown light type {fields[0]!r} in {spec!r} (expected "
                         f"{', '.join(LIGHT_KINDS[:-1])} or {LIGHT_KINDS[-1]})")
    try:
        if kind == "env":
            return _env_spec(spec.strip().split(":", 1)[1] if ":" in spec else "", spec)
        if kind == "uniform":
            if len(fields) > 2:
                raise LightError(f"light spec {spec!r} must look like {_SPEC_SYNTAX['uniform']}")
            return EnvironmentLight.uniform(_spec_scalar(fields[1], "uniform radiance") if len(fields) == 2 else 1.0)
        if kind == "area":
            return _area_spec(fields, spec, scale)
    except LightError as exc:
        text = str(exc)
        raise LightError(text if text.startswith(("light spec", "environment map")) else
                         f"light spec {spec!r}: {text}") from None
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
