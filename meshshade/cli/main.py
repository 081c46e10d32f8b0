"""Command-line interface: a thin layer over the Python API (meshio pattern).

``main(argv=None) -> int``; one ``add_<cmd>_args`` / ``run_<cmd>`` pair per subcommand. Only
:class:`~meshshade.errors.MeshshadeError` is caught: one line on stderr and exit code 2.
"""
from __future__ import annotations

import argparse
import logging
import sys
import warnings

import numpy as np

from meshshade.errors import MeshshadeError
from meshshade.materials import JENSEN_2001_PRESETS, material_from_options

log = logging.getLogger("meshshade")


# --- shared option helpers ---------------------------------------------------------------------------
def _floats(text: str, what: str, n: tuple[int, ...] | None = None) -> list[float]:
    try:
        vals = [float(x) for x in str(text).split(",") if x.strip() != ""]
    except ValueError:
        raise MeshshadeError(f"{what}: expected comma-separated numbers, got {text!r}") from None
    if not vals or (n is not None and len(vals) not in n):
        raise MeshshadeError(f"{what}: expected {' or '.join(map(str, n or (1,)))} value(s), got {text!r}")
    return vals


def add_material_args(p: argparse.ArgumentParser, *, with_g: bool = False) -> None:
    g = p.add_argument_group("material (a preset, or coefficients in 1/mm)")
    g.add_argument("--material", metavar="NAME",
                   help="measured preset of Jensen et al. 2001: " + ", ".join(sorted(JENSEN_2001_PRESETS)))
    g.add_argument("--sigma-s-prime", metavar="S", help="reduced scattering [1/mm]: one value or R,G,B")
    g.add_argument("--sigma-a", metavar="A", help="absorption [1/mm]: one value or R,G,B")
    g.add_argument("--eta", type=float, help="relative index of refraction (default 1.3)")
    if with_g:
        g.add_argument("--g", type=float, default=0.0, help="Henyey-Greenstein anisotropy (Monte Carlo only)")


def material_from_args(args):
    ss = _floats(args.sigma_s_prime, "--sigma-s-prime", (1, 3)) if args.sigma_s_prime is not None else None
    sa = _floats(args.sigma_a, "--sigma-a", (1, 3)) if args.sigma_a is not None else None
    if args.material is None and ss is None and sa is None:
        raise MeshshadeError("choose a material: --material NAME, or --sigma-s-prime and --sigma-a (1/mm)")
    return material_from_options(args.material, sigma_s_prime=ss, sigma_a=sa, eta=args.eta,
                                 g=getattr(args, "g", 0.0) or 0.0)


# --- profile -----------------------------------------------------------------------------------------
def add_profile_args(p: argparse.ArgumentParser) -> None:
    add_material_args(p)
    p.add_argument("--shape", default="plane", choices=["plane", "sphere", "cylinder", "saddle"],
                   help="surface the profile lives on (default plane); --k1/--k2 give any curvature pair")
    p.add_argument("--radius", metavar="MM", help="radius of sphere/cylinder/saddle [mm]; several: 5,10,50")
    p.add_argument("--k1", type=float, help="first principal curvature at the entry point [1/mm] (with --k2)")
    p.add_argument("--k2", type=float, help="second principal curvature [1/mm]; k > 0 is convex")
    p.add_argument("--azimuth", default="0", metavar="DEG",
                   help="exit direction from the first principal direction [deg]; several: 0,45,90")
    p.add_argument("--models", default="dipole,exact",
                   help="comma list among dipole,exact,curved,mc (default dipole,exact)")
    p.add_argument("--distances", metavar="LIST", help="geodesic distances [mm], e.g. 0.1,0.5,1")
    p.add_argument("--max-distance", type=float, default=None, metavar="MM",
                   help="with --samples: evenly spaced distances 0..MM (default 20 mm)")
    p.add_argument("--samples", type=int, default=41, metavar="N", help="number of distances (default 41)")
    p.add_argument("--rtol", type=float, default=1e-10, help="relative tolerance of the exact series")
    p.add_argument("--csv", metavar="FILE", help="write model,channel,distance_mm,reflectance_per_mm2 rows")
    p.add_argument("--plot", metavar="FILE.png", help="plot log reflectance vs geodesic distance")


