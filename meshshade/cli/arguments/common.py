"""Options shared by the subcommands' parsers: material, mesh and units, lights, model, geodesics, far field,
Dask, images; and the argparse types of numbers.

Each ``add_*`` function adds options to an :class:`argparse.ArgumentParser`. Like every module of
:mod:`meshshade.cli.arguments` this imports only the standard library and meshshade's light name modules
(:mod:`meshshade.names`, :mod:`meshshade.material_presets`); the options are turned into the objects of the
Python API by :mod:`meshshade.cli.options`, once the command runs.
"""
from __future__ import annotations

import argparse
import decimal
import math
import sys

from meshshade.material_presets import JENSEN_2001_PRESETS
from meshshade.names import DEFAULT_MODEL, MODELS

LIGHT_HELP = ("light SPEC (repeatable), positions in the mesh's units: beam:ox,oy,oz:dx,dy,dz[:power W[:radius]] | "
              "directional:dx,dy,dz[:irradiance W/mm^2] | point:x,y,z[:intensity W/sr] | "
              "spot:x,y,z:dx,dy,dz[:intensity W/sr[:cone deg[:blend]]] | "
              "env:FILE.exr[:strength[:rotation deg[:up y|z]]] (equirectangular HDR, W/(mm^2 sr) per unit strength) | "
              "uniform[:radiance W/(mm^2 sr)] | area:x,y,z:nx,ny,nz:rect:w,h[:power W[:ux,uy,uz]] | "
              "area:x,y,z:nx,ny,nz:disc:r[,r2][:power W[:ux,uy,uz]]")
#: the relative standard error of each vertex's entering power an environment or area light aims for by default
LIGHT_ERROR_DEFAULT = 0.005


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


# --- material ---------------------------------------------------------------------------------------------
def add_albedo_map_args(p: argparse.ArgumentParser, *, note: str = "") -> None:
    """``--albedo-map FILE|mtl|vertex``, ``--albedo-clamp``, ``--radius-map FILE`` and ``--radius-scale`` (a painted
    material, docs/physics.md §17), as ``meshshade bake``, ``render`` and ``mc`` read them
    (:func:`meshshade.cli.options.painted_material`)."""
    p.add_argument("--albedo-map", metavar="FILE|mtl|vertex",
                   help="paint the material: the colour (diffuse reflectance) per point of the surface, over the "
                        "mesh's UVs from FILE (EXR linear; PNG, JPEG... sRGB), the OBJ's MTL map_Kd (mtl) or the "
                        "PLY's vertex colours (vertex); each channel's albedo is found so that the model reflects "
                        "that colour, the material's mean free path kept (docs/physics.md §17" + note + ")")
    p.add_argument("--albedo-clamp", action="store_true",
                   help="move painted colours outside the range the model reaches (a 0 or a 1) just inside it, "
                        "saying how many (default: refuse them)")
    p.add_argument("--radius-map", metavar="FILE",
                   help="paint the mean free path: a map over the mesh's UVs whose values (read as data, not "
                        "colour: no sRGB decoding; one channel for all three or R,G,B) times --radius-scale scale the "
                        "material's mean free path per point; every value must be above 0 (docs/physics.md "
                        "eq. (132)" + note + ")")
    p.add_argument("--radius-scale", metavar="S", type=number,
                   help="multiply the radius map's values by S (default 1; an 8-bit map holds 0-1), as Blender's "
                        "Subsurface Scale multiplies its Radius")


def add_material_args(p: argparse.ArgumentParser, *, with_g: bool = False) -> None:
    g = p.add_argument_group("material (a preset, or coefficients in 1/mm)")
    g.add_argument("--material", metavar="NAME", action="append",
                   help="measured preset (Jensen et al. 2001, Narasimhan et al. 2006; `meshshade materials` lists "
                        "them): " + ", ".join(sorted(JENSEN_2001_PRESETS)) + ", lowfat-milk, espresso, ...; "
                        "bake and render also take PART=NAME, repeatable: the preset of the mesh's part PART (an "
                        "OBJ usemtl or g name, a glTF material), or its coefficients PART=SIGMA_S_PRIME/SIGMA_A[/ETA] "
                        "(1/mm, one value or R,G,B each); a plain NAME then sets the rest")
    g.add_argument("--sigma-s-prime", metavar="S", help="reduced scattering [1/mm]: one value or R,G,B")
    g.add_argument("--sigma-a", metavar="A", help="absorption [1/mm]: one value or R,G,B")
    g.add_argument("--eta", type=number, help="relative index of refraction (default: the preset's, 1.3 or 1.33; "
                                              "1.3 for coefficients)")
    if with_g:
        g.add_argument("--g", type=number, default=0.0, help="Henyey-Greenstein anisotropy (Monte Carlo only)")


