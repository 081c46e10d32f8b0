"""``meshshade check MESH [--units U] [material]``: report what the pipeline will make of a mesh.

A thin layer over :func:`meshshade.check.check_mesh` (meshio pattern): load (mesh defects go into the report
instead of warning lines), optional material, report on stdout, ``--json FILE`` for the full report.
"""
from __future__ import annotations

import warnings


def add_check_args(p) -> None:
    from meshshade.cli.main import add_material_args, add_mesh_args  # noqa: PLC0415 - cli imports this module lazily

    add_mesh_args(p)
    add_material_args(p)
    p.add_argument("--curvature-radius", type=float, default=None, metavar="MM",
                   help="neighbourhood for the curvature fit [mm] (default 2 mean edge lengths, as bake)")
    p.add_argument("--json", metavar="FILE", help="also write the full report as JSON")


def run_check(args) -> int:
    from meshshade import io  # noqa: PLC0415
    from meshshade.check import check_mesh, format_check, report_to_json  # noqa: PLC0415
    from meshshade.cli.main import material_from_args  # noqa: PLC0415
    from meshshade.errors import MeshshadeError  # noqa: PLC0415
    from meshshade.geometry.mesh import MeshDefectWarning  # noqa: PLC0415

    if args.json:
        io.check_output_path(args.json, [args.mesh])
    cr = args.curvature_radius
    if cr is not None and not (cr > 0 and cr < float("inf")):
        raise MeshshadeError(f"--curvature-radius must be a positive number of mm, got {cr}")
    given = args.material is not None or args.sigma_s_prime is not None or args.sigma_a is not None
    material = material_from_args(args) if given else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshDefectWarning)  # listed in the report instead
        mesh = io.load_mesh(args.mesh, units=args.units)
        report = check_mesh(mesh, material, curvature_radius_mm=cr)  # curvature fallbacks: in the report too
    print(format_check(report))
    if args.json:
        io.write_text(args.json, report_to_json(report))
        if not args.quiet:
            print(f"wrote {args.json}")
    return 0
