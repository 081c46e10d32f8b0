"""``meshshade mc``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.mc`)."""
from __future__ import annotations

import argparse

from meshshade.cli.arguments.common import (add_albedo_map_args, add_cluster_args, add_light_arg, add_material_args, add_mesh_args, integer,
                                          number)

HELP = "Monte Carlo reference: random walk inside the mesh, exitance with standard errors"


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_mesh_args(p)
    add_material_args(p, with_g=True)
    add_albedo_map_args(p, note="; the walk takes at each collision the medium of the nearest surface point")
    add_light_arg(p)
    p.add_argument("--photons", type=integer(16), default=None, metavar="N",
                   help="photons per channel (default 100000; 1e5 or 100_000 notation accepted)")
    p.add_argument("--time-budget", type=number, default=None, metavar="SECONDS",
                   help="wall-clock budget (with --photons: whichever comes first): emission stops when the photons "
                        "in flight are predicted to finish in time; at 1.25x the budget the rest are cut off and "
                        "reported as 'lost'")
    p.add_argument("--pool", type=integer(1), default=None, metavar="N",
                   help="photons walked together (default 262144; results do not depend on it beyond rounding)")
    p.add_argument("--seed", type=integer(0), default=0, help="random seed (same seed, same result)")
    p.add_argument("--out", required=True, metavar="OUT.ply",
                   help="PLY with radiance_r/g/b (W/mm^2), stderr_r/g/b and tone-mapped red/green/blue")
    p.add_argument("--npz", metavar="OUT.npz", help="also save face/vertex powers, stderrs, beam distance")
    p.add_argument("--summary", metavar="OUT.json", help="totals with standard errors, photons, events, seconds")
    add_cluster_args(p)
