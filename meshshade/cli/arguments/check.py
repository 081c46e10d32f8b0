"""``meshshade check``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.check`)."""
from __future__ import annotations

import argparse

from meshshade.cli.arguments.common import add_material_args, add_mesh_args, number

HELP = ("what the pipeline will make of a mesh: size in mm and transport lengths, defects, curvature, "
        "resolution, where first-order theory holds")


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_mesh_args(p)
    add_material_args(p)
    p.add_argument("--curvature-radius", type=number, default=None, metavar="MM",
                   help="neighbourhood for the curvature fit [mm] (default 2 mean edge lengths, as bake)")
    p.add_argument("--json", metavar="FILE", help="also write the full report as JSON")
