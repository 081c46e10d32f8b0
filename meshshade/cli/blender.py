"""``meshshade blender``: write the Blender add-on file that Preferences > Add-ons > Install from Disk
takes (thin layer over :func:`meshshade.blender.addon_source`).

Its help and arguments are in :mod:`meshshade.cli.arguments.blender`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

from meshshade.blender import addon_source
from meshshade.io import check_output_path, write_text


def run_blender(args) -> int:
    out = check_output_path(args.out, suffixes=(".py",), option="OUT.py")
    write_text(out, addon_source())
    if not args.quiet:
        print(f"wrote {out}: in Blender, Edit > Preferences > Add-ons > Install from Disk..., then enable "
              f"'meshshade translucency' (meshshade itself must be installed in Blender's Python: docs/blender.md)")
    return 0
