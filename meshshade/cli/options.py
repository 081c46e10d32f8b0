"""Options shared by the subcommands: material, mesh and units, lights, model, geodesics, far field, images.

Each ``add_*`` function adds options to an :class:`argparse.ArgumentParser`; each ``*_from_args`` function turns
the parsed options into the objects of the Python API. Directories and files are created through
:mod:`meshshade.io` only.
"""
from __future__ import annotations

import argparse
import decimal
import math
from dataclasses import dataclass

from meshshade.errors import MeshshadeError
from meshshade.geometry.mesh import Mesh
from meshshade.io import load_mesh
from meshshade.light import parse_light_spec
from meshshade.materials import JENSEN_2001_PRESETS, Material, material_from_options
from meshshade.output.render import Camera, parse_camera
from meshshade.transport import MODELS, describe_scale
from meshshade.transport.models import DEFAULT_MODEL
from meshshade.units import mm_per_unit

LIGHT_HELP = ("light SPEC (repeatable), positions in the mesh's units: beam:ox,oy,oz:dx,dy,dz[:power W[:radius]] | "
              "directional:dx,dy,dz[:irradiance W/mm^2] | point:x,y,z[:intensity W/sr] | "
              "spot:x,y,z:dx,dy,dz[:intensity W/sr[:cone deg[:blend]]]")


# --- numbers ---------------------------------------------------------------------------------------------
def number(text: str) -> float:
    """argparse type: a finite real number (``nan`` and ``inf`` are refused; the option's own range is checked by
    the Python API, which names it)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def integer(minimum: int | None = None):
    """argparse type factory: a whole number, written as digits (``100000``, ``100_000``) or in exponent notation
    when that is exact (``1e5``, ``2.5e6``), and at least ``minimum``."""
    def parse(text: str) -> int:
        try:
            value = decimal.Decimal(str(text).strip().replace("_", ""))
        except decimal.InvalidOperation:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if not value.is_finite() or value != value.to_integral_value():
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}")
        if abs(value.adjusted()) > 4300:  # beyond Python's int-to-text limit: no count or seed is that large
            raise argparse.ArgumentTypeError(f"{text!r} is too large")
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"expected a whole number >= {minimum}, got {text!r}")
        return int(value)

    parse.__name__ = "integer" if minimum is None else f"integer >= {minimum}"
    return parse


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
def add_material_args(p: argparse.ArgumentParser, *, with_g: bool = False) -> None:
    g = p.add_argument_group("material (a preset, or coefficients in 1/mm)")
    g.add_argument("--material", metavar="NAME",
                   help="measured preset (Jensen et al. 2001, Narasimhan et al. 2006; `meshshade materials` lists "
                        "them): " + ", ".join(sorted(JENSEN_2001_PRESETS)) + ", lowfat-milk, espresso, ...")
    g.add_argument("--sigma-s-prime", metavar="S", help="reduced scattering [1/mm]: one value or R,G,B")
    g.add_argument("--sigma-a", metavar="A", help="absorption [1/mm]: one value or R,G,B")
    g.add_argument("--eta", type=number, help="relative index of refraction (default: the preset's, 1.3 or 1.33; "
                                              "1.3 for coefficients)")
    if with_g:
        g.add_argument("--g", type=number, default=0.0, help="Henyey-Greenstein anisotropy (Monte Carlo only)")


def material_given(args) -> bool:
    """Whether any material option was given (``check`` accepts none)."""
    return args.material is not None or args.sigma_s_prime is not None or args.sigma_a is not None


def material_from_args(args) -> Material:
    ss = parse_floats(args.sigma_s_prime, "--sigma-s-prime", (1, 3)) if args.sigma_s_prime is not None else None
    sa = parse_floats(args.sigma_a, "--sigma-a", (1, 3)) if args.sigma_a is not None else None
    if args.material is None and ss is None and sa is None:
        raise MeshshadeError("choose a material: --material NAME, or --sigma-s-prime and --sigma-a (1/mm)")
    return material_from_options(args.material, sigma_s_prime=ss, sigma_a=sa, eta=args.eta,
                                 g=getattr(args, "g", 0.0) or 0.0)


# --- mesh, lights ---------------------------------------------------------------------------------------
def add_mesh_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("mesh", help="input mesh: OBJ, PLY, OFF, STL or GLB (never modified)")
    p.add_argument("--units", default="mm", help="length unit of the mesh file: mm, cm, m or in (default mm)")


def mesh_and_material(args) -> tuple[Mesh, Material]:
    """The material of the options, then the mesh (in mm); unless ``--quiet``, one line on their scales."""
    material = material_from_args(args)
    mesh = load_mesh(args.mesh, units=args.units)
    if not args.quiet:
        print(describe_scale(mesh, material))
    return mesh, material


def add_light_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--light", action="append", default=[], metavar="SPEC", help=LIGHT_HELP)


def lights_from_args(args, mesh: Mesh | None = None) -> list:
    """The ``--light`` specs as light objects, positions converted from the mesh's units (``--units``) to mm.

    Needs no mesh, so commands check their lights before any work."""
    if not args.light:
        raise MeshshadeError("give at least one light: --light SPEC (" + LIGHT_HELP.split(": ", 1)[1] + ")")
    scale = mesh.mm_per_unit if mesh is not None else mm_per_unit(args.units)
    return [parse_light_spec(s, mm_per_unit=scale) for s in args.light]


# --- transport -----------------------------------------------------------------------------------------
def add_model_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", default=DEFAULT_MODEL, choices=list(MODELS),
                   help=f"transport model (default {DEFAULT_MODEL}): volume, diffusion inside the object's volume "
                        "with the analytic near field on top (a mesh that is not closed falls back to auto, "
                        "saying so); dipole, curved, exact-sphere, fitted, surface kernels over geodesic "
                        "neighbourhoods; auto picks per entry sample the cheapest surface kernel and geodesic "
                        "method the scene calls for and reports its choices")


def add_near_field_arg(p: argparse.ArgumentParser, default: str | None = None) -> None:
    p.add_argument("--near-field", default=default, choices=["point", "beam"],
                   help=f"what enters the medium (default {default or 'beam for volume, point for the others'}): "
                        "point, each surface model's point source at depth z_r; "
                        "beam, exact single scattering plus diffusion sources along the beam fitted to exact "
                        "transport, composed with the model's geometry (docs/physics.md §13)")


def add_geodesic_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--geodesic", default="exact", choices=["exact", "arc"],
                   help="geodesic distances: exact polyhedral (default) or arc (curvature-corrected chords: "
                        "~5x faster, 1e-4 on smooth meshes, 1-11 %% low on bumpy scans)")


def add_far_field_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--far-field", default=None, choices=["off", "clustered"],
                   help="directional/point lights: sum pairs beyond r_near (where 10 %% of the dipole's energy lies beyond) "
                        "by clusters "
                        "of the planar dipole (default: off; auto uses it where the surface is flat on the scale "
                        "of the cutoff)")


def add_transport_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--transport", default="auto", choices=["auto", "hierarchical", "direct"],
                   help="surface models: how directional/point-light samples are summed: hierarchical (near "
                        "field plus clusters; near-linear in the vertex count), direct (every pair, the reference) "
                        "or auto (default: "
                        "hierarchical where its distance check passes on the mesh, else direct)")


def add_cluster_args(p: argparse.ArgumentParser) -> None:
    """``--scheduler ADDRESS`` / ``--workers N``: run on Dask distributed (:mod:`meshshade.batch.cluster`)."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on an existing Dask scheduler (tcp://host:8786, or a scheduler file)")
    g.add_argument("--workers", type=integer(1), default=None, metavar="N",
                   help="run on a local Dask cluster of N worker processes")


