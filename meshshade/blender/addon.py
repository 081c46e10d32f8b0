"""The Blender side of the add-on: settings, the operator ``object.meshshade_bake``, the panel, preferences.

Imported only inside Blender (it needs ``bpy``); everything it computes goes through
:mod:`meshshade.blender.convert` (units and lights) and :mod:`meshshade.blender.job` (the bake in a child
process). What it reads from the scene: the active mesh object (its base mesh, triangulated, with its world
transform), the scene's unit scale, every sun, point, spot and area light that renders, and the World (an
Environment Texture or a constant colour into its Background: :func:`scene_world`). What it writes: the float
colour attribute :data:`RADIANCE_ATTRIBUTE` (linear exitance, W/mm²) and the byte colour attribute
:data:`DISPLAY_ATTRIBUTE` (tone-mapped, made the active and render colour), optionally a material
:data:`MATERIAL_NAME` that shows the exitance. With "Bake to texture", also a float image ``meshshade <object>``
of the active UV map (:func:`apply_texture`: the CLI's ``--texture``, linear W/mm², alpha the coverage), shown by
the material through an Image Texture node instead of the attribute.
"""
from __future__ import annotations

import math
import sys
import traceback
from dataclasses import replace
from pathlib import Path

import bpy
import numpy as np
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, PointerProperty,
                       StringProperty)

from meshshade.blender.convert import (BlenderLight, BlenderWorld, PrincipledSlot, colour_groups, convert_lights,
                                       mm_per_blender_unit, principled_medium, world_faces, world_vertices_mm)
from meshshade.blender.job import BakeJob, BakeSettings
from meshshade import io
from meshshade.errors import MeshshadeError
from meshshade.materials import PRESETS
from meshshade.output.tonemap import tonemap_linear
from meshshade.names import DEFAULT_MODEL, MODELS

#: the float colour attribute holding the linear exitance (W/mm², per vertex, alpha 1)
RADIANCE_ATTRIBUTE = "meshshade_radiance"
#: the byte colour attribute holding the tone-mapped display colour
DISPLAY_ATTRIBUTE = "meshshade_display"
#: the material that shows the exitance (Attribute -> Emission)
MATERIAL_NAME = "meshshade radiance"
#: emission strength per W/mm² of exitance: Cycles renders an emission of strength E and colour c as radiance E c
#: (W/(m² sr)) and a white Lambertian surface under a sun of strength S W/m² as S/π, so light leaving with
#: exitance M W/mm² (diffusely) shows as M 1e6/π, on the same scale as Blender's own lights (tested with a render)
EMISSION_PER_W_PER_MM2 = 1e6 / math.pi
#: the log (in the temporary directory) of the child bakes' output and of unexpected failures
LOG_NAME = "meshshade-blender.log"
#: seconds between two looks at a running bake
POLL_SECONDS = 0.2

_MODEL_ITEMS = [("volume", "volume", "diffusion inside the object's volume with the analytic near field on top "
                   "(recommended; open and many-part meshes included, a flat sheet uses auto)"),
                ("auto", "auto", "surface kernels: meshshade chooses per entry sample the planar dipole, curvature "
                 "kernel, exact sphere or fitted model where each is needed")] + [
    (m, m, {"dipole": "planar dipole (Jensen et al. 2001): flat half-space everywhere",
            "curved": "first-order correction in the principal curvatures k1, k2",
            "exact-sphere": "exact diffusion solution of the sphere of the local mean curvature",
            "fitted": "curvature model fitted to Monte Carlo beyond first order"}.get(m, m))
    for m in MODELS if m not in ("auto", "volume")]
_PRESET_ITEMS = [("MATERIAL", "From the object's material",
                  "the Principled BSDF of the object's material: Subsurface Radius x Scale as the mean free path, the "
                  "Base Color (a colour or an Image Texture) as the diffuse reflectance (docs/blender.md)"),
                 ("CUSTOM", "Custom coefficients", "sigma_s' and sigma_a in 1/mm")] + [
    (name, name, f"{source}: sigma_s' {', '.join(f'{x:g}' for x in s)} /mm, sigma_a "
                 f"{', '.join(f'{x:g}' for x in a)} /mm, eta {eta:g}")
    for name, (s, a, eta, source) in PRESETS.items()]


