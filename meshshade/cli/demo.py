"""``meshshade demo``: the README's images into one folder (thin layer over :func:`meshshade.demo.run_demo`)."""
from __future__ import annotations

import argparse

from meshshade.demo import run_demo as make_demo
from meshshade.io import output_dir

HELP = "the README's images (paper's Figure 1 corrected, profiles, a pebble) into ./meshshade-demo"


def add_demo_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="meshshade-demo", metavar="DIR", help="output folder (default ./meshshade-demo)")
    p.add_argument("--small", action="store_true", help="reduced sizes (CI): small images, coarse pebble")


def run_demo(args) -> int:
    make_demo(output_dir(args.out), small=args.small)
    return 0
