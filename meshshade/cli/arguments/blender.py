"""``meshshade blender``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.blender`)."""
from __future__ import annotations

import argparse

from meshshade.names import ADDON_MODULE

HELP = "write the Blender add-on file (install it from Blender's preferences; see docs/blender.md)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out", nargs="?", default=f"{ADDON_MODULE}.py", metavar="OUT.py",
                   help=f"the add-on file (default {ADDON_MODULE}.py; its name is the add-on's module name)")
