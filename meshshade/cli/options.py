"""What the shared options mean, once a command runs: material, mesh and units, lights, the bake's options, images.

Each ``*_from_args`` function turns the parsed options into the objects of the Python API (their parsers are
in :mod:`meshshade.cli.arguments.common`, which imports nothing heavy). Directories and files are created
through :mod:`meshshade.io` only.
"""
from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass

import numpy as np

from meshshade.cli.arguments.common import LIGHT_HELP
from meshshade.errors import LightError, MeshshadeError, ParameterError
from meshshade.geometry.mesh import Mesh
from meshshade.io import (load_mesh, mtl_colour_map, read_colour_map, read_data_map, read_face_names, read_uv_map,
                          read_vertex_colours)
from meshshade.light import AreaLight, EnvironmentLight, parse_light_spec
from meshshade.materials import Material, material_from_options
from meshshade.output.render import Camera, parse_camera
from meshshade.painted import PaintedMaterial
from meshshade.parts import PartedMaterial
from meshshade.transport import BakeOptions, SurfaceOptions, describe_scale
from meshshade.units import mm_per_unit


# --- numbers ---------------------------------------------------------------------------------------------
def parse_floats(text: str, what: str, n: tuple[int, ...] | None = None) -> list[float]:
    """Comma-separated finite numbers of option ``what``; ``n``: the allowed counts (default: any, at least
    one)."""
    try:
        vals = [float(x) for x in str(text).split(",") if x.strip() != ""]
    except ValueError:
        raise MeshshadeError(f"{what}: expected comma-separated numbers, got {text!r}") from None
    if not vals or (n is not None and len(vals) not in n):
        raise MeshshadeError(f"{what}: expected {' or '.join(map(str, n or (1,)))} value(s), got {text!r}")
    if not all(map(math.isfinite, vals)):
        raise MeshshadeError(f"{what}: expected finite numbers, got {text!r}")
    return vals


def parse_names(text: str | None) -> list[str] | None:
    """A comma list of names (blanks dropped), or None when the option was not given."""
    return None if text is None else [x.strip() for x in text.split(",") if x.strip()]


# --- material ---------------------------------------------------------------------------------------------
def material_given(args) -> bool:
    """Whether any material option was given (``check`` accepts none)."""
    return args.material is not None or args.sigma_s_prime is not None or args.sigma_a is not None


def _material_specs(args):
    """(plain presets, [(part, preset or coefficients)]) of the repeatable ``--material``."""
    given = args.material or []
    given = [given] if isinstance(given, str) else list(given)
    plain = [x for x in given if "=" not in x]
    parts = []
    for x in given:
        if "=" in x:
            name, _, preset = x.partition("=")
            if not name.strip() or not preset.strip():
                raise ParameterError(f"--material {x!r}: a part's material is PART=PRESET or "
                                     "PART=SIGMA_S_PRIME/SIGMA_A[/ETA]")
            parts.append((name.strip(), preset.strip()))
    if len(plain) > 1:
        raise ParameterError(f"--material given {len(plain)} times ({', '.join(plain)}); one sets the whole mesh, "
                             "PART=NAME the mesh's parts")
    return plain, parts


def material_from_args(args, *, parts_allowed: bool = False) -> Material:
    plain, parts = _material_specs(args)
    if parts and not parts_allowed:
        raise ParameterError("--material PART=NAME (a material per part) is for `meshshade bake` and `render`; "
                             "give one preset")
    ss = parse_floats(args.sigma_s_prime, "--sigma-s-prime", (1, 3)) if args.sigma_s_prime is not None else None
    sa = parse_floats(args.sigma_a, "--sigma-a", (1, 3)) if args.sigma_a is not None else None
    if not plain and ss is None and sa is None:
        if parts:
            return None
        raise MeshshadeError("choose a material: --material NAME, or --sigma-s-prime and --sigma-a (1/mm)")
    return material_from_options(plain[0] if plain else None, sigma_s_prime=ss, sigma_a=sa, eta=args.eta,
                                 g=getattr(args, "g", 0.0) or 0.0)


def parted_material(args, mesh, default):
    """The :class:`~meshshade.parts.PartedMaterial` of ``--material PART=NAME`` on ``mesh`` (read from
    ``args.mesh``'s part names: :func:`meshshade.io.part_names.read_face_names`), ``default`` (or None) the rest;
    ``default`` itself where no part is named."""
    _, parts = _material_specs(args)
    if not parts:
        return default
    names = read_face_names(args.mesh, mesh.n_faces)
    g = getattr(args, "g", 0.0) or 0.0
    assigned = [(name, _part_material(name, spec, args.eta, g)) for name, spec in parts]
    return PartedMaterial.from_names(names, assigned, default, where=str(args.mesh))


