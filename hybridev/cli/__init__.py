"""The ``hybridev`` command-line interface (top layer): :func:`main` and one module per
subcommand in :mod:`hybridev.cli.commands`."""

from hybridev.cli.main import main

__all__ = ["main"]
