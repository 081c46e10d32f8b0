"""``meshshade materials``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.materials`)."""
from __future__ import annotations

import argparse

HELP = "list the measured material presets (coefficients in 1/mm, albedo, z_r, diffusion length, colour)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--csv", metavar="FILE.csv", help="write the table as CSV")
    p.add_argument("--plot", metavar="FILE.png", help="draw swatches: each preset's colour as a flat half-space "
                                                      "under white light")
