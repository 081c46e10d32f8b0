"""``meshshade render``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.render`)."""
from __future__ import annotations

import argparse

from meshshade.cli.arguments.common import add_albedo_map_args, add_image_args, add_model_arg, add_source_model_arg

HELP = "render a mesh's shading: linear EXR (with metadata) and tone-mapped PNG"
BAKED_EPILOG = ("A PLY written by 'meshshade bake' is rendered as it is (its radiance, units and material's eta): "
                "no --material or --light is needed, and material, light and model options are ignored. Any other "
                "mesh is baked first, with the material, lights and model given.")


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_image_args(p)
    add_albedo_map_args(p, note="; volume model only")
    add_model_arg(p)
    add_source_model_arg(p)
    p.add_argument("--out", required=True, metavar="OUT[.exr|.png]", help="writes OUT.exr (linear) and OUT.png")
    p.epilog = BAKED_EPILOG
