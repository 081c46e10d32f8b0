"""``meshshade mc``: Monte Carlo reference random walk inside a mesh (thin layer over
:func:`meshshade.montecarlo.simulation.simulate` and :func:`meshshade.output.mc_file.write_mc`); with
``--workers N`` or ``--scheduler ADDRESS`` the photons are split across Dask workers (the same result);
``--albedo-map`` and ``--radius-map`` paint the material as ``meshshade bake`` does (a varying medium, walked in
this process).

Its help and arguments are in :mod:`meshshade.cli.arguments.mc`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

import contextlib

from meshshade.batch.dask_cluster import check_cluster_options, open_client
from meshshade.cli.options import is_painted, lights_from_args, mesh_and_material, painted_material
from meshshade.errors import MeshshadeError
from meshshade.io import check_output_path
from meshshade.montecarlo import MCOptions, describe_mc, simulate
from meshshade.output.mc_file import write_mc


def run_mc(args) -> int:
    outs = [(o, option, suffix) for o, option, suffix in
            ((args.out, "--out", ".ply"), (args.npz, "--npz", ".npz"), (args.summary, "--summary", ".json")) if o]
    for i, (o, option, suffix) in enumerate(outs):
        check_output_path(o, [args.mesh, *(x for x, _, _ in outs[:i])], suffixes=(suffix,), option=option)
    photons = args.photons if args.photons is not None else (None if args.time_budget else 100_000)
    options = MCOptions(photons=photons, seed=args.seed, time_budget=args.time_budget, pool=args.pool)
    split = args.scheduler is not None or args.workers is not None
    check_cluster_options(args.scheduler, args.workers)
    if split and args.time_budget is not None:
        raise MeshshadeError("--time-budget cannot be split across Dask workers (the split needs a photon count); "
                             "give --photons without --time-budget")
    lights = lights_from_args(args)
    mesh, material = mesh_and_material(args)
    if is_painted(args):        # the same painting as meshshade bake's
        material = painted_material(args, mesh, material)
    with contextlib.ExitStack() as stack:
        client = stack.enter_context(open_client(args.scheduler, args.workers, quiet=args.quiet)) if split else None
        result = simulate(mesh, material, lights, options, progress=not args.quiet, client=client)
    write_mc(result, mesh, args.out, npz=args.npz, summary=args.summary)
    if not args.quiet:
        print(describe_mc(result))
        print("wrote " + ", ".join(o for o, _, _ in outs))
    return 0