class _BakeProperties:
    """The bake's settings: the panel shows them (per object), the operator takes them as its properties."""

    material: EnumProperty(name="Material", items=_PRESET_ITEMS, default="skin1",
                           description="measured medium (Jensen et al. 2001, Narasimhan et al. 2006) or coefficients")
    sigma_s_prime: FloatVectorProperty(name="Reduced scattering σs' (1/mm)", size=3, min=0.0, soft_max=100.0,
                                       default=(1.0, 1.0, 1.0), precision=4, subtype="NONE",
                                       description="reduced scattering coefficient per channel, in 1/mm")
    sigma_a: FloatVectorProperty(name="Absorption σa (1/mm)", size=3, min=0.0, soft_max=10.0,
                                 default=(0.01, 0.01, 0.01), precision=4, subtype="NONE",
                                 description="absorption coefficient per channel, in 1/mm")
    eta: FloatProperty(name="Index of refraction", default=1.3, min=1.0, max=2.5, precision=3,
                       description="relative index of refraction of the medium")
    model: EnumProperty(name="Model", items=_MODEL_ITEMS, default=DEFAULT_MODEL, description="transport model")
    cutoff_tol: FloatProperty(name="Cutoff tolerance", default=1e-4, min=1e-12, max=0.5, precision=6,
                              description="neighbourhood radius: reflectance beyond it below this fraction "
                                          "(smaller: more accurate, slower)")
    geodesic: EnumProperty(name="Geodesics", default="exact",
                           items=[("exact", "exact", "polyhedral window propagation (reference)"),
                                  ("arc", "arc", "curvature-corrected chords: about 5x faster, 1-11 % low on "
                                                 "bumpy scans")])
    transport: EnumProperty(name="Transport", default="auto",
                            items=[("auto", "auto", "surface models: hierarchical where its distance check "
                                                    "passes, else direct (the volume model has its own)"),
                                   ("hierarchical", "hierarchical", "near zone + source clusters (near-linear cost)"),
                                   ("direct", "direct", "every pair within the cutoff (reference)")])
    texture: BoolProperty(name="Bake to texture", default=False,
                          description="also bake into a float image of the active UV map (each texel a point on "
                                      "the surface: sharper than the vertices)")
    texture_size: IntProperty(name="Texture size", default=2048, min=8, max=16384,
                              description="texels per side of the baked image")
    albedo_clamp: BoolProperty(name="Clamp painted colours", default=True,
                               description="a Base Color image's texels that no medium reflects (pure white or "
                                           "black in a channel) are moved into the range the model reaches, with a "
                                           "note (off: such an image is an error)")
    make_material: BoolProperty(name="Assign display material", default=False,
                                description=f"create or update the material '{MATERIAL_NAME}' (Attribute "
                                            f"{RADIANCE_ATTRIBUTE} -> Emission) and make it the object's active one")

    def bake_settings(self) -> BakeSettings:
        custom = self.material in ("CUSTOM", "MATERIAL")   # MATERIAL: prepare() sets the medium from the slot
        return BakeSettings(preset=None if custom else self.material, sigma_s_prime=tuple(self.sigma_s_prime),
                            sigma_a=tuple(self.sigma_a), eta=float(self.eta), model=self.model,
                            cutoff_tol=float(self.cutoff_tol), geodesic=self.geodesic, transport=self.transport,
                            albedo_clamp=bool(self.albedo_clamp))


_SETTING_NAMES = ("material", "sigma_s_prime", "sigma_a", "eta", "albedo_clamp", "model", "cutoff_tol", "geodesic",
                  "transport", "texture", "texture_size", "make_material")


class MESHSHADE_PG_settings(_BakeProperties, bpy.types.PropertyGroup):
    """Per-object bake settings (``object.meshshade``)."""


class MESHSHADE_AP_preferences(bpy.types.AddonPreferences):
    bl_idname = "meshshade.blender"   # replaced by the enabled module's name in register()

    python: StringProperty(name="Python for bakes", subtype="FILE_PATH", default="",
                           description="interpreter with meshshade installed that runs the bakes (empty: "
                                       "Blender's own Python)")

    def draw(self, context):
        self.layout.prop(self, "python")
        self.layout.label(text=f"Empty: {sys.executable}")


