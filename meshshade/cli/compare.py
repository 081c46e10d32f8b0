"""``meshshade compare``: two models, same camera and lights: split image, relative-difference heat map and
statistics (thin layer over :func:`meshshade.output.compare.run_comparison` and
:func:`meshshade.output.compare.save_comparison`).

Its help and arguments are in :mod:`meshshade.cli.arguments.compare`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

import json

from meshshade.cli.options import image_scene_from_args
from meshshade.io import output_dir
from meshshade.output.compare import check_floor, check_models, run_comparison, save_comparison
from meshshade.output.render import check_image_size
from meshshade.output.tonemap import check_tonemap_options


def run_compare(args) -> int:
    sm = tuple(x.strip() for x in args.source_model.split(",") if x.strip()) if args.source_model else (None,)
    source_model = sm[0] if len(sm) == 1 else sm
    models = check_models(tuple(m.strip() for m in args.models.split(",") if m.strip()), source_model=source_model)
    check_floor(args.floor)
    check_image_size(args.width, args.height, args.spp)
    check_tonemap_options(args.tonemap, args.bias)
    scene = image_scene_from_args(args)
    out = output_dir(args.out)
    cmp = run_comparison(scene.mesh, scene.material, scene.lights, models, camera=scene.camera, width=args.width,
                         height=args.height, spp=args.spp, per_pixel=args.per_pixel, cutoff_tol=args.cutoff_tol,
                         floor=args.floor, mc_photons=args.photons, geodesic=args.geodesic,
                         far_field=args.far_field, transport=args.transport,
                         progress=False if args.quiet else "compare", source_model=source_model)
    for p in save_comparison(cmp, out, models=cmp["labels"], metadata=scene.metadata, operator=args.tonemap,
                             bias=args.bias, background=scene.background):
        if not args.quiet:
            print(f"wrote {p}")
    s = cmp["stats"]
    print(json.dumps({k: s[k] for k in ("max_rel_diff", "mean_rel_diff", "p95_rel_diff")}))
    return 0
