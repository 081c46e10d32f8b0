"""``python -m meshshade.cli``: the same entry point as the ``meshshade`` console script (guarded: a process that
the demo spawns imports this module as ``__mp_main__`` and must not run the command again)."""
import sys

from meshshade.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
