"""``meshshade compare``: two models, same camera and lights: split image, relative-difference heat map and
statistics (thin layer over :func:`meshshade.output.compare.run_comparison` and
:func:`meshshade.output.compare.save_comparison`).

Its help and arguments are in :mod:`meshshade.cli.arguments.compare`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

import json

from meshshade.cli.options import image_scene_from_args, surface_options_from_args
from meshshade.io import output_dir
from meshshade.montecarlo import MCOptions
from meshshade.output.compare import CompareOptions, check_models, run_comparison, save_comparison
from meshshade.output.tonemap import check_tonemap_options


def run_compare(args) -> int:
    sm = tuple(x.strip() for x in args.source_model.split(",") if x.strip()) if args.source_model else (None,)
    source_model = sm[0] if len(sm) == 1 else sm
    models = check_models(tuple(m.strip() for m in args.models.split(",") if m.strip()), source_model=source_model)
    options = CompareOptions(width=args.width, height=args.height, spp=args.spp, per_pixel=args.per_pixel,
                             floor=args.floor, source_model=source_model)
    surface = surface_options_from_args(args)   # each side takes its own model and source model
    mc = MCOptions(photons=args.photons)
    check_tonemap_options(args.tonemap, args.bias)
    scene = image_scene_from_args(args)
    out = output_dir(args.out)
    cmp = run_comparison(scene.mesh, scene.material, scene.lights, models, options, surface=surface, mc=mc,
                         camera=scene.camera, progress=False if args.quiet else "compare")
    for p in save_comparison(cmp, out, models=cmp["labels"], metadata=scene.metadata, operator=args.tonemap,
                             bias=args.bias, background=scene.background):
        if not args.quiet:
            print(f"wrote {p}")
    s = cmp["stats"]
    print(json.dumps({k: s[k] for k in ("max_rel_diff", "mean_rel_diff", "p95_rel_diff")}))
    return 0
