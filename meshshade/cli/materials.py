"""``meshshade materials``: every measured preset with its coefficients, albedo, z_r, diffusion length and colour
(thin layer over :func:`meshshade.materials.preset_table` and :mod:`meshshade.output.materials_table`).

Its help and arguments are in :mod:`meshshade.cli.arguments.materials`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

from meshshade.io import check_output_path, write_figure, write_text
from meshshade.materials import preset_table
from meshshade.output.materials_table import materials_csv, materials_text, swatches_figure


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