# ------------------------------------------------------------------------------------------------ scene reading
def _preferences(context):
    addon = context.preferences.addons.get(MESHSHADE_AP_preferences.bl_idname)
    return addon.preferences if addon is not None else None


def bake_python(context) -> str:
    """The interpreter that runs bakes: the add-on preference, else Blender's own."""
    prefs = _preferences(context)
    path = bpy.path.abspath(prefs.python) if prefs is not None and prefs.python.strip() else ""
    return path or sys.executable


def scene_lights(context) -> list[BlenderLight]:
    """Every light object of the view layer that renders, as :class:`BlenderLight` (world matrix, strength
    times 2^exposure where Blender has light exposure)."""
    out = []
    for ob in context.view_layer.objects:
        if ob.type != "LIGHT" or ob.hide_render:
            continue
        lt = ob.data
        energy = float(lt.energy) * 2.0 ** float(getattr(lt, "exposure", 0.0))
        out.append(BlenderLight(name=ob.name, kind=lt.type, energy=energy, color=tuple(lt.color),
                                matrix=np.array(ob.matrix_world, dtype=np.float64),
                                spot_size=float(getattr(lt, "spot_size", math.pi)),
                                spot_blend=float(getattr(lt, "spot_blend", 0.0)),
                                shape=str(getattr(lt, "shape", "SQUARE")), size=float(getattr(lt, "size", 1.0)),
                                size_y=float(getattr(lt, "size_y", 1.0)), spread=float(getattr(lt, "spread", math.pi))))
    return out


def _linked(socket):
    """The node feeding ``socket`` (None when unlinked)."""
    return socket.links[0].from_node if socket.is_linked else None


def scene_world(context) -> BlenderWorld | None:
    """The scene's World as :class:`BlenderWorld`: its Background's strength and colour and, when an Environment
    Texture feeds the colour, the image's absolute path, projection and the Mapping node before it; None without a
    World or a node tree with a Background into the World Output."""
    world = context.scene.world
    if world is None or not getattr(world, "use_nodes", True) or world.node_tree is None:   # 5.0: always nodes
        return None
    nodes = world.node_tree.nodes
    out = next((n for n in nodes if n.type == "OUTPUT_WORLD" and n.is_active_output), None) or \
        next((n for n in nodes if n.type == "OUTPUT_WORLD"), None)
    bg = _linked(out.inputs["Surface"]) if out is not None else None
    if bg is None:
        return None
    if bg.type != "BACKGROUND":
        return BlenderWorld(other=f"a {bg.bl_label} node into the World Output")
    strength_in, colour_in = bg.inputs["Strength"], bg.inputs["Color"]
    strength = float(strength_in.default_value)
    if strength_in.is_linked:
        return BlenderWorld(other="a node feeding the Background's strength")
    tex = _linked(colour_in)
    if tex is None:
        return BlenderWorld(strength=strength, color=tuple(colour_in.default_value)[:3])
    if tex.type != "TEX_ENVIRONMENT":
        return BlenderWorld(strength=strength, other=f"a {tex.bl_label} node into the Background's colour")
    image = tex.image
    path = "" if image is None or image.packed_file is not None or not image.filepath else \
        bpy.path.abspath(image.filepath, library=image.library)
    mapping = _linked(tex.inputs["Vector"])
    if mapping is not None and mapping.type != "MAPPING":
        return BlenderWorld(strength=strength, other=f"a {mapping.bl_label} node into the texture's vector")
    kw = {}
    if mapping is not None:
        kw = {"mapping": mapping.vector_type, "rotation": tuple(mapping.inputs["Rotation"].default_value),
              "location": tuple(mapping.inputs["Location"].default_value)
              if "Location" in mapping.inputs else (0.0, 0.0, 0.0),
              "scale": tuple(mapping.inputs["Scale"].default_value) if "Scale" in mapping.inputs else (1.0, 1.0, 1.0)}
    return BlenderWorld(strength=strength, image=path, projection=tex.projection, **kw)


