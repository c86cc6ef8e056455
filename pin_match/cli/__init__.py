"""The ``pin-match`` command line: thin, over the same functions the notebooks call (``main`` is the entry point)."""

from pin_match.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
