"""`meshshade mc`: Monte Carlo reference random walk inside a mesh (thin layer over meshshade.montecarlo.simulate)."""
from __future__ import annotations

import argparse

from meshshade.errors import MeshshadeError


def add_mc_args(p: argparse.ArgumentParser) -> None:
    from meshshade.cli.main import LIGHT_HELP, add_material_args, add_mesh_args  # noqa: PLC0415

    add_mesh_args(p)
    add_material_args(p, with_g=True)
    p.add_argument("--light", action="append", required=True, metavar="SPEC", help=LIGHT_HELP)
    p.add_argument("--photons", type=int, default=None, metavar="N", help="photons per channel (default 100000)")
    p.add_argument("--time-budget", type=float, default=None, metavar="SECONDS",
                   help="wall-clock budget (with --photons: whichever comes first): emission stops when the photons "
                        "in flight are predicted to finish in time; at 1.25x the budget the rest are cut off and "
                        "reported as 'lost'")
    p.add_argument("--pool", type=int, default=None, metavar="N",
                   help="photons walked together (default 262144; results do not depend on it beyond rounding)")
    p.add_argument("--seed", type=int, default=0, help="random seed (same seed, same result)")
    p.add_argument("--out", required=True, metavar="OUT.ply",
                   help="PLY with radiance_r/g/b (W/mm^2), stderr_r/g/b and tone-mapped red/green/blue")
    p.add_argument("--npz", metavar="OUT.npz", help="also save face/vertex powers, stderrs, beam distance")
    p.add_argument("--summary", metavar="OUT.json", help="totals with standard errors, photons, events, seconds")


def run_mc(args) -> int:
    from meshshade import io  # noqa: PLC0415
    from meshshade.light import samples as lights  # noqa: PLC0415
    from meshshade.montecarlo import simulate as montecarlo  # noqa: PLC0415
    from meshshade.cli.main import mesh_and_material  # noqa: PLC0415

    outs = [o for o in (args.out, args.npz, args.summary) if o]
    for i, o in enumerate(outs):
        io.check_output_path(o, [args.mesh, *outs[:i]])
    photons = args.photons if args.photons is not None else (None if args.time_budget else 100_000)
    if (photons is not None and photons < 16) or (args.time_budget is not None and args.time_budget <= 0):
        raise MeshshadeError("--photons must be >= 16 and --time-budget > 0")
    if args.pool is not None and args.pool < 1:
        raise MeshshadeError(f"--pool must be >= 1, got {args.pool}")
    if args.seed < 0:
        raise MeshshadeError(f"--seed must be >= 0, got {args.seed}")
    mesh, material = mesh_and_material(args)
    light_list = [lights.parse_light_spec(s, mm_per_unit=mesh.mm_per_unit) for s in args.light]
    result = montecarlo.simulate(mesh, material, light_list, photons=photons, seed=args.seed,
                                 time_budget=args.time_budget, pool=args.pool, progress=not args.quiet)
    montecarlo.write_mc(result, mesh, args.out, npz=args.npz, summary=args.summary)
    if not args.quiet:
        print(montecarlo.describe_mc(result))
        print("wrote " + ", ".join(outs))
    return 0
