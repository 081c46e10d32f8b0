"""Command-line interface: ``main(argv=None) -> int`` and one small module per subcommand over the public API."""
from meshshade.cli.main import main

__all__ = ["main"]
