"""``meshshade blender``: write the Blender add-on file that Preferences > Add-ons > Install from Disk
takes (thin layer over :func:`meshshade.blender.addon_source`)."""
from __future__ import annotations

import argparse

from meshshade.blender import ADDON_MODULE, addon_source
from meshshade.io import check_output_path, write_text

HELP = "write the Blender add-on file (install it from Blender's preferences; see docs/blender.md)"


def add_blender_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("out", nargs="?", default=f"{ADDON_MODULE}.py", metavar="OUT.py",
                   help=f"the add-on file (default {ADDON_MODULE}.py; its name is the add-on's module name)")


def run_blender(args) -> int:
    out = check_output_path(args.out, suffixes=(".py",), option="OUT.py")
    write_text(out, addon_source())
    if not args.quiet:
        print(f"wrote {out}: in Blender, Edit > Preferences > Add-ons > Install from Disk..., then enable "
              f"'meshshade translucency' (meshshade itself must be installed in Blender's Python: docs/blender.md)")
    return 0
