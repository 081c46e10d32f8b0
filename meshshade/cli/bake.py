"""``meshshade bake``: per-vertex radiance of a translucent mesh, written as a coloured PLY (thin layer over
:func:`meshshade.transport.baking.bake` and :func:`meshshade.output.bake_file.write_bake`)."""
from __future__ import annotations

import argparse

from meshshade.cli.options import (add_far_field_arg, add_geodesic_arg, add_light_arg, add_material_args, add_mesh_args,
                                   add_model_arg, add_near_field_arg, add_transport_arg, lights_from_args,
                                   mesh_and_material, number)
from meshshade.asset_cache import AssetCache
from meshshade.io import check_output_path
from meshshade.output.bake_file import BAKE_FORMATS, check_bake_output, write_bake
from meshshade.transport import bake, describe_result
from meshshade.transport.baking import check_bake_options

HELP = "per-vertex radiance of a translucent mesh, written as a coloured PLY, glTF/GLB or USD"


def add_bake_args(p: argparse.ArgumentParser) -> None:
    add_mesh_args(p)
    add_material_args(p)
    add_light_arg(p)
    add_model_arg(p)
    p.add_argument("--cutoff-tol", type=number, default=1e-4,
                   help="neighbourhood radius: reflectance beyond it below this fraction (default 1e-4)")
    p.add_argument("--curvature-radius", type=number, default=None, metavar="MM",
                   help="neighbourhood for the curvature fit [mm] (default 2 mean edge lengths)")
    add_geodesic_arg(p)
    add_far_field_arg(p)
    add_transport_arg(p)
    add_near_field_arg(p)
    p.add_argument("--out", required=True, metavar="OUT.ply|.glb|.gltf|.usd|.usda|.usdc",
                   help="the baked mesh, format from the extension: PLY with radiance_r/g/b (W/mm^2) and tone-mapped "
                        "red/green/blue; glTF/GLB with COLOR_0 and _RADIANCE; USD with displayColor and "
                        "primvars:meshshade:radiance")
    p.add_argument("--npz", metavar="OUT.npz", help="also save radiance, k1, k2, d1, d2, beam distance")


def run_bake(args) -> int:
    check_output_path(args.out, [args.mesh], suffixes=tuple(BAKE_FORMATS))
    check_bake_output(args.out)
    if args.npz:
        check_output_path(args.npz, [args.mesh, args.out], suffixes=(".npz",), option="--npz")
    check_bake_options(args.model, args.cutoff_tol, args.curvature_radius, args.geodesic, args.far_field,
                       transport=args.transport, near_field=args.near_field)
    lights = lights_from_args(args)
    mesh, material = mesh_and_material(args)
    result = bake(mesh, material, lights, model=args.model, cutoff_tol=args.cutoff_tol,
                  curvature_radius_mm=args.curvature_radius, progress=not args.quiet, geodesic=args.geodesic,
                  far_field=args.far_field, transport=args.transport, near_field=args.near_field,
                  volume_cache=AssetCache("volume"))
    write_bake(result, mesh, args.out, npz=args.npz, lights=lights)
    if not args.quiet:
        print(describe_result(result))
        if result.plan is not None:
            print(result.plan.describe())
        print(f"wrote {args.out}" + (f" and {args.npz}" if args.npz else ""))
    return 0
