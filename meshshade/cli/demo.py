"""``meshshade demo``: the README's images into one folder (thin layer over :func:`meshshade.demo.run_demo`).

Its help and arguments are in :mod:`meshshade.cli.arguments.demo`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

from meshshade.demo import run_demo as make_demo
from meshshade.io import output_dir


def run_demo(args) -> int:
    make_demo(output_dir(args.out), small=args.small)
    return 0
