"""``meshshade profile``: reflectance against geodesic distance on a plane, sphere, cylinder, saddle, cavity, bore
or curvature pair (thin layer over :func:`meshshade.profiles.profile_rows` and :mod:`meshshade.output.report`).

Its help and arguments are in :mod:`meshshade.cli.arguments.profile`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

import numpy as np

from meshshade.cli.options import material_from_args, parse_floats
from meshshade.io import check_output_path, write_figure, write_text
from meshshade.output.report import format_profile_table, profile_csv_text, profile_figure
from meshshade.profiles import Shape, profile_distances, profile_rows


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
                        source_model=[x.strip() for x in args.source_model.split(",") if x.strip()])
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
