"""``meshshade profile``: reflectance against geodesic distance on a plane, sphere, cylinder, saddle, cavity, bore
or curvature pair (thin layer over :func:`meshshade.profiles.profile_rows` and :mod:`meshshade.output.report`)."""
from __future__ import annotations

import argparse

import numpy as np

from meshshade.cli.options import add_material_args, integer, material_from_args, number, parse_floats
from meshshade.io import check_output_path, write_figure, write_text
from meshshade.output.report import format_profile_table, profile_csv_text, profile_figure
from meshshade.profiles import MC_PHOTONS, SHAPES, Shape, profile_distances, profile_rows

HELP = "reflectance vs geodesic distance on a plane, sphere, cylinder, saddle, cavity, bore or curvature pair"


def add_profile_args(p: argparse.ArgumentParser) -> None:
    add_material_args(p)
    p.add_argument("--shape", default="plane", choices=[s for s in SHAPES if s != "point"],
                   help="surface the profile lives on (default plane; cavity: the medium outside a ball, bore: "
                        "outside a cylinder); --k1/--k2 give any curvature pair")
    p.add_argument("--radius", metavar="MM", help="radius of sphere/cylinder/saddle/cavity/bore [mm]; several: 5,10,50")
    p.add_argument("--k1", type=number, help="first principal curvature at the entry point [1/mm] (with --k2)")
    p.add_argument("--k2", type=number, help="second principal curvature [1/mm]; k > 0 is convex")
    p.add_argument("--azimuth", default="0", metavar="DEG",
                   help="exit direction from the first principal direction [deg]; several: 0,45,90")
    p.add_argument("--models", default="dipole,exact",
                   help="comma list among dipole,exact,curved,fitted,mc (default dipole,exact); fitted: the "
                        "curvature model fitted to Monte Carlo; mc: Monte Carlo on the exact plane, sphere, "
                        "cylinder, cavity or bore, with error bars")
    p.add_argument("--near-field", default="point", metavar="NF[,NF]",
                   help="what enters the medium: point (each model's point source at z_r; default), beam (single "
                        "scattering plus the fitted beam sources, composed with the model's geometry, docs/physics.md "
                        "§13), or point,beam for both curves (named model+beam)")
    p.add_argument("--distances", metavar="LIST", help="geodesic distances [mm], e.g. 0.1,0.5,1")
    p.add_argument("--max-distance", type=number, default=None, metavar="MM",
                   help="with --samples: evenly spaced distances 0..MM (default 20 mm)")
    p.add_argument("--samples", type=integer(2), default=41, metavar="N", help="number of distances (default 41)")
    p.add_argument("--rtol", type=number, default=1e-10, help="relative tolerance of the exact series")
    p.add_argument("--photons", type=integer(16), default=MC_PHOTONS, metavar="N",
                   help=f"Monte Carlo photons per channel for --models mc (default {MC_PHOTONS:.0e})")
    p.add_argument("--seed", type=integer(0), default=0, help="Monte Carlo seed (default 0)")
    p.add_argument("--csv", metavar="FILE", help="write model,channel,distance_mm,reflectance_per_mm2 rows "
                                                 "(and stderr_per_mm2 with mc)")
    p.add_argument("--plot", metavar="FILE.png", help="plot log reflectance vs geodesic distance")


def run_profile(args) -> int:
    for path, option in ((args.csv, "--csv"), (args.plot, "--plot")):
        if path:
            check_output_path(path, option=option)
    material = material_from_args(args)
    models = [m.strip().lower() for m in args.models.split(",") if m.strip()]
    if args.distances is not None:
        distances = np.array(parse_floats(args.distances, "--distances"))
    else:
        distances = profile_distances(20.0 if args.max_distance is None else args.max_distance, args.samples)
    azimuths = parse_floats(args.azimuth, "--azimuth")
    if args.k1 is not None or args.k2 is not None:
        shapes = [Shape.make("point", k1=args.k1, k2=args.k2)]
    else:
        radii = parse_floats(args.radius, "--radius") if args.radius is not None else [None]
        shapes = [Shape.make(args.shape, r) for r in radii]
    rows = profile_rows(material, distances, models=models, shapes=shapes, azimuths_deg=azimuths,
                        rtol=args.rtol, photons=args.photons, seed=args.seed,
                        near_field=[x.strip() for x in args.near_field.split(",") if x.strip()])
    extra = (["radius_mm"] if len(shapes) > 1 else []) + (
        ["azimuth_deg"] if len(azimuths) > 1 or shapes[0].kind in ("cylinder", "saddle", "point") else [])
    if args.csv:
        write_text(args.csv, profile_csv_text(rows, extra_columns=extra))
        if not args.quiet:
            print(f"wrote {args.csv}")
    if args.plot:
        write_figure(args.plot, profile_figure(rows, material=material, shapes=shapes))
        if not args.quiet:
            print(f"wrote {args.plot}")
    if not args.csv and not args.plot:
        print(format_profile_table(rows, material=material, extra_columns=extra))
    return 0
