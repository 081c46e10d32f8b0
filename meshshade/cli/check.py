"""``meshshade check MESH [--units U] [material]``: report what the pipeline will make of a mesh.

A thin layer over :func:`meshshade.check.check_mesh` (meshio pattern): load (mesh defects go into the report
instead of warning lines), optional material, report on stdout, ``--json FILE`` for the full report.


Its help and arguments are in :mod:`meshshade.cli.arguments.check`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

import warnings

from meshshade.check import check_mesh, format_check, report_to_json
from meshshade.cli.options import material_from_args, material_given
from meshshade.errors import MeshshadeError
from meshshade.geometry.mesh import MeshDefectWarning
from meshshade.io import check_output_path, load_mesh, write_text


def run_check(args) -> int:
    if args.json:
        check_output_path(args.json, [args.mesh], suffixes=(".json",), option="--json")
    cr = args.curvature_radius
    if cr is not None and not (cr > 0 and cr < float("inf")):
        raise MeshshadeError(f"--curvature-radius must be a positive number of mm, got {cr}")
    material = material_from_args(args) if material_given(args) else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshDefectWarning)  # listed in the report instead
        mesh = load_mesh(args.mesh, units=args.units)
        report = check_mesh(mesh, material, curvature_radius_mm=cr)  # curvature fallbacks: in the report too
    print(format_check(report))
    if args.json:
        write_text(args.json, report_to_json(report))
        if not args.quiet:
            print(f"wrote {args.json}")
    return 0
