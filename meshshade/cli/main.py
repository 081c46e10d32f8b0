"""Command-line interface: a thin layer over the Python API (meshio pattern).

``main(argv=None) -> int``; one module per subcommand with an ``add_<cmd>_args`` / ``run_<cmd>`` pair and its
one-line ``HELP`` (:data:`COMMANDS`), shared options in :mod:`meshshade.cli.options`. Only
:class:`~meshshade.errors.MeshshadeError` is caught: one line on stderr and exit code 2; warnings are one line
each (``meshshade: warning: ...``); Ctrl-C is one line and exit code 130.
"""
from __future__ import annotations

import argparse
import logging
import sys
import warnings

from meshshade import __version__
from meshshade.cli import bake, bench, check, compare, demo, mc, profile, render
from meshshade.errors import MeshshadeError

#: subcommand name -> (add_<cmd>_args, run_<cmd>, one-line help), in the order ``meshshade --help`` lists them
COMMANDS = {
    "mc": (mc.add_mc_args, mc.run_mc, mc.HELP),
    "bake": (bake.add_bake_args, bake.run_bake, bake.HELP),
    "profile": (profile.add_profile_args, profile.run_profile, profile.HELP),
    "check": (check.add_check_args, check.run_check, check.HELP),
    "render": (render.add_render_args, render.run_render, render.HELP),
    "compare": (compare.add_compare_args, compare.run_compare, compare.HELP),
    "demo": (demo.add_demo_args, demo.run_demo, demo.HELP),
    "bench": (bench.add_bench_args, bench.run_bench, bench.HELP),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="meshshade",
        description="Curvature-aware diffusion shading of translucent meshes (lengths in mm, coefficients 1/mm).")
    parser.add_argument("--verbose", "-v", action="store_true", help="log what is computed and chosen")
    parser.add_argument("--version", action="version", version="meshshade " + __version__)
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
