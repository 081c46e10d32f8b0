"""``meshshade render``: bake, then render the mesh: linear EXR (with metadata) and tone-mapped PNG (thin layer
over :func:`meshshade.transport.baking.bake` and :mod:`meshshade.output.render`).

A PLY written by ``meshshade bake`` (vertex radiance ``radiance_r/g/b``, :func:`meshshade.io.read_baked_ply`) is
rendered as it is: its radiance, its recorded units and the eta of its recorded material; no material, light or
model option is needed, and those given are reported as ignored (one warning line). ``--per-pixel`` needs the bake
itself (its entry points) and is refused for such a file.

Its help and arguments are in :mod:`meshshade.cli.arguments.render`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

import os
import warnings
from pathlib import Path

from meshshade.cli.options import (background_from_args, bake_options_from_args, image_scene_from_args,
                                   material_given)
from meshshade.errors import MaterialError, MeshshadeError, MeshValidationError, OutputError
from meshshade.io import check_output_path, read_baked_ply, write_exr, write_png
from meshshade.kernels.optics import check_eta
from meshshade.names import DEFAULT_MODEL
from meshshade.output.render import (PixelGather, check_image_size, display_rgba, image_rgba, parse_camera,
                                     render_radiance)
from meshshade.output.tonemap import check_tonemap_options
from meshshade.transport import bake, describe_result
from meshshade.units import mm_per_unit


def image_outputs(out: str, inputs=()) -> tuple[Path, Path]:
    """The two files ``--out OUT`` names: ``OUT.exr`` and ``OUT.png`` (an ``.exr`` or ``.png`` on OUT is dropped
    first). Refuses a folder and any other extension, which would otherwise land beside what was asked."""
    if str(out).endswith(("/", os.sep)) or Path(out).is_dir():
        raise OutputError(f"--out {out} is a folder; give a base name such as {Path(out) / 'render'} "
                          "(writes render.exr and render.png there)")
    base = Path(out)
    if base.suffix.lower() in (".exr", ".png"):
        base = base.with_suffix("")
    elif base.suffix:
        raise OutputError(f"--out {out}: render writes OUT.exr and OUT.png; give a name without an extension or "
                          f"ending in .exr or .png, not {base.suffix}")
    exr, png = base.with_name(base.name + ".exr"), base.with_name(base.name + ".png")
    check_output_path(exr, inputs)
    check_output_path(png, inputs)
    return exr, png


def run_render(args) -> int:
    exr, png = image_outputs(args.out, [args.mesh])
    check_image_size(args.width, args.height, args.spp)
    check_tonemap_options(args.tonemap, args.bias)
    background_from_args(args)
    baked = read_baked_ply(args.mesh, units=args.units)  # None unless the input is a bake's PLY
    if baked is not None:
        return _render_baked(args, baked, exr, png)
    options = bake_options_from_args(args, progress=False if args.quiet else "render")
    scene = image_scene_from_args(args, varying=True)
    mesh, material = scene.mesh, scene.material
    res = bake(mesh, material, scene.lights, options)
    gather = PixelGather(mesh, res) if args.per_pixel else None
    rgb, alpha = render_radiance(mesh, res.radiance, scene.camera, args.width, args.height, args.spp,
                                 eta=material.eta, exitance_at=gather)
    decisions = {"auto_decisions": res.plan.describe()} if res.plan is not None else {}
    write_exr(exr, image_rgba(rgb, alpha), {**scene.metadata, "model": args.model,
                                           "per_pixel": bool(args.per_pixel), **decisions})
    write_png(png, display_rgba(rgb, alpha, operator=args.tonemap, bias=args.bias, background=scene.background))
    if not args.quiet:
        print(describe_result(res))
        print(f"wrote {exr} and {png}")
    return 0


def _ignored_options(args, info) -> list[str]:
    """The options that do not apply to a bake's PLY and were given anyway (or differ from their defaults)."""
    given = [("--material/--sigma-s-prime/--sigma-a", material_given(args)), ("--eta", args.eta is not None),
             ("--light", bool(args.light)), ("--model", args.model != DEFAULT_MODEL),
             ("--geodesic", args.geodesic != "exact"), ("--far-field", args.far_field is not None),
             ("--transport", args.transport != "auto"),
             ("--cutoff-tol", args.cutoff_tol != 1e-4),
             ("--units", mm_per_unit(args.units) != info["mm_per_unit"] and args.units.strip().lower() != "mm")]
    return [name for name, yes in given if yes]


def _render_baked(args, baked, exr, png) -> int:
    """Render the radiance a bake's PLY carries (see the module docstring)."""
    mesh, radiance, info = baked
    if args.per_pixel:
        raise MeshshadeError(f"--per-pixel needs the bake itself (its entry points), which {args.mesh} does not "
                             "hold; render the original mesh with --per-pixel to bake and gather per pixel")
    eta = info["eta"]
    if eta is not None:
        try:
            check_eta(eta)
        except MaterialError as exc:
            raise MeshValidationError(f"{args.mesh}: the material it records is not valid: {exc}") from None
    else:
        eta = args.eta if args.eta is not None else 1.3
        warnings.warn(f"{args.mesh} records no material; its radiance is turned into image radiance with "
                      f"eta {eta:g}" + ("" if args.eta is not None else " (give --eta to change it)"), UserWarning,
                      stacklevel=2)
    ignored = [o for o in _ignored_options(args, info) if not (o == "--eta" and info["eta"] is None)]
    if ignored:
        warnings.warn(f"{args.mesh} is a bake (model {info['model']}, {info['material']}): its radiance is rendered "
                      f"as it is and {', '.join(ignored)} ignored (render the original mesh to bake anew)",
                      UserWarning, stacklevel=2)
    camera = parse_camera(args.camera, mesh, mesh.mm_per_unit)
    background = background_from_args(args)
    rgb, alpha = render_radiance(mesh, radiance, camera, args.width, args.height, args.spp, eta=eta)
    meta = {"material": info["material"] or f"unknown (eta {eta:g})", "lights": "as baked into the input",
            "camera": camera.describe(), "mesh": str(args.mesh), "model": f"{info['model']} (baked)",
            "units": "radiance W/(mm^2 sr) per unit light power/irradiance/intensity; lengths mm",
            "per_pixel": False, "baked_from": info["source"] or "unknown"}
    write_exr(exr, image_rgba(rgb, alpha), meta)
    write_png(png, display_rgba(rgb, alpha, operator=args.tonemap, bias=args.bias, background=background))
    if not args.quiet:
        print(f"rendered the radiance baked into {args.mesh} (model {info['model']}, {info['material']})")
        print(f"wrote {exr} and {png}")
    return 0