# --- images (render, compare) ------------------------------------------------------------------------
def add_image_args(p: argparse.ArgumentParser) -> None:
    """Mesh, material, lights, bake knobs and camera/image options of ``render`` and ``compare``."""
    add_mesh_args(p)
    add_material_args(p)
    add_light_arg(p)
    p.add_argument("--cutoff-tol", type=number, default=1e-4, help="neighbourhood tolerance (default 1e-4)")
    p.add_argument("--width", type=integer(1), default=512, help="image width in pixels (default 512)")
    p.add_argument("--height", type=integer(1), default=512, help="image height in pixels (default 512)")
    p.add_argument("--spp", type=integer(1), default=4, help="samples per pixel, jittered strata (default 4)")
    p.add_argument("--camera", default="auto", help="auto[:dx,dy,dz] (default, view along -z) | "
                   "persp:ex,ey,ez:tx,ty,tz:ux,uy,uz:FOV_DEG | ortho:eye:target:up:HEIGHT (mesh units)")
    p.add_argument("--background", default="transparent", help="transparent (PNG alpha) or R,G,B in [0, 1]")
    p.add_argument("--tonemap", default="drago", choices=["drago", "exposure"], help="PNG tone mapping")
    p.add_argument("--bias", type=number, default=0.85, help="Drago bias (default 0.85)")
    add_geodesic_arg(p)
    add_far_field_arg(p)
    add_transport_arg(p)
    p.add_argument("--per-pixel", action="store_true",
                   help="gather the kernel at every pixel sample (exact peaks; slower) instead of interpolating")


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


def image_scene_from_args(args) -> ImageScene:
    lights = lights_from_args(args)
    mesh, material = mesh_and_material(args)
    camera = parse_camera(args.camera, mesh, mesh.mm_per_unit)
    bg = background_from_args(args)
    meta = {"material": material.describe(), "lights": "; ".join(args.light), "camera": camera.describe(),
            "units": "radiance W/(mm^2 sr) per unit light power/irradiance/intensity; lengths mm",
            "mesh": str(args.mesh)}
    return ImageScene(mesh, material, lights, camera, bg, meta)
