"""Command-line interface: :func:`meshshade.cli.main.main` (``main(argv=None) -> int``, the ``meshshade`` console
script) and one small module per subcommand over the public API, shared options in :mod:`meshshade.cli.options`.
"""