def run_profile(args) -> int:
    from meshshade import profiles  # noqa: PLC0415
    from meshshade.output import report  # noqa: PLC0415

    material = material_from_args(args)
    models = [m.strip().lower() for m in args.models.split(",") if m.strip()]
    if args.distances is not None:
        distances = np.array(_floats(args.distances, "--distances"))
    else:
        if args.samples < 2:
            raise MeshshadeError("--samples must be at least 2")
        distances = np.linspace(0.0, 20.0 if args.max_distance is None else args.max_distance, args.samples)
    azimuths = _floats(args.azimuth, "--azimuth")
    if args.k1 is not None or args.k2 is not None:
        shapes = [profiles.Shape.make("point", k1=args.k1, k2=args.k2)]
    else:
        radii = _floats(args.radius, "--radius") if args.radius is not None else [None]
        shapes = [profiles.Shape.make(args.shape, r) for r in radii]
    rows = profiles.profile_rows(material, distances, models=models, shapes=shapes, azimuths_deg=azimuths,
                                 rtol=args.rtol)
    extra = (["radius_mm"] if len(shapes) > 1 else []) + (
        ["azimuth_deg"] if len(azimuths) > 1 or shapes[0].kind in ("cylinder", "saddle", "point") else [])
    if args.csv or args.plot:
        from meshshade import io  # noqa: PLC0415
    if args.csv:
        io.write_text(args.csv, report.profile_csv_text(rows, extra_columns=extra))
        print(f"wrote {args.csv}")
    if args.plot:
        io.write_figure(args.plot, report.profile_figure(rows, material=material, shapes=shapes))
        print(f"wrote {args.plot}")
    if not args.csv and not args.plot:
        print(report.format_profile_table(rows, material=material, extra_columns=extra))
    return 0


# --- bake ------------------------------------------------------------------------------------------------
LIGHT_HELP = ("light SPEC (repeatable), positions in the mesh's units: beam:ox,oy,oz:dx,dy,dz[:power W[:radius]] | "
              "directional:dx,dy,dz[:irradiance W/mm^2] | point:x,y,z[:intensity W/sr]")


def add_mesh_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("mesh", help="input mesh: OBJ, PLY, OFF, STL or GLB (never modified)")
    p.add_argument("--units", default="mm", help="length unit of the mesh file: mm, cm, m or in (default mm)")


def add_bake_args(p: argparse.ArgumentParser) -> None:
    add_mesh_args(p)
    add_material_args(p)
    p.add_argument("--light", action="append", required=True, metavar="SPEC", help=LIGHT_HELP)
    p.add_argument("--model", default="curved", choices=["dipole", "curved", "exact-sphere", "auto"],
                   help="transport kernel (default curved); auto picks per entry sample the cheapest kernel and "
                        "geodesic method the scene calls for and reports its choices (with --verbose)")
    p.add_argument("--cutoff-tol", type=float, default=1e-4,
                   help="neighbourhood radius: reflectance beyond it below this fraction (default 1e-4)")
    p.add_argument("--curvature-radius", type=float, default=None, metavar="MM",
                   help="neighbourhood for the curvature fit [mm] (default 2 mean edge lengths)")
    p.add_argument("--geodesic", default="exact", choices=["exact", "arc"],
                   help="geodesic distances: exact polyhedral (default) or arc (curvature-corrected chords: "
                        "~5x faster, 1e-4 on smooth meshes, 1-11 %% low on bumpy scans)")
    add_far_field_arg(p)
    p.add_argument("--out", required=True, metavar="OUT.ply",
                   help="PLY with radiance_r/g/b (W/mm^2) and tone-mapped red/green/blue vertex colours")
    p.add_argument("--npz", metavar="OUT.npz", help="also save radiance, k1, k2, d1, d2, beam distance")


