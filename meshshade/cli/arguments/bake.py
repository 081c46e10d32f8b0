"""``meshshade bake``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.bake`)."""
from __future__ import annotations

import argparse

from meshshade.cli.arguments.common import (add_albedo_map_args, add_far_field_arg, add_geodesic_arg, add_light_arg, add_material_args,
                                          add_mesh_args, add_model_arg, add_source_model_arg, add_transport_arg, number)

HELP = "per-vertex radiance of a translucent mesh, written as a coloured PLY, glTF/GLB or USD"


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_mesh_args(p)
    add_material_args(p)
    add_albedo_map_args(p, note="; volume model only")
    add_light_arg(p)
    add_model_arg(p)
    p.add_argument("--cutoff-tol", type=number, default=1e-4,
                   help="neighbourhood radius: reflectance beyond it below this fraction (default 1e-4)")
    p.add_argument("--curvature-radius", type=number, default=None, metavar="MM",
                   help="neighbourhood for the curvature fit [mm] (default 2 mean edge lengths)")
    add_geodesic_arg(p)
    add_far_field_arg(p)
    add_transport_arg(p)
    add_source_model_arg(p)
    p.add_argument("--out", metavar="OUT.ply|.glb|.gltf|.usd|.usda|.usdc",
                   help="the baked mesh, format from the extension: PLY with radiance_r/g/b (W/mm^2) and tone-mapped "
                        "red/green/blue; glTF/GLB with COLOR_0 and _RADIANCE (with --texture: the texture bound as "
                        "emissive); USD with displayColor and primvars:meshshade:radiance")
    p.add_argument("--npz", metavar="OUT.npz", help="also save radiance, k1, k2, d1, d2, beam distance")
    p.add_argument("--texture", metavar="OUT.exr",
                   help="also (or instead of --out) bake into a texture of the mesh's UV map (OBJ vt, glTF TEXCOORD_0, "
                        "PLY s/t or u/v; an automatic atlas when it has none, written as OUT.obj): linear exitance "
                        "W/mm^2 as float OpenEXR and tone-mapped as OUT.png")
    p.add_argument("--texture-size", type=int, default=2048, metavar="N",
                   help="texels per side of the texture (default 2048)")
    p.add_argument("--padding", type=int, default=16, metavar="N",
                   help="texels around each UV island filled from its border, against bleeding in filtering and "
                        "mipmaps (default 16)")
    p.add_argument("--texture-refine", default="auto", metavar="auto|N",
                   help="segments per edge of the surface the texture bake solves on (default auto: the mesh as it "
                        "is for the volume model, which samples the surface itself; for the surface models the mesh "
                        "split until its edges are about what the material resolves; 1: the mesh as it is)")
