"""``meshshade demo``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.demo`)."""
from __future__ import annotations

import argparse

HELP = "the README's images (paper's Figure 1 corrected, profiles, a pebble) into ./meshshade-demo"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="meshshade-demo", metavar="DIR", help="output folder (default ./meshshade-demo)")
    p.add_argument("--small", action="store_true", help="reduced sizes (CI): small images, coarse pebble")
