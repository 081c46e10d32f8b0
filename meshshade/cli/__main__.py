"""``python -m meshshade.cli``: the same entry point as the ``meshshade`` console script."""
import sys

from meshshade.cli.main import main

sys.exit(main())
