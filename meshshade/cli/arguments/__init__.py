"""The command line's light half: each subcommand's one-line ``HELP`` and ``add_arguments(parser)``, one module
per subcommand, the options they share in :mod:`meshshade.cli.arguments.common`.

Nothing here imports numpy, numba, scipy or trimesh, nor any meshshade module that does (only the standard
library, :mod:`meshshade.names` and :mod:`meshshade.material_presets`; ``tests/cli/test_startup.py`` checks it), so
:mod:`meshshade.cli.main` builds the whole parser, answers ``--help`` and argument errors and installs its signal
handling in a tenth of a second. What a command does is in ``meshshade.cli.<command>`` (``run_<command>(args)``),
imported by :func:`meshshade.cli.main.load_command` once its arguments are parsed.
"""
from meshshade.cli.arguments import bake, batch, bench, blender, check, compare, demo, materials, mc, profile, render

#: subcommand name -> its arguments module (``HELP``, ``add_arguments``), in the order ``meshshade --help`` lists
#: them; each runs in ``meshshade.cli.<name>`` (``run_<name>``)
COMMANDS = {"mc": mc, "bake": bake, "profile": profile, "check": check, "materials": materials, "render": render,
            "compare": compare, "demo": demo, "bench": bench, "batch": batch, "blender": blender}

__all__ = ["COMMANDS"]
