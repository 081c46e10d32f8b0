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

Area
    A Blender area light of *power* P W is a one-sided Lambertian emitter (Cycles: radiance P / (pi A) towards every
    direction in front of it, the default *spread* of 180 degrees) facing its local −Z, of size ``size`` along its
    local X and ``size_y`` along Y (SQUARE: size x size; DISK: diameter size; ELLIPSE: diameters size and size_y),
    the object's scale applied: meshshade's :class:`~meshshade.light.sources.AreaLight` with the local Y axis as its
    ``up`` (:func:`area_light`). A spread below 180 degrees (a narrower beam) is not modelled: noted.

Material (a slot's Principled BSDF)
    Cycles' subsurface takes a per-channel *Subsurface Radius* times a *Subsurface Scale* (a length in scene units)
    and the *Base Color*. meshshade reads them as the medium's transport mean free path and its painted colour
    (docs/physics.md §17): 1/sigma_t' = radius x scale x mm per unit, the base colour the diffuse reflectance the
    medium must have, inverted per channel into the reduced albedo with the model's own total reflectance
    (:func:`meshshade.kernels.painted_reflectance.albedo_for_reflectance`) at the slot's *IOR* as eta
    (:func:`principled_medium`). A Base Color fed by an Image Texture is a colour map over the UVs
    (``--albedo-map``); its medium's own albedo is then the map's, per point. An Image Texture feeding the Radius
    or the Scale is a radius map (``--radius-map``, eq. (132)): its values take the place of that socket's. A
    Subsurface Weight of 0 is an opaque slot (refused); a weight below 1 is noted (meshshade bakes the subsurface
    part alone).

World
    The World's Background shader emits radiance ``strength x colour`` W/(m² sr) from every direction. Fed by an
    Environment Texture (equirectangular), that is the image's pixel values times the strength: meshshade's
    :class:`~meshshade.light.sources.EnvironmentLight` of the same file, strength × 1e-6 (W/(mm² sr) per W/(m² sr)),
    ``up = "z"`` (the add-on passes Blender's world coordinates), rotated by the Mapping node's Z rotation (type
    Point; type Texture rotates the other way: :func:`convert_world`). A constant colour is a ``uniform`` light of
    that colour. Other setups (a Sky Texture, a mirror-ball projection, rotations about X or Y) are left out with a
    note.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from meshshade.errors import LightError, MaterialError, UnitsError
from meshshade.kernels.painted_reflectance import albedo_for_reflectance
from meshshade.light.sources import AreaLight, DirectionalLight, EnvironmentLight, PointLight, Spot
from meshshade.light.spec import parse_light_spec

__all__ = ["BlenderLight", "BlenderWorld", "mm_per_blender_unit", "world_vertices_mm", "world_faces",
           "light_direction", "sun_irradiance", "point_intensity", "area_light", "convert_world", "convert_lights",
           "colour_groups", "RADIANCE_PER_W_PER_M2_SR", "PrincipledSlot", "principled_medium"]

#: W/mm² per W/m²
W_PER_MM2_PER_W_PER_M2 = 1e-6
#: mm per metre
MM_PER_METRE = 1000.0
#: W/(mm² sr) per W/(m² sr)
RADIANCE_PER_W_PER_M2_SR = 1e-6


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
    shape: str = "SQUARE"
    size: float = 1.0
    size_y: float = 1.0
    spread: float = math.pi


@dataclass
class BlenderWorld:
    """What the add-on reads from the scene's World: the Background's ``strength`` and ``color``; ``image`` the
    absolute path of the Environment Texture feeding its colour (None: a constant colour; ``""``: a texture whose
    image has no file, e.g. packed into the .blend), its ``projection``; the Mapping node before it (``mapping``
    its type, "POINT", "TEXTURE", ... or None without one; ``rotation`` radians XYZ, ``location``, ``scale``);
    ``other``: a description of anything else feeding the Background (a Sky Texture ...), or None."""

    strength: float = 1.0
    color: tuple = (0.05, 0.05, 0.05)
    image: str | None = None
    projection: str = "EQUIRECTANGULAR"
    mapping: str | None = None
    rotation: tuple = (0.0, 0.0, 0.0)
    location: tuple = (0.0, 0.0, 0.0)
    scale: tuple = (1.0, 1.0, 1.0)
    other: str | None = None


def area_light(lt: BlenderLight, mm_per_unit: float) -> AreaLight:
    """The :class:`~meshshade.light.sources.AreaLight` of a Blender area light (module docstring): centre, −Z
    normal and local Y ``up`` from its world matrix, sizes in mm with the object's scale, power in W."""
    M = _matrix(lt.matrix)
    sx, sy = (float(np.linalg.norm(M[:3, k])) * float(mm_per_unit) for k in (0, 1))
    shape = lt.shape.upper()
    a = float(lt.size) * sx
    b = (float(lt.size_y) if shape in ("RECTANGLE", "ELLIPSE") else float(lt.size)) * sy
    up = M[:3, 1] / max(float(np.linalg.norm(M[:3, 1])), 1e-300)
    if shape in ("DISK", "ELLIPSE"):
        return AreaLight(tuple(M[:3, 3] * float(mm_per_unit)), tuple(light_direction(M)), "disc", (a / 2, b / 2),
                         float(lt.energy), up=tuple(up))
    return AreaLight(tuple(M[:3, 3] * float(mm_per_unit)), tuple(light_direction(M)), "rect", (a, b),
                     float(lt.energy), up=tuple(up))


def convert_world(world: BlenderWorld | None) -> tuple[list, list[str]]:
    """``([(light, colour)] or [], notes)``: the World as an environment light (module docstring).

    An Environment Texture gives ``env:<image>:<strength x 1e-6>:<rotation deg>:z`` (the map is read, and checked,
    here: a bad file is a :class:`~meshshade.errors.LightError`); a constant colour a ``uniform`` light of that
    colour; a zero strength, a black colour or an unsupported setup nothing, with a note."""
    if world is None:
        return [], []
    strength = float(world.strength)
    if not (math.isfinite(strength) and strength >= 0.0):
        raise LightError(f"the World's strength {world.strength!r} must be finite and >= 0")
    colour = np.asarray(world.color, dtype=np.float64).reshape(3)
    if world.other is not None:
        return [], [f"the World left out: {world.other} has no counterpart in meshshade (an Environment Texture "
                    "or a constant colour into the Background has)"]
    if strength == 0.0:
        return [], ["the World left out: its strength is zero"]
    if world.image is None:
        if not (np.all(np.isfinite(colour)) and np.all(colour >= 0.0)) or not np.any(colour > 0.0):
            return [], ["the World left out: its colour is black"]
        return [(EnvironmentLight.uniform(strength * RADIANCE_PER_W_PER_M2_SR), colour)], []
    if not world.image:
        return [], ["the World left out: its Environment Texture's image has no file (packed into the .blend? "
                    "unpack it: File > External Data > Unpack Resources)"]
    if world.projection.upper() != "EQUIRECTANGULAR":
        return [], [f"the World left out: its Environment Texture's projection is {world.projection}, meshshade "
                    "reads equirectangular maps"]
    notes = []
    rx, ry, rz = (float(x) for x in world.rotation)
    rotation = 0.0
    if world.mapping is not None:
        if world.mapping.upper() not in ("POINT", "TEXTURE"):
            notes.append(f"the World's Mapping node of type {world.mapping} is ignored (Point and Texture are read)")
        else:
            rotation = math.degrees(rz) if world.mapping.upper() == "POINT" else -math.degrees(rz)
            if abs(rx) > 1e-9 or abs(ry) > 1e-9:
                notes.append("the World's Mapping rotation about X and Y is ignored (only Z, about the up axis, is "
                             "read)")
            if any(abs(x) > 1e-9 for x in world.location) or any(abs(x - 1.0) > 1e-9 for x in world.scale):
                notes.append("the World's Mapping location and scale are ignored (they do not move a direction's "
                             "lookup as a rotation does)")
    spec = f"env:{world.image}:{strength * RADIANCE_PER_W_PER_M2_SR!r}:{rotation!r}:z"
    return [(parse_light_spec(spec), np.ones(3))], notes


def convert_lights(lights, mm_per_unit: float, world: BlenderWorld | None = None) -> tuple[list, list[str]]:
    """``([(meshshade light, (3,) colour), ...], notes)`` for the scene's ``lights`` (:class:`BlenderLight`) and its
    ``world`` (:func:`convert_world`).

    Lights of zero strength or black colour, and setups meshshade cannot read, are left out with a note each. No
    light left: :class:`~meshshade.errors.LightError` (one line, naming what was found).
    """
    out, notes = [], []
    for lt in lights:
        colour = np.asarray(lt.color, dtype=np.float64).reshape(3)
        what = f"{lt.kind.lower()} light {lt.name!r}"
        if lt.kind not in ("SUN", "POINT", "SPOT", "AREA"):
            notes.append(f"{what} left out: meshshade has sun, point, spot and area lights only")
            continue
        if not (math.isfinite(lt.energy) and lt.energy >= 0.0) or not np.all(np.isfinite(colour) & (colour >= 0)):
            raise LightError(f"{what}: strength {lt.energy!r} and colour {tuple(colour)} must be finite and >= 0")
        if lt.energy == 0.0 or not np.any(colour > 0.0):
            notes.append(f"{what} left out: its strength or colour is zero")
            continue
        M = _matrix(lt.matrix)
        if lt.kind == "AREA":
            if float(lt.spread) < math.pi - 1e-6:
                notes.append(f"{what}: its spread ({math.degrees(lt.spread):.3g} deg) is taken as 180 (Lambertian)")
            out.append((area_light(lt, mm_per_unit), colour))
            continue
        if lt.kind == "SUN":
            light = DirectionalLight(tuple(light_direction(M)), sun_irradiance(lt.energy))
        else:
            spot = (Spot(tuple(light_direction(M)), float(lt.spot_size), float(lt.spot_blend))
                    if lt.kind == "SPOT" else None)
            light = PointLight(tuple(M[:3, 3] * float(mm_per_unit)), point_intensity(lt.energy), spot=spot)
        out.append((light, colour))
    sky, sky_notes = convert_world(world)
    out += sky
    notes += sky_notes
    if not out:
        found = ", ".join(f"{lt.kind.lower()} {lt.name!r}" for lt in lights) or "none"
        raise LightError(f"no sun, point, spot or area light with a strength above zero and no World to light the "
                         f"scene (found: {found})")
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


@dataclass
class PrincipledSlot:
    """A material slot's Principled BSDF as the add-on reads it: ``name`` (the material's), ``base_colour`` (3,)
    linear RGB (None when an image feeds it), ``image`` (the Image Texture's file, absolute, or None), ``radius``
    (3,) Subsurface Radius, ``scale`` Subsurface Scale (scene units), ``ior`` and ``weight`` (Subsurface Weight);
    ``radius_image`` / ``scale_image``: an Image Texture feeding the radius or the scale (a radius map, eq. (132))."""

    name: str
    base_colour: tuple | None
    image: str | None
    radius: tuple
    scale: float
    ior: float
    weight: float = 1.0
    #: an Image Texture's file feeding Subsurface Radius, or Subsurface Scale (absolute), or None
    radius_image: str | None = None
    scale_image: str | None = None
    #: whether that image's colour space is data (Non-Color, or linear): read as its values, as Blender does
    radius_image_is_data: bool = True


def principled_medium(slot: PrincipledSlot, mm_per_unit: float) -> tuple[dict, list[str]]:
    """(medium, notes): ``slot``'s medium in meshshade's terms (module docstring, "Material"): ``sigma_s_prime`` and
    ``sigma_a`` (3,) 1/mm, ``eta``, ``albedo_map`` (the image's path, or None) and ``radius_map`` (the image
    feeding the radius or the scale, or None). With an image the painted colour sets the albedo per point and only
    sigma_t' = sigma_s' + sigma_a matters: the base is given the albedo 1/2. With a radius map the image's value
    takes the place of the socket it feeds (Blender ignores a linked socket's own value): Radius from an image,
    1/sigma_t' = image x Scale x mm per unit, the base at a radius of 1; Scale from an image, 1/sigma_t' = Radius x
    image x mm per unit, the base at a scale of 1 (read per channel: a grey mask is its value, as Blender's
    luminance of a grey image is).
    MaterialError (naming the slot) for an opaque slot, a radius x scale that is not positive and finite, a colour
    no medium of that index reflects, or both the radius and the scale from images."""
    where = f"material {slot.name!r}"
    if not slot.weight > 0.0:
        raise MaterialError(f"{where}: Subsurface Weight is 0 (an opaque material): nothing to bake; raise it or "
                            "choose a preset")
    if slot.radius_image and slot.scale_image:
        raise MaterialError(f"{where}: both Subsurface Radius and Subsurface Scale come from images; meshshade reads "
                            "one radius map (feed one of them, or multiply the two into one image)")
    radius = np.ones(3) if slot.radius_image else np.asarray(slot.radius, dtype=np.float64)
    scale = 1.0 if slot.scale_image else float(slot.scale)
    ell = radius * scale * float(mm_per_unit)
    if ell.shape != (3,) or not np.all(np.isfinite(ell) & (ell > 0.0)):
        raise MaterialError(f"{where}: Subsurface Radius x Scale must be positive in every channel, got "
                            f"{np.round(ell, 6).tolist()} mm")
    eta = float(slot.ior)
    notes = []
    if slot.weight < 1.0:
        notes.append(f"{where}: Subsurface Weight {slot.weight:g}: meshshade bakes the subsurface part alone")
    radius_map = slot.radius_image or slot.scale_image
    if radius_map and not slot.radius_image_is_data:
        notes.append(f"{where}: the Subsurface {'Radius' if slot.radius_image else 'Scale'} image is read as data "
                     "(its values); set its colour space to Non-Color for Cycles to read the same")
    if slot.image is not None:
        albedo = np.full(3, 0.5)
    else:
        colour = np.asarray(slot.base_colour, dtype=np.float64)[:3]
        try:
            albedo = albedo_for_reflectance(colour, eta)
        except MaterialError as e:
            raise MaterialError(f"{where}: Base Color {np.round(colour, 4).tolist()}: {e}") from None
    st = 1.0 / ell
    return {"sigma_s_prime": tuple(float(x) for x in albedo * st),
            "sigma_a": tuple(float(x) for x in (1.0 - albedo) * st), "eta": eta, "albedo_map": slot.image,
            "radius_map": radius_map}, notes
