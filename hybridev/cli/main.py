"""The ``hybridev`` command-line interface.

Subcommands live in :mod:`hybridev.cli.commands`. Every subcommand exits with 0 on
success and with 2 and a one-line message (naming the field, value and allowed
range) on bad input, and with 130 and a one-line message when interrupted
(Ctrl-C, without a traceback; outputs are written to a temporary file and
renamed only when complete, so an interrupted run leaves none half-written). Warnings are printed as one line each,
``hybridev <command>: <WarningClass>: <message>``, without Python file paths.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings
from collections.abc import Sequence

from hybridev.cli.commands import COMMAND_MODULES

__all__ = ["main"]


def _parser() -> tuple[argparse.ArgumentParser, dict]:
    p = argparse.ArgumentParser(
        prog="hybridev",
        description="Hybrid physics + residual-learning EV trip energy, with uncertainty.")
    sub = p.add_subparsers(dest="command", required=True)
    runners = {}
    for name in COMMAND_MODULES:
        mod = importlib.import_module(name)
        sp = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(sp)
        runners[mod.NAME] = mod.run
    return p, runners


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``hybridev`` console script; returns the exit code."""
    parser, runners = _parser()
    args = parser.parse_args(argv)

    def show(message, category, filename, lineno, file=None, line=None):  # one line each
        print(f"hybridev {args.command}: {category.__name__}: {message}",
              file=sys.stderr if file is None else file)

    with warnings.catch_warnings():  # restores the previous showwarning on exit
        warnings.showwarning = show
        try:
            return runners[args.command](args)
        except ValueError as exc:
            print(f"hybridev {args.command}: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print(f"hybridev {args.command}: interrupted (each output is written whole or "
                  "not at all)", file=sys.stderr)
            return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
