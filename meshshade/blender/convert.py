"""Blender's lengths and lights in meshshade's units: pure functions of numbers (no ``bpy``), so every conversion
the add-on makes is tested without Blender.

Lengths
    A Blender unit is ``scene.unit_settings.scale_length`` metres (Blender's convention under every unit system,
    "None" included), so ``mm_per_unit = 1000 * scale_length``. Vertices are taken in world space (the object's
    ``matrix_world`` applied) and converted once (:func:`world_vertices_mm`). A mirroring transform (negative
    determinant) turns the winding inside out; the faces are flipped back so normals still point outwards.

Sun
    Blender's sun *strength* is the irradiance in W/m² on a surface facing it: W/mm² = strength × 1e-6
    (:func:`sun_irradiance`). It shines along the lamp's local −Z axis (:func:`light_direction`).

Point
    A point light of *power* P W is an isotropic source of radiant intensity I = P / (4π) W/sr
    (:func:`point_intensity`): the power spread evenly over the sphere of directions, which is how Cycles emits
    it. Its radius (soft shadows) is ignored: meshshade's point lights are points.

Spot
    Blender gives a spot the intensity of a point light of the same power inside its cone (``spot_size`` is the
    full cone angle, ``spot_blend`` softens the edge): I = P / (4π) W/sr along the axis, times Cycles' smoothstep
    falloff towards the edge (:meth:`meshshade.light.sources.Spot.falloff`; meshshade's
    :class:`~meshshade.light.sources.PointLight` with a ``spot`` cone).

Colour
    The exitance is linear in each light's strength, per channel, so a light's colour multiplies its share of the
    result channel by channel. Lights of one colour are baked together; each further colour is one more bake
    (:func:`colour_groups`).

Area lights and the world (environment) light have no counterpart in meshshade; they are left out with a note.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from meshshade.errors import LightError, UnitsError
from meshshade.light.sources import DirectionalLight, PointLight, Spot

__all__ = ["BlenderLight", "mm_per_blender_unit", "world_vertices_mm", "world_faces", "light_direction",
           "sun_irradiance", "point_intensity", "convert_lights", "colour_groups"]

#: W/mm² per W/m²
W_PER_MM2_PER_W_PER_M2 = 1e-6
#: mm per metre
MM_PER_METRE = 1000.0


def mm_per_blender_unit(scale_length: float) -> float:
    """Millimetres per Blender unit for the scene's ``unit_settings.scale_length`` (metres per unit)."""
    s = float(scale_length)
    if not (math.isfinite(s) and s > 0.0):
        raise UnitsError(f"the scene's unit scale must be a positive number of metres per unit, got {scale_length!r}")
    return MM_PER_METRE * s


def _matrix(matrix) -> np.ndarray:
    M = np.asarray(matrix, dtype=np.float64)
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise UnitsError(f"a world matrix must be a finite 4x4 array, got shape {M.shape}")
    return M


def world_vertices_mm(local, matrix, mm_per_unit: float) -> np.ndarray:
    """(n, 3) float64 mm: ``local`` vertex positions (Blender units, object space) through the 4x4 world
    ``matrix``, times ``mm_per_unit``."""
    M = _matrix(matrix)
    V = np.asarray(local, dtype=np.float64).reshape(-1, 3)
    return (V @ M[:3, :3].T + M[:3, 3]) * float(mm_per_unit)


def world_faces(faces, matrix) -> np.ndarray:
    """(m, 3) int64 faces, their winding flipped when the world ``matrix`` mirrors (negative determinant)."""
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    return F[:, [0, 2, 1]] if np.linalg.det(_matrix(matrix)[:3, :3]) < 0.0 else F


def light_direction(matrix) -> np.ndarray:
    """(3,) unit vector: the lamp's local −Z axis in world space (where a sun or spot points)."""
    d = -_matrix(matrix)[:3, 2]
    n = np.linalg.norm(d)
    if not n > 0.0:
        raise LightError("a light's world matrix has a zero Z axis (scaled to nothing)")
    return d / n


def sun_irradiance(strength_w_per_m2: float) -> float:
    """W/mm² of a Blender sun of ``strength`` W/m²."""
    return float(strength_w_per_m2) * W_PER_MM2_PER_W_PER_M2


def point_intensity(power_w: float) -> float:
    """W/sr of an isotropic point (or the axis of a spot) light of ``power`` W: P / (4π)."""
    return float(power_w) / (4.0 * math.pi)


@dataclass
class BlenderLight:
    """What the add-on reads from one light object: ``kind`` is Blender's light type ("SUN", "POINT", "SPOT",
    "AREA"), ``energy`` its strength (W/m² for a sun, W otherwise), ``matrix`` its (4, 4) world matrix."""

    name: str
    kind: str
    energy: float
    color: tuple = (1.0, 1.0, 1.0)
    matrix: np.ndarray = field(default_factory=lambda: np.eye(4))
    spot_size: float = math.pi
    spot_blend: float = 0.0


def convert_lights(lights, mm_per_unit: float) -> tuple[list, list[str]]:
    """``([(meshshade light, (3,) colour), ...], notes)`` for the scene's ``lights`` (:class:`BlenderLight`).

    Area lights, lights of zero strength or black colour are left out with a note each. No light left:
    :class:`~meshshade.errors.LightError` (one line, naming what was found).
    """
    out, notes = [], []
    for lt in lights:
        colour = np.asarray(lt.color, dtype=np.float64).reshape(3)
        what = f"{lt.kind.lower()} light {lt.name!r}"
        if lt.kind not in ("SUN", "POINT", "SPOT"):
            notes.append(f"{what} left out: meshshade has sun, point and spot lights only")
            continue
        if not (math.isfinite(lt.energy) and lt.energy >= 0.0) or not np.all(np.isfinite(colour) & (colour >= 0)):
            raise LightError(f"{what}: strength {lt.energy!r} and colour {tuple(colour)} must be finite and >= 0")
        if lt.energy == 0.0 or not np.any(colour > 0.0):
            notes.append(f"{what} left out: its strength or colour is zero")
            continue
        M = _matrix(lt.matrix)
        if lt.kind == "SUN":
            light = DirectionalLight(tuple(light_direction(M)), sun_irradiance(lt.energy))
        else:
            spot = (Spot(tuple(light_direction(M)), float(lt.spot_size), float(lt.spot_blend))
                    if lt.kind == "SPOT" else None)
            light = PointLight(tuple(M[:3, 3] * float(mm_per_unit)), point_intensity(lt.energy), spot=spot)
        out.append((light, colour))
    if not out:
        found = ", ".join(f"{lt.kind.lower()} {lt.name!r}" for lt in lights) or "none"
        raise LightError(f"no sun, point or spot light with a strength above zero in the scene (found: {found})")
    return out, notes


def colour_groups(converted) -> list[tuple[np.ndarray, list]]:
    """``[(colour, [lights of that colour]), ...]`` in order of first appearance: the bakes to run, each
    weighted by its colour (the exitance is linear in every light, channel by channel)."""
    groups: list[tuple[np.ndarray, list]] = []
    for light, colour in converted:
        for c, members in groups:
            if np.array_equal(c, colour):
                members.append(light)
                break
        else:
            groups.append((np.asarray(colour, dtype=np.float64), [light]))
    return groups
