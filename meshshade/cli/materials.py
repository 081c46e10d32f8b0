"""``meshshade materials``: every measured preset with its coefficients, albedo, z_r, diffusion length and colour
(thin layer over :func:`meshshade.materials.preset_table` and :mod:`meshshade.output.materials_table`)."""
from __future__ import annotations

import argparse

from meshshade.io import check_output_path, write_figure, write_text
from meshshade.materials import preset_table
from meshshade.output.materials_table import materials_csv, materials_text, swatches_figure

HELP = "list the measured material presets (coefficients in 1/mm, albedo, z_r, diffusion length, colour)"


def add_materials_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--csv", metavar="FILE.csv", help="write the table as CSV")
    p.add_argument("--plot", metavar="FILE.png", help="draw swatches: each preset's colour as a flat half-space "
                                                      "under white light")


def run_materials(args) -> int:
    if args.csv:
        check_output_path(args.csv, suffixes=(".csv",), option="--csv")
    if args.plot:
        check_output_path(args.plot, [args.csv] if args.csv else [], option="--plot")
    rows = preset_table()
    if args.csv:
        write_text(args.csv, materials_csv(rows))
    if args.plot:
        write_figure(args.plot, swatches_figure(rows))
    if not (args.quiet and (args.csv or args.plot)):
        print(materials_text(rows), end="")
    return 0