def _part_material(name: str, spec: str, eta, g) -> Material:
    """A part's material: a preset's name, or its coefficients ``SIGMA_S_PRIME/SIGMA_A[/ETA]`` in 1/mm (each one
    value or R,G,B; ETA defaults to ``--eta``, else 1.3), named after the part."""
    if "/" not in spec:
        return material_from_options(spec, eta=eta, g=g)
    fields = spec.split("/")
    what = f"--material {name}={spec}"
    if len(fields) not in (2, 3):
        raise ParameterError(f"{what}: coefficients are SIGMA_S_PRIME/SIGMA_A[/ETA] (1/mm, one value or R,G,B each)")
    ss = parse_floats(fields[0], f"{what} (sigma_s')", (1, 3))
    sa = parse_floats(fields[1], f"{what} (sigma_a)", (1, 3))
    if len(fields) == 3:
        eta = parse_floats(fields[2], f"{what} (eta)", (1,))[0]
    return Material(ss, sa, 1.3 if eta is None else eta, g, name=name)


# --- mesh, lights ---------------------------------------------------------------------------------------
def mesh_and_material(args, *, parts_allowed: bool = False) -> tuple[Mesh, Material]:
    """The material of the options, then the mesh (in mm); unless ``--quiet``, one line on their scales. With
    ``parts_allowed`` (bake), ``--material PART=NAME`` makes a material of the mesh's parts."""
    material = material_from_args(args, parts_allowed=parts_allowed)
    mesh = load_mesh(args.mesh, units=args.units)
    if parts_allowed:
        material = parted_material(args, mesh, material)
    if not args.quiet:
        first = material.materials[-1] if hasattr(material, "materials") else material
        print(describe_scale(mesh, first))
    return mesh, material


def is_painted(args) -> bool:
    """Whether the command's options paint the material (``--albedo-map`` or ``--radius-map``), and a one-line
    error for ``--radius-scale`` or ``--albedo-clamp`` without the map they act on."""
    if getattr(args, "radius_scale", None) is not None and not args.radius_map:
        raise ParameterError("--radius-scale multiplies the radius map: give --radius-map FILE with it")
    return bool(args.albedo_map or getattr(args, "radius_map", None))


def painted_material(args, mesh, material) -> PaintedMaterial:
    """``material`` painted as ``--albedo-map`` says (a file over the UVs, the OBJ's map_Kd, the PLY's vertex
    colours) and ``--radius-map`` / ``--radius-scale`` (its mean free path scaled per point, eq. (132)); a one-line
    error for a map that cannot be read, a mesh without UVs, a colour no medium has (unless ``--albedo-clamp``,
    which says how many it moved) or a radius of 0. ``meshshade bake``, ``render`` and ``mc`` read it."""
    option = "--albedo-map" if args.albedo_map else "--radius-map"
    if not isinstance(material, Material):
        raise ParameterError(f"{option} paints one material; it cannot be given with --material PART=NAME")
    if getattr(args, "model", "volume") != "volume":   # meshshade mc has no model: its walk takes any medium
        raise ParameterError(f"{option} needs the volume model (model {args.model!r} takes one medium)")
    kind = args.albedo_map
    clamp = bool(args.albedo_clamp)
    paint = {}
    uv = None
    if kind == "vertex":
        paint["colour"] = read_vertex_colours(args.mesh, mesh)
    elif kind:
        image_path = mtl_colour_map(args.mesh) if kind == "mtl" else kind
        paint["image"] = read_colour_map(image_path)
        uv = read_uv_map(args.mesh, mesh)
        if uv is None:
            raise ParameterError(f"{args.mesh}: has no texture coordinates (UVs), so --albedo-map cannot be laid on it")
    if getattr(args, "radius_map", None):
        scale = 1.0 if args.radius_scale is None else float(args.radius_scale)
        if not (math.isfinite(scale) and scale > 0.0):
            raise ParameterError(f"--radius-scale must be a finite number above 0, got {args.radius_scale!r}")
        factors = read_data_map(args.radius_map) * scale
        if not np.all(factors > 0.0):
            bad = int(np.sum(np.any(factors <= 0.0, axis=2)))
            raise ParameterError(f"{args.radius_map}: the radius map holds {bad} texel(s) of 0 or below (no medium "
                                 "has a mean free path of 0)")
        uv = read_uv_map(args.mesh, mesh) if uv is None else uv
        if uv is None:
            raise ParameterError(f"{args.mesh}: has no texture coordinates (UVs), so --radius-map cannot be laid on it")
        paint["radius_image"] = factors
        if kind == "vertex":
            raise ParameterError("--radius-map is an image over the UVs; it cannot be given with --albedo-map vertex")
    painted = PaintedMaterial(material, uv=uv, clamp=clamp, **paint)
    if painted.clamped and not args.quiet:
        lo, hi = painted.clamp_range
        print(f"meshshade: note: --albedo-clamp moved {painted.clamped} painted values into [{lo:.4f}, {hi:.4f}]",
              file=sys.stderr)
    return painted


