"""``meshshade compare``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.compare`)."""
from __future__ import annotations

import argparse

from meshshade.cli.arguments.common import add_deprecated_alias, add_image_args, integer, number
from meshshade.names import DEFAULT_MODEL, MODELS

HELP = "two models, same camera and lights: split image, relative-difference heat map, stats.json"


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_image_args(p)
    p.add_argument("--models", default=f"{DEFAULT_MODEL},dipole",
                   help=f"two models A,B among {', '.join((*MODELS, 'mc'))} (default {DEFAULT_MODEL},dipole)")
    p.add_argument("--source-model", default=None, metavar="SM[,SM]",
                   help="what enters the medium, for both models or per model A,B (default: beam for volume, point "
                        "for the others): point (each surface model's point source at z_r) or beam (the near-field "
                        "model: single scattering plus the fitted beam sources, docs/physics.md §13); e.g. --models "
                        "curved,curved --source-model point,beam")
    add_deprecated_alias(p, "--near-field", "--source-model", metavar="SM[,SM]")
    p.add_argument("--floor", type=number, default=1e-3, help="relative radiance floor for the ratios")
    p.add_argument("--photons", type=integer(16), default=100_000, help="photons when one model is mc (default 1e5)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
