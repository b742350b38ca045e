"""The command line (``sa-daemon``): argparse in, a :class:`~..config.Config` and plain options out."""

from .main import build_parser, main

__all__ = ["build_parser", "main"]
