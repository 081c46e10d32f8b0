"""CLI subcommands that make images: ``render``, ``compare``, ``demo`` (thin layers over render/compare/demo)."""
from __future__ import annotations

import argparse
from pathlib import Path

from meshshade.errors import MeshshadeError


def _add_image_args(p: argparse.ArgumentParser) -> None:
    from meshshade.cli.main import LIGHT_HELP, add_material_args, add_mesh_args  # noqa: PLC0415

    add_mesh_args(p)
    add_material_args(p)
    p.add_argument("--light", action="append", required=True, metavar="SPEC", help=LIGHT_HELP)
    p.add_argument("--cutoff-tol", type=float, default=1e-4, help="neighbourhood tolerance (default 1e-4)")
    p.add_argument("--width", type=int, default=512)
    p.add_argument("--height", type=int, default=512)
    p.add_argument("--spp", type=int, default=4, help="samples per pixel, jittered strata (default 4)")
    p.add_argument("--camera", default="auto", help="auto[:dx,dy,dz] (default, view along -z) | "
                   "persp:ex,ey,ez:tx,ty,tz:ux,uy,uz:FOV_DEG | ortho:eye:target:up:HEIGHT (mesh units)")
    p.add_argument("--background", default="transparent", help="transparent (PNG alpha) or R,G,B in [0, 1]")
    p.add_argument("--tonemap", default="drago", choices=["drago", "exposure"], help="PNG tone mapping")
    p.add_argument("--bias", type=float, default=0.85, help="Drago bias (default 0.85)")
    p.add_argument("--geodesic", default="exact", choices=["exact", "arc"],
                   help="geodesic distances of the bake: exact polyhedral (default) or arc (faster, smooth meshes)")
    from meshshade.cli.main import add_far_field_arg  # noqa: PLC0415
    add_far_field_arg(p)
    p.add_argument("--per-pixel", action="store_true",
                   help="gather the kernel at every pixel sample (exact peaks; slower) instead of interpolating")


def _setup(args):
    from meshshade import io  # noqa: PLC0415
    from meshshade.light import samples as lights  # noqa: PLC0415
    from meshshade.output import render  # noqa: PLC0415
    from meshshade.cli.main import _floats, mesh_and_material  # noqa: PLC0415

    mesh, material = mesh_and_material(args)
    light_list = [lights.parse_light_spec(s, mm_per_unit=mesh.mm_per_unit) for s in args.light]
    camera = render.parse_camera(args.camera, mesh, mesh.mm_per_unit)
    bg = None if args.background == "transparent" else _floats(args.background, "--background", (3,))
    meta = {"material": material.describe(), "lights": "; ".join(args.light), "camera": camera.describe(),
            "units": "radiance W/(mm^2 sr) per unit light power/irradiance/intensity; lengths mm",
            "mesh": str(args.mesh)}
    return io, mesh, material, light_list, camera, bg, meta


def add_render_args(p: argparse.ArgumentParser) -> None:
    _add_image_args(p)
    p.add_argument("--model", default="curved", choices=["dipole", "curved", "exact-sphere", "auto"],
                   help="transport kernel (default curved; auto: per entry sample what the scene calls for)")
    p.add_argument("--out", required=True, metavar="OUT[.exr|.png]", help="writes OUT.exr (linear) and OUT.png")


def run_render(args) -> int:
    from meshshade.output import render  # noqa: PLC0415
    from meshshade.transport import bake as transport  # noqa: PLC0415

    base = Path(args.out)
    base = base.with_suffix("") if base.suffix.lower() in (".exr", ".png") else base
    exr, png = base.with_name(base.name + ".exr"), base.with_name(base.name + ".png")
    io, mesh, material, light_list, camera, bg, meta = _setup(args)
    io.check_output_path(exr, [args.mesh]), io.check_output_path(png, [args.mesh])
    res = transport.bake(mesh, material, light_list, model=args.model, cutoff_tol=args.cutoff_tol,
                         geodesic=args.geodesic, far_field=args.far_field)
    ex = render.PixelGather(mesh, res) if args.per_pixel else None
    rgb, alpha = render.render_radiance(mesh, res.radiance, camera, args.width, args.height, args.spp,
                                        eta=material.eta, exitance_at=ex)
    decisions = {"auto_decisions": res.plan.describe()} if res.plan is not None else {}
    io.write_exr(exr, render.image_rgba(rgb, alpha), {**meta, "model": args.model,
                                                      "per_pixel": bool(args.per_pixel), **decisions})
    io.write_png(png, render.display_rgba(rgb, alpha, operator=args.tonemap, bias=args.bias, background=bg))
    if not args.quiet:
        print(transport.describe_result(res))
    print(f"wrote {exr} and {png}")
    return 0


def add_compare_args(p: argparse.ArgumentParser) -> None:
    _add_image_args(p)
    p.add_argument("--models", default="curved,dipole",
                   help="two models A,B among dipole, curved, exact-sphere, auto, mc (default curved,dipole)")
    p.add_argument("--floor", type=float, default=1e-3, help="relative radiance floor for the ratios")
    p.add_argument("--photons", type=int, default=100_000, help="photons when one model is mc (default 1e5)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")


def run_compare(args) -> int:
    import json  # noqa: PLC0415

    from meshshade.output import compare  # noqa: PLC0415

    models = tuple(m.strip() for m in args.models.split(",") if m.strip())
    if len(models) != 2:
        raise MeshshadeError(f"--models needs two models A,B, got {args.models!r}")
    io, mesh, material, light_list, camera, bg, meta = _setup(args)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise MeshshadeError(f"--out {out} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    cmp = compare.run_comparison(mesh, material, light_list, models, camera=camera, width=args.width,
                                 height=args.height, spp=args.spp, per_pixel=args.per_pixel,
                                 cutoff_tol=args.cutoff_tol, floor=args.floor, mc_photons=args.photons,
                                 geodesic=args.geodesic, far_field=args.far_field)
    for p in compare.save_comparison(cmp, out, models=models, metadata=meta, operator=args.tonemap,
                                     bias=args.bias, background=bg):
        print(f"wrote {p}")
    s = cmp["stats"]
    print(json.dumps({k: s[k] for k in ("max_rel_diff", "mean_rel_diff", "p95_rel_diff")}))
    return 0


def add_demo_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="meshshade-demo", metavar="DIR", help="output folder (default ./meshshade-demo)")
    p.add_argument("--small", action="store_true", help="reduced sizes (CI): small images, coarse pebble")


def run_demo(args) -> int:
    from meshshade import demo  # noqa: PLC0415

    demo.run_demo(args.out, small=args.small)
    return 0


#: registered in cli.COMMANDS
IMAGE_COMMANDS = {
    "render": (add_render_args, run_render, "render a baked mesh: linear EXR (with metadata) and tone-mapped PNG"),
    "compare": (add_compare_args, run_compare,
                "two models, same camera and lights: split image, relative-difference heat map, stats.json"),
    "demo": (add_demo_args, run_demo, "the README's images (paper's Figure 1 corrected, profiles, a pebble) "
             "into ./meshshade-demo"),
}