def lights_from_args(args, mesh: Mesh | None = None) -> list:
    """The ``--light`` specs as light objects, positions converted from the mesh's units (``--units``) to mm.

    Needs no mesh, so commands check their lights before any work."""
    if not args.light:
        raise MeshshadeError("give at least one light: --light SPEC (" + LIGHT_HELP.split(": ", 1)[1] + ")")
    scale = mesh.mm_per_unit if mesh is not None else mm_per_unit(args.units)
    lights = [parse_light_spec(s, mm_per_unit=scale) for s in args.light]
    error = getattr(args, "light_error", None)
    return [with_light_error(light, error) for light in lights]


def with_light_error(light, error):
    """``light`` with the ``--light-error`` (an environment or area light's target relative error); other lights,
    or ``error`` None, as they are."""
    if error is None or not isinstance(light, (EnvironmentLight, AreaLight)):
        return light
    try:
        return dataclasses.replace(light, error=error)
    except LightError as exc:
        raise LightError(f"--light-error: {exc}".replace("environment error", "the error")
                         .replace("area light error", "the error")) from None


# --- the bake's options (bake, render, compare) ---------------------------------------------------------------
def surface_options_from_args(args, source_model: str | None = None) -> SurfaceOptions:
    """The surface models' :class:`~meshshade.surface.options.SurfaceOptions` of ``--cutoff-tol``,
    ``--curvature-radius``, ``--geodesic``, ``--far-field``, ``--transport`` and ``source_model``, checked as they
    are made (one line naming the option)."""
    return SurfaceOptions(source_model=source_model, geodesic=args.geodesic, cutoff_tol=args.cutoff_tol,
                          curvature_radius_mm=getattr(args, "curvature_radius", None), transport=args.transport,
                          far_field=args.far_field)


def bake_options_from_args(args, *, progress: bool | str = False) -> BakeOptions:
    """The :class:`~meshshade.transport.options.BakeOptions` of ``--model``, ``--source-model`` and the surface
    models' options (:func:`surface_options_from_args`), checked as they are made, before any work."""
    return BakeOptions(model=args.model, surface=surface_options_from_args(args, args.source_model),
                       progress=progress)


# --- images (render, compare) ------------------------------------------------------------------------
@dataclass(frozen=True)
class ImageScene:
    """What ``render`` and ``compare`` read from their options: mesh (mm), material, lights, camera,
    ``background`` (None: transparent, else 3 floats in [0, 1]) and the metadata written into the EXR files."""

    mesh: Mesh
    material: Material
    lights: list
    camera: Camera
    background: list | None
    metadata: dict


def background_from_args(args) -> list | None:
    """``--background``: None (transparent) or three numbers in [0, 1]."""
    if args.background == "transparent":
        return None
    rgb = parse_floats(args.background, "--background", (3,))
    if not all(0.0 <= x <= 1.0 for x in rgb):
        raise MeshshadeError(f"--background: expected transparent or R,G,B in [0, 1], got {args.background!r}")
    return rgb


def image_scene_from_args(args, *, varying: bool = False) -> ImageScene:
    """The mesh, material, lights, camera and background of ``meshshade render`` and ``compare``; with ``varying``
    (render) the material may have parts (``--material PART=NAME``) or be painted (``--albedo-map``), as bake's."""
    lights = lights_from_args(args)
    mesh, material = mesh_and_material(args, parts_allowed=varying)
    if varying and is_painted(args):
        material = painted_material(args, mesh, material)
    camera = parse_camera(args.camera, mesh, mesh.mm_per_unit)
    bg = background_from_args(args)
    meta = {"material": material.describe(), "lights": "; ".join(args.light), "camera": camera.describe(),
            "units": "radiance W/(mm^2 sr) per unit light power/irradiance/intensity; lengths mm",
            "mesh": str(args.mesh)}
    return ImageScene(mesh, material, lights, camera, bg, meta)
