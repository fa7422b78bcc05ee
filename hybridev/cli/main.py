"""The ``hybridev`` command-line interface.

Subcommands live in :mod:`hybridev.cli.commands`. Every subcommand exits with 0 on
success and with 2 and a one-line message (naming the option, value and allowed
range) on bad input, and with 130 and a one-line message when interrupted
(Ctrl-C, without a traceback; outputs are written to a temporary file and
renamed only when complete, so an interrupted run leaves none half-written). Warnings are printed as one line each,
``hybridev <command>: <WarningClass>: <message>``, without Python file paths.

Before any heavy import (pandas, torch) the arguments are checked
(:mod:`hybridev.cli.args`): an unknown or misspelt option is named with the
closest valid one, and every input file or folder must exist. Errors of the
operating system at the boundary (a name too long, no permission, a read-only
or full disk) and a missing optional extra (dask) are exit code 2 with one line
naming the option, never a traceback.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Sequence

from hybridev.cli.args import build_parser, check_inputs, option_of, unknown_options

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``hybridev`` console script; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser, runners = build_parser()
    bad = unknown_options(parser, argv)
    if bad:
        parser.exit(2, f"hybridev: error: {bad}\n")
    args = parser.parse_args(argv)
    command = args.command

    def show(message, category, filename, lineno, file=None, line=None):  # one line each
        print(f"hybridev {command}: {category.__name__}: {message}",
              file=sys.stderr if file is None else file)

    def fail(message: str) -> int:
        print(f"hybridev {command}: error: {' '.join(str(message).split())}", file=sys.stderr)
        return 2

    with warnings.catch_warnings():  # restores the previous showwarning on exit
        warnings.showwarning = show
        try:
            check_inputs(parser, args)
            return runners[command](args)
        except ValueError as exc:
            return fail(str(exc))
        except ModuleNotFoundError as exc:
            extra = "dask" if (exc.name or "").split(".")[0] in ("dask", "distributed") else None
            if extra is None:
                raise
            return fail(f"this needs the optional {extra} dependencies, which are not "
                        f"installed: pip install 'hybridev[{extra}]'")
        except OSError as exc:
            from hybridev.core.outputs import os_reason

            where = option_of(parser, args, exc.filename)
            return fail(f"{where}: {os_reason(exc)}")
        except MemoryError:
            return fail("out of memory: use smaller sizes (--n-eval, --n-samples) or a "
                        "smaller input")
        except KeyboardInterrupt:
            print(f"hybridev {command}: interrupted (each output is written whole or "
                  "not at all)", file=sys.stderr)
            return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