def mesh_arrays(ob) -> tuple[np.ndarray, np.ndarray]:
    """(local vertex positions (n, 3) float64, triangles (m, 3) int64) of ``ob``'s base mesh."""
    me = ob.data
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    me.calc_loop_triangles()
    tris = np.empty(len(me.loop_triangles) * 3, dtype=np.int32)
    me.loop_triangles.foreach_get("vertices", tris)
    return co.reshape(-1, 3).astype(np.float64), tris.reshape(-1, 3).astype(np.int64)


def corner_uv(ob) -> np.ndarray:
    """(m, 3, 2) UVs of the active UV map at the corners of ``ob``'s loop triangles (as :func:`mesh_arrays`)."""
    me = ob.data
    layer = me.uv_layers.active
    if layer is None:
        raise MeshshadeError(f"{ob.name}: the mesh has no UV map to bake a texture into (add one: UV > Unwrap)")
    uv = np.empty(len(me.loops) * 2, dtype=np.float32)
    layer.data.foreach_get("uv", uv)
    me.calc_loop_triangles()
    loops = np.empty(len(me.loop_triangles) * 3, dtype=np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    return uv.reshape(-1, 2).astype(np.float64)[loops].reshape(-1, 3, 2)


def _input(node, *names):
    for name in names:
        inp = node.inputs.get(name)
        if inp is not None:
            return inp
    return None


def principled_slot(mat) -> PrincipledSlot:
    """The Principled BSDF of material ``mat`` (the one feeding its output's Surface, else the first) as a
    :class:`~meshshade.blender.convert.PrincipledSlot`; MeshshadeError (naming the material) where it has none, or
    a Base Color fed by anything but an Image Texture of a file."""
    if mat is None:
        raise MeshshadeError("an empty material slot: give every slot a material with a Principled BSDF")
    nodes = mat.node_tree.nodes if getattr(mat, "node_tree", None) else []
    bsdfs = [n for n in nodes if n.type == "BSDF_PRINCIPLED"]
    outs = [n for n in nodes if n.type == "OUTPUT_MATERIAL" and n.inputs["Surface"].is_linked]
    fed = [ln.from_node for o in outs for ln in o.inputs["Surface"].links if ln.from_node.type == "BSDF_PRINCIPLED"]
    node = (fed or bsdfs or [None])[0]
    if node is None:
        raise MeshshadeError(f"material {mat.name!r}: no Principled BSDF to read the medium from (use one, or pick "
                             "a preset)")
    base = node.inputs["Base Color"]
    colour, image = None, None
    if base.is_linked:
        image, _ = _image_file(mat, base, "Base Color", "a constant colour")
    else:
        colour = tuple(float(x) for x in base.default_value[:3])
    radius_in = node.inputs["Subsurface Radius"]
    radius = tuple(float(x) for x in radius_in.default_value[:3])
    scale_in = _input(node, "Subsurface Scale")
    weight_in = _input(node, "Subsurface Weight", "Subsurface")
    radius_image = scale_image = None
    is_data = True
    if radius_in.is_linked:
        radius_image, is_data = _image_file(mat, radius_in, "Subsurface Radius", "a constant radius")
    if scale_in is not None and scale_in.is_linked:
        scale_image, is_data = _image_file(mat, scale_in, "Subsurface Scale", "a constant scale")
    return PrincipledSlot(mat.name, colour, image, radius, float(scale_in.default_value) if scale_in else 1.0,
                          float(_input(node, "IOR").default_value),
                          float(weight_in.default_value) if weight_in else 1.0, radius_image=radius_image,
                          scale_image=scale_image, radius_image_is_data=is_data)


def _image_file(mat, socket, what: str, instead: str) -> tuple[str, bool]:
    """(the absolute file, whether its colour space is data) of the Image Texture feeding ``socket``; a
    MeshshadeError naming the material for any other node or an image that is not a file on disk."""
    src = socket.links[0].from_node
    if src.type != "TEX_IMAGE" or src.image is None:
        raise MeshshadeError(f"material {mat.name!r}: its {what} comes from a {src.type} node; meshshade reads "
                             f"{instead} or an Image Texture")
    img = src.image
    path = bpy.path.abspath(img.filepath, library=img.library)
    if img.packed_file is not None or not path or not Path(path).is_file():
        raise MeshshadeError(f"material {mat.name!r}: the image {img.name!r} is not a file on disk (unpack or "
                             "save it)")
    space = str(getattr(getattr(img, "colorspace_settings", None), "name", "Non-Color"))
    return path, space in ("Non-Color", "Linear", "Linear Rec.709", "Linear CIE-XYZ D65", "Raw")


def material_settings(ob, settings: BakeSettings, mm_per_unit: float) -> tuple[BakeSettings, list[str], object]:
    """``(settings, notes, face_part)``: ``settings`` with the media of ``ob``'s materials (the add-on's "From the
    object's material"): the Principled BSDF of each slot its faces use (:func:`principled_slot`,
    :func:`meshshade.blender.convert.principled_medium`). One medium: the settings' material, ``face_part`` None.
    Several: the first slot's medium for its faces, the others' as parts (``settings.parts``, named ``slotK``;
    ``face_part`` (m,) per loop triangle, -1 for the first's), transported through as parts of different media
    (one index for all: a MeshshadeError otherwise, as for an image on one of several media)."""
    me = ob.data
    me.calc_loop_triangles()
    index = np.empty(len(me.loop_triangles), dtype=np.int32)
    me.loop_triangles.foreach_get("material_index", index)
    slots = [s.material for s in ob.material_slots]
    index = np.clip(index, 0, max(len(slots) - 1, 0))
    used = sorted(set(index.tolist())) if slots else []
    if not used:
        raise MeshshadeError(f"{ob.name}: no material to read the medium from (add one, or pick a preset)")
    media = [principled_medium(principled_slot(slots[k]), mm_per_unit) for k in used]
    notes = [n for _, more in media for n in more]
    medium = media[0][0]
    distinct = [k for k, (m, _) in zip(used, media) if m != medium]
    if not distinct:
        return replace(settings, preset=None, sigma_s_prime=medium["sigma_s_prime"], sigma_a=medium["sigma_a"],
                       eta=medium["eta"], albedo_map=medium["albedo_map"],
                       radius_map=medium["radius_map"]), notes, None
    names = [slots[k].name for k in used]
    if any(m["albedo_map"] or m["radius_map"] for m, _ in media):
        raise MeshshadeError(f"{ob.name}: its faces use {len(used)} materials of different media ({', '.join(names)})"
                             " and one is painted by an image; bake the painted one as an object of its own")
    if any(m["eta"] != medium["eta"] for m, _ in media):
        raise MeshshadeError(f"{ob.name}: its materials ({', '.join(names)}) have different IORs; parts of different "
                             "media need one IOR (their interfaces are index-matched)")
    parts, part_of_medium = [], {}
    slot_part = np.full(max(used) + 1, -1, dtype=np.int64)        # the first slot's medium: -1, the rest
    for k, (m, _) in zip(used[1:], media[1:]):
        if m == medium:
            continue
        key = (m["sigma_s_prime"], m["sigma_a"])
        if key not in part_of_medium:                             # slots of one medium: one part
            part_of_medium[key] = len(parts)
            parts.append((f"slot{k}", m["sigma_s_prime"], m["sigma_a"]))
        slot_part[k] = part_of_medium[key]
    face_part = slot_part[index]
    notes.append(f"{ob.name}: {len(parts) + 1} media from its materials ({', '.join(names)}), transported through "
                 "as parts")
    return replace(settings, preset=None, sigma_s_prime=medium["sigma_s_prime"], sigma_a=medium["sigma_a"],
                   eta=medium["eta"], albedo_map=None, parts=tuple(parts)), notes, face_part


def prepare(context, ob, settings, *, python: str | None = None) -> tuple[BakeJob, list[str]]:
    """The job for ``ob`` and notes to report (lights left out, modifiers ignored); MeshshadeError on bad
    input."""
    if ob is None or ob.type != "MESH":
        raise MeshshadeError("select a mesh object to bake")
    if ob.mode != "OBJECT":
        raise MeshshadeError(f"{ob.name}: switch to Object Mode to bake (the bake writes the mesh's attributes)")
    local, tris = mesh_arrays(ob)
    if tris.shape[0] == 0:
        raise MeshshadeError(f"{ob.name}: the mesh has no faces")
    mpu = mm_per_blender_unit(context.scene.unit_settings.scale_length)
    M = np.array(ob.matrix_world, dtype=np.float64)
    lights, notes = convert_lights(scene_lights(context), mpu, world=scene_world(context))
    mods = [m.name for m in ob.modifiers if m.show_render]
    if mods:
        notes.append(f"{ob.name}: baked on the base mesh; modifiers ({', '.join(mods)}) interpolate the result")
    bake_settings = settings.bake_settings()
    face_part = None
    if settings.material == "MATERIAL":
        bake_settings, more, face_part = material_settings(ob, bake_settings, mpu)
        notes += more
    uv = None
    if settings.texture or bake_settings.albedo_map or bake_settings.radius_map:
        uv = corner_uv(ob)
        if np.linalg.det(M[:3, :3]) < 0.0:   # world_faces flips the winding of a mirrored object: so its corners
            uv = uv[:, [0, 2, 1]]
    job = BakeJob(world_vertices_mm(local, M, mpu), world_faces(tris, M), colour_groups(lights),
                  bake_settings, python=python or bake_python(context),
                  log=io.temp_path(LOG_NAME), uv=uv,
                  texture_size=int(settings.texture_size) if settings.texture else None, face_part=face_part)
    job.object_name, job.n_vertices = ob.name, len(ob.data.vertices)
    return job, notes


# ------------------------------------------------------------------------------------------------ writing back
def _set_colour_attribute(me, name: str, kind: str, rgb: np.ndarray):
    old = me.color_attributes.get(name)
    if old is not None and (old.data_type != kind or old.domain != "POINT"):
        me.color_attributes.remove(old)
        old = None
    attr = old or me.color_attributes.new(name=name, type=kind, domain="POINT")
    rgba = np.ones((rgb.shape[0], 4), dtype=np.float32)
    rgba[:, :3] = rgb
    attr.data.foreach_set("color", rgba.ravel())
    return attr


def apply_result(ob, radiance: np.ndarray, *, make_material: bool = False) -> None:
    """Write ``radiance`` (n, 3) W/mm² into ``ob``'s mesh: :data:`RADIANCE_ATTRIBUTE` (linear) and
    :data:`DISPLAY_ATTRIBUTE` (Drago tone-mapped as the PLY's colours), the latter active and rendered."""
    me = ob.data
    if len(me.vertices) != radiance.shape[0]:
        raise MeshshadeError(f"{ob.name} has {len(me.vertices)} vertices now, {radiance.shape[0]} when the bake "
                             f"started: the mesh changed during the bake; bake again")
    _set_colour_attribute(me, RADIANCE_ATTRIBUTE, "FLOAT_COLOR", radiance)
    _set_colour_attribute(me, DISPLAY_ATTRIBUTE, "BYTE_COLOR", tonemap_linear(radiance, operator="drago"))
    me.color_attributes.active_color_name = DISPLAY_ATTRIBUTE
    me.color_attributes.render_color_index = me.color_attributes.find(DISPLAY_ATTRIBUTE)
    me.update()
    if make_material:
        ob.active_material = radiance_material()


def texture_image_name(ob) -> str:
    return f"meshshade {ob.name}"


def apply_texture(ob, texture: np.ndarray, *, make_material: bool = False):
    """Write ``texture`` (H, W, 4) (RGB linear W/mm², A coverage; row 0 the top) into the float image
    :func:`texture_image_name` (made or resized; Blender stores rows from the bottom); with ``make_material`` the
    display material shows it through the active UV map. Returns the image."""
    H, W = texture.shape[:2]
    name = texture_image_name(ob)
    img = bpy.data.images.get(name)
    if img is not None and (tuple(img.size) != (W, H) or not img.is_float):
        bpy.data.images.remove(img)
        img = None
    if img is None:
        img = bpy.data.images.new(name, width=W, height=H, alpha=True, float_buffer=True)
    img.pixels.foreach_set(np.ascontiguousarray(texture[::-1], dtype=np.float32).ravel())
    img.update()
    if make_material:
        ob.active_material = radiance_material(img)
    return img


def radiance_material(image=None):
    """The material :data:`MATERIAL_NAME`: Attribute ``meshshade_radiance`` (or the baked ``image`` through the
    active UV map) -> Emission of strength :data:`EMISSION_PER_W_PER_MM2` -> output (made or reset)."""
    mat = bpy.data.materials.get(MATERIAL_NAME) or bpy.data.materials.new(MATERIAL_NAME)
    if not getattr(mat, "node_tree", None) and hasattr(mat, "use_nodes"):
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    if image is None:
        attr = nodes.new("ShaderNodeAttribute")
        attr.attribute_type, attr.attribute_name = "GEOMETRY", RADIANCE_ATTRIBUTE
    else:
        attr = nodes.new("ShaderNodeTexImage")
        attr.image, attr.interpolation = image, "Linear"
    attr.location = (-400, 0)
    emit = nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = EMISSION_PER_W_PER_MM2
    emit.location = (-150, 0)
    out = nodes.new("ShaderNodeOutputMaterial")
    out.location = (100, 0)
    links.new(attr.outputs["Color"], emit.inputs["Color"])
    links.new(emit.outputs["Emission"], out.inputs["Surface"])
    return mat


def _active_mesh(context) -> bool:
    """Whether the active object is a mesh (the operator's and the panel's poll)."""
    ob = context.active_object
    return ob is not None and ob.type == "MESH"


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if isinstance(exc, MeshshadeError) else f"{type(exc).__name__}: {text}"


# ------------------------------------------------------------------------------------------------ operator
class MESHSHADE_OT_bake(_BakeProperties, bpy.types.Operator):
    """Bake subsurface exitance of the active mesh under the scene's sun, point and spot lights (meshshade)"""

    bl_idname = "object.meshshade_bake"
    bl_label = "Bake translucency"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _active_mesh(context)

    def _start(self, context):
        ob = context.active_object
        job, notes = prepare(context, ob, self)
        for note in notes:
            self.report({"WARNING"}, note)
        return job

    def _finish(self, context, job) -> set:
        ob = bpy.data.objects.get(job.object_name)
        if ob is None:
            raise MeshshadeError(f"the object {job.object_name!r} was deleted during the bake")
        apply_result(ob, job.radiance, make_material=self.make_material and job.texture is None)
        if job.texture is not None:
            img = apply_texture(ob, job.texture, make_material=self.make_material)
            self.report({"INFO"}, f"meshshade: texture {img.size[0]}x{img.size[1]} of the active UV map in image "
                                  f"'{img.name}' (linear W/mm²; save it as OpenEXR to keep it)")
        for w in job.warnings:
            self.report({"WARNING"}, w)
        peak = job.radiance.max(axis=0)
        self.report({"INFO"}, f"meshshade: baked {ob.name} ({job.n_vertices} vertices, {self.model}); peak "
                              f"exitance {peak[0]:.3g}/{peak[1]:.3g}/{peak[2]:.3g} W/mm² into {RADIANCE_ATTRIBUTE}")
        return {"FINISHED"}

    def _fail(self, exc: BaseException) -> set:
        if not isinstance(exc, MeshshadeError):   # not a user mistake: the traceback goes to the log
            log = io.temp_path(LOG_NAME)
            io.append_text(log, "".join(traceback.format_exception(exc)))
            self.report({"ERROR"}, f"meshshade: {_one_line(exc)} (details in {log})")
            return {"CANCELLED"}
        self.report({"ERROR"}, f"meshshade: {_one_line(exc)}")
        return {"CANCELLED"}

    def execute(self, context):
        """Scripts and background mode: bake to the end, then write the result."""
        try:
            job = self._start(context)
            job.wait()
            return self._finish(context, job)
        except Exception as exc:  # noqa: BLE001 - every failure becomes a report
            return self._fail(exc)

    def invoke(self, context, event):
        """The interface: start the bake in a child process and watch it from a timer (Esc cancels)."""
        if context.window is None:   # no window to show progress in: run it through
            return self.execute(context)
        try:
            self._job = self._start(context).start()
        except Exception as exc:  # noqa: BLE001
            return self._fail(exc)
        wm = context.window_manager
        self._timer = wm.event_timer_add(POLL_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 100)
        self._status(context, "meshshade: bake starting (Esc to cancel)")
        return {"RUNNING_MODAL"}

    def _status(self, context, text):
        if context.workspace is not None:
            context.workspace.status_text_set(text)

    def _end(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        self._status(context, None)

    def modal(self, context, event):
        if event.type == "ESC":
            self._job.cancel()
            self._end(context)
            self.report({"WARNING"}, "meshshade: bake cancelled")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            done = self._job.poll()
        except Exception as exc:  # noqa: BLE001
            self._end(context)
            return self._fail(exc)
        if not done:
            context.window_manager.progress_update(int(100 * self._job.fraction))
            self._status(context, f"meshshade: {self._job.message} (Esc to cancel)")
            return {"RUNNING_MODAL"}
        self._end(context)
        try:
            return self._finish(context, self._job)
        except Exception as exc:  # noqa: BLE001
            return self._fail(exc)

    def cancel(self, context):   # Blender ends the operator (file closed, window gone)
        job = getattr(self, "_job", None)
        if job is not None:
            job.cancel()
            self._end(context)


# ------------------------------------------------------------------------------------------------ panel
class MESHSHADE_PT_panel(bpy.types.Panel):
    bl_label = "meshshade translucency"
    bl_idname = "MESHSHADE_PT_panel"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        return _active_mesh(context)

    def draw(self, context):
        layout = self.layout
        ob = context.active_object
        s = ob.meshshade
        layout.prop(s, "material")
        if s.material == "CUSTOM":
            col = layout.column(align=True)
            col.prop(s, "sigma_s_prime")
            col.prop(s, "sigma_a")
            col.prop(s, "eta")
        elif s.material == "MATERIAL":
            layout.prop(s, "albedo_clamp")
        layout.prop(s, "model")
        col = layout.column(align=True)
        col.prop(s, "cutoff_tol")
        col.prop(s, "geodesic")
        col.prop(s, "transport")
        row = layout.row(align=True)
        row.prop(s, "texture")
        sub = row.row(align=True)
        sub.enabled = s.texture
        sub.prop(s, "texture_size")
        layout.prop(s, "make_material")
        try:
            mpu = mm_per_blender_unit(context.scene.unit_settings.scale_length)
            size = np.array(ob.dimensions) * mpu
            layout.label(text=f"Size {size[0]:.4g} x {size[1]:.4g} x {size[2]:.4g} mm ({mpu:g} mm per unit)")
        except MeshshadeError as exc:
            layout.label(text=str(exc), icon="ERROR")
        n = sum(1 for lt in scene_lights(context) if lt.kind in ("SUN", "POINT", "SPOT"))
        layout.label(text=f"{n} sun/point/spot light(s) in the scene", icon="LIGHT" if n else "ERROR")
        op = layout.operator(MESHSHADE_OT_bake.bl_idname, icon="RENDER_STILL")
        for name in _SETTING_NAMES:
            setattr(op, name, getattr(s, name))
        if RADIANCE_ATTRIBUTE in ob.data.color_attributes:
            layout.label(text=f"Result: color attribute '{RADIANCE_ATTRIBUTE}' (W/mm², linear)")


_CLASSES = (MESHSHADE_PG_settings, MESHSHADE_AP_preferences, MESHSHADE_OT_bake, MESHSHADE_PT_panel)


def register(module: str = "meshshade.blender") -> None:
    """Register the add-on's classes (``module``: its name in Blender's preferences). Registered already (the
    package and the add-on file both enabled): the earlier registration is replaced."""
    if MESHSHADE_OT_bake.is_registered:
        unregister()
    MESHSHADE_AP_preferences.bl_idname = module
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.meshshade = PointerProperty(type=MESHSHADE_PG_settings)


def unregister() -> None:
    if hasattr(bpy.types.Object, "meshshade"):
        del bpy.types.Object.meshshade
    for cls in reversed(_CLASSES):
        if cls.is_registered:
            bpy.utils.unregister_class(cls)