def add_far_field_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--far-field", default=None, choices=["off", "clustered"],
                   help="directional/point lights: sum pairs beyond r_near (1 %% of the dipole's energy) by clusters "
                        "of the planar dipole (default: off; auto uses it where the surface is flat on the scale "
                        "of the cutoff)")


def mesh_and_material(args):
    from meshshade import io  # noqa: PLC0415
    from meshshade.transport import bake as transport  # noqa: PLC0415

    material = material_from_args(args)
    mesh = io.load_mesh(args.mesh, units=args.units)
    if not args.quiet:
        print(transport.describe_scale(mesh, material))
    return mesh, material


def run_bake(args) -> int:
    from meshshade import io  # noqa: PLC0415
    from meshshade.light import samples as lights  # noqa: PLC0415
    from meshshade.transport import bake as transport  # noqa: PLC0415

    io.check_output_path(args.out, [args.mesh])
    if args.npz:
        io.check_output_path(args.npz, [args.mesh, args.out])
    mesh, material = mesh_and_material(args)
    light_list = [lights.parse_light_spec(s, mm_per_unit=mesh.mm_per_unit) for s in args.light]
    result = transport.bake(mesh, material, light_list, model=args.model, cutoff_tol=args.cutoff_tol,
                            curvature_radius_mm=args.curvature_radius, progress=not args.quiet,
                            geodesic=args.geodesic, far_field=args.far_field)
    transport.write_bake(result, mesh, args.out, npz=args.npz)
    if not args.quiet:
        print(transport.describe_result(result))
        if result.plan is not None:
            print(result.plan.describe())
        print(f"wrote {args.out}" + (f" and {args.npz}" if args.npz else ""))
    return 0


# --- main --------------------------------------------------------------------------------------------
from meshshade.cli.mc import add_mc_args, run_mc  # noqa: E402  (lazy inside; no import cycle)

COMMANDS = {
    "mc": (add_mc_args, run_mc, "Monte Carlo reference: random walk inside the mesh, exitance with standard errors"),
    "bake": (add_bake_args, run_bake, "per-vertex radiance of a translucent mesh, written as a coloured PLY"),
    "profile": (add_profile_args, run_profile,
                "reflectance vs geodesic distance on a plane, sphere, cylinder, saddle or curvature pair"),
    "check": (lambda p: __import__("meshshade.cli.check", fromlist=["_"]).add_check_args(p),
              lambda a: __import__("meshshade.cli.check", fromlist=["_"]).run_check(a),
              "what the pipeline will make of a mesh: size in mm and transport lengths, defects, curvature, "
              "resolution, where first-order theory holds"),
    **__import__("meshshade.cli.images", fromlist=["_"]).IMAGE_COMMANDS,
    "bench": (lambda p: __import__("meshshade.cli.bench", fromlist=["_"]).add_bench_args(p), lambda a: __import__("meshshade.cli.bench", fromlist=["_"]).run_bench(a), "accuracy vs time of every model and knob against exact or Monte Carlo references"),  # noqa: E501
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="meshshade",
        description="Curvature-aware diffusion shading of translucent meshes (lengths in mm, coefficients 1/mm).")
    parser.add_argument("--verbose", "-v", action="store_true", help="log what is computed and chosen")
    parser.add_argument("--version", action="version", version="meshshade " + __import__("meshshade").__version__)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (add, _run, help_) in COMMANDS.items():
        sp = sub.add_parser(name, help=help_, description=help_)
        sp.add_argument("--quiet", "-q", action="store_true", help="no progress bars or notes")
        add(sp)
    return parser


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    print(f"meshshade: warning: {message}", file=sys.stderr)


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="meshshade: %(message)s")
    if args.command is None:
        parser.print_help()
        return 2
    _add, run, _help = COMMANDS[args.command]
    with warnings.catch_warnings():
        warnings.showwarning = _one_line_warning
        try:
            return run(args)
        except MeshshadeError as exc:
            print(f"meshshade: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("meshshade: interrupted; no partial output was left", file=sys.stderr)
            return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
