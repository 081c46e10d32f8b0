"""``meshshade render``: bake, then render the mesh: linear EXR (with metadata) and tone-mapped PNG (thin layer
over :func:`meshshade.transport.baking.bake` and :mod:`meshshade.output.render`)."""
from __future__ import annotations

import argparse
from pathlib import Path

from meshshade.cli.options import add_image_args, add_model_arg, image_scene_from_args
from meshshade.io import check_output_path, write_exr, write_png
from meshshade.output.render import PixelGather, display_rgba, image_rgba, render_radiance
from meshshade.transport import bake, describe_result

HELP = "render a baked mesh: linear EXR (with metadata) and tone-mapped PNG"


def add_render_args(p: argparse.ArgumentParser) -> None:
    add_image_args(p)
    add_model_arg(p)
    p.add_argument("--out", required=True, metavar="OUT[.exr|.png]", help="writes OUT.exr (linear) and OUT.png")


def run_render(args) -> int:
    base = Path(args.out)
    base = base.with_suffix("") if base.suffix.lower() in (".exr", ".png") else base
    exr, png = base.with_name(base.name + ".exr"), base.with_name(base.name + ".png")
    scene = image_scene_from_args(args)
    check_output_path(exr, [args.mesh])
    check_output_path(png, [args.mesh])
    mesh, material = scene.mesh, scene.material
    res = bake(mesh, material, scene.lights, model=args.model, cutoff_tol=args.cutoff_tol, geodesic=args.geodesic,
               far_field=args.far_field)
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