# --- mesh, lights ---------------------------------------------------------------------------------------
def add_mesh_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("mesh", help="input mesh: OBJ, PLY, OFF, STL or GLB (never modified)")
    p.add_argument("--units", default="mm", help="length unit of the mesh file: mm, cm, m or in (default mm)")


def add_light_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--light", action="append", default=[], metavar="SPEC", help=LIGHT_HELP)
    p.add_argument("--light-error", type=number, default=LIGHT_ERROR_DEFAULT, metavar="REL",
                   help="env, uniform and area lights: the relative standard error of each vertex's entering power "
                        "that their directions per vertex are chosen for, in [1e-4, 0.5] (default "
                        f"{LIGHT_ERROR_DEFAULT}; the error left is reported)")


# --- transport -----------------------------------------------------------------------------------------
def add_model_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", default=DEFAULT_MODEL, choices=list(MODELS),
                   help=f"transport model (default {DEFAULT_MODEL}): volume, diffusion inside the object's volume "
                        "(open, many-part and coarse meshes included; a flat sheet, which encloses nothing, falls "
                        "back to auto, saying so) with the analytic near field on top; dipole, curved, "
                        "exact-sphere, fitted, surface kernels over geodesic neighbourhoods; auto picks per entry sample the cheapest surface kernel and geodesic "
                        "method the scene calls for and reports its choices")


# --- former spellings ---------------------------------------------------------------------------------------
class DeprecatedAlias(argparse.Action):
    """A former spelling of an option (hidden from --help): it still works, storing into the new option's ``dest``,
    and says so in one line on stderr, ``meshshade: warning: --old is deprecated; use --new``."""

    def __init__(self, option_strings, dest, *, new: str, **kwargs):
        self.new = new
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"meshshade: warning: {option_string} is deprecated; use {self.new}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_deprecated_alias(p: argparse.ArgumentParser, old: str, new: str, **kwargs) -> None:
    """``old`` as a hidden, deprecated spelling of the option ``new`` (already added to ``p``; ``kwargs``: its
    ``choices`` or ``metavar``)."""
    dest = next(a.dest for a in p._actions if new in a.option_strings)
    p.add_argument(old, dest=dest, action=DeprecatedAlias, new=new, default=argparse.SUPPRESS, help=argparse.SUPPRESS,
                   **kwargs)


def deprecated_aliases(p: argparse.ArgumentParser) -> dict:
    """``{old option name: new option name}`` (without dashes) of the parser's :class:`DeprecatedAlias` options."""
    return {o.lstrip("-"): a.new.lstrip("-") for a in p._actions if isinstance(a, DeprecatedAlias)
            for o in a.option_strings}


# --- source model -------------------------------------------------------------------------------------------
SOURCE_MODEL_HELP = ("point, each surface model's point source at depth z_r; beam, the near-field model: exact "
                     "single scattering plus diffusion sources along the beam fitted to exact transport, composed "
                     "with the model's geometry (docs/physics.md §13)")


def add_source_model_arg(p: argparse.ArgumentParser, default: str | None = None) -> None:
    """``--source-model {point,beam}`` (and its former spelling ``--near-field``)."""
    p.add_argument("--source-model", default=default, choices=["point", "beam"],
                   help=f"what enters the medium (default {default or 'beam for volume, point for the others'}): "
                        + SOURCE_MODEL_HELP)
    add_deprecated_alias(p, "--near-field", "--source-model", choices=["point", "beam"])


def add_geodesic_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--geodesic", default="exact", choices=["exact", "arc"],
                   help="geodesic distances: exact polyhedral (default) or arc (curvature-corrected chords: "
                        "~5x faster, 1e-4 on smooth meshes, 1-11 %% low on bumpy scans)")


def add_far_field_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--far-field", default=None, choices=["off", "clustered"],
                   help="directional/point lights: sum pairs beyond r_near (where 10 %% of the dipole's energy "
                        "lies beyond) by source clusters of the planar dipole (default: off; auto uses it where the "
                        "surface is flat on the scale of the cutoff)")


def add_transport_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--transport", default="auto", choices=["auto", "hierarchical", "direct"],
                   help="surface models: how directional/point-light samples are summed: hierarchical (near "
                        "zone plus source clusters; near-linear in the vertex count), direct (every pair, the "
                        "reference) or auto (default: "
                        "hierarchical where its distance check passes on the mesh, else direct)")


def add_cluster_args(p: argparse.ArgumentParser) -> None:
    """``--scheduler ADDRESS`` / ``--workers N``: run on Dask distributed (:mod:`meshshade.batch.dask_cluster`)."""
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
