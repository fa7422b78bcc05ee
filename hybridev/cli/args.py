"""The argument parser of the ``hybridev`` CLI and the checks that run before any heavy import.

* :func:`build_parser`: the parser with every subcommand, ``--version``, and a
  help formatter that never breaks a word or an option name across lines.
* :func:`unknown_options`: an unknown or misspelt option (or subcommand) is
  named with the closest valid one (``unknown option --sped; did you mean
  --speed?``), before argparse would complain about a missing required option.
* :func:`check_inputs`: every input file or folder exists (a missing file is
  reported in well under a second: nothing heavy is imported yet).
* :func:`option_of`: the option whose value names a file, for OS errors.

Only the standard library (and :mod:`hybridev.core`) is imported here.
"""

from __future__ import annotations

import argparse
import difflib
import glob
import importlib
import os
import re
import textwrap

from hybridev.cli.commands import COMMAND_MODULES

__all__ = ["INPUT_DESTS", "build_parser", "check_inputs", "option_of", "unknown_options"]

INPUT_DESTS = ("model", "measured", "trips", "schedule", "timeseries", "tariff", "columns_file")
"""Argument names that are inputs read by the command (checked to exist before the work)."""

_DATASET_DESTS = ("measured", "trips", "timeseries")  # may be a glob or a folder (dask)
_NUMBER = re.compile(r"^-(\d|\.\d)")


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter without breaking words at hyphens or inside long words."""

    def _split_lines(self, text: str, width: int) -> list[str]:
        text = self._whitespace_matcher.sub(" ", text).strip()
        return textwrap.wrap(text, width, break_long_words=False, break_on_hyphens=False)

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        text = self._whitespace_matcher.sub(" ", text).strip()
        return textwrap.fill(text, width, initial_indent=indent, subsequent_indent=indent,
                             break_long_words=False, break_on_hyphens=False)


def build_parser() -> tuple[argparse.ArgumentParser, dict]:
    """The ``hybridev`` parser and ``{command: run}``."""
    from hybridev import __version__

    p = argparse.ArgumentParser(
        prog="hybridev", formatter_class=HelpFormatter,
        description="Hybrid physics + residual-learning EV trip energy, with uncertainty.")
    p.add_argument("--version", action="version", version=f"hybridev {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    runners = {}
    for name in COMMAND_MODULES:
        mod = importlib.import_module(name)
        sp = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP,
                            formatter_class=HelpFormatter)
        mod.add_arguments(sp)
        runners[mod.NAME] = mod.run
    return p, runners


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _suggest(word: str, choices) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f"; did you mean {close[0]}?" if close else ""


def unknown_options(parser: argparse.ArgumentParser, argv: list[str]) -> str | None:
    """The message for the first unknown subcommand or option in ``argv``, else None.

    Examples
    --------
    >>> p, _ = build_parser()
    >>> unknown_options(p, ["range", "--sped", "50"])
    "unknown option --sped; did you mean --speed? (see 'hybridev range --help')"
    >>> unknown_options(p, ["range", "--speed", "50"]) is None
    True
    """
    subs = _subparsers(parser)
    top = set(parser._option_string_actions)
    i = 0
    while i < len(argv) and argv[i].startswith("-"):
        opt = argv[i].split("=", 1)[0]
        if opt not in top:
            return f"unknown option {opt}{_suggest(opt, top)}"
        i += 1
    if i >= len(argv):
        return None
    command = argv[i]
    if command not in subs:
        return (f"unknown command {command!r}{_suggest(command, subs)} (commands: "
                f"{', '.join(subs)})")
    sp = subs[command]
    known = set(sp._option_string_actions)
    longs = [o for o in known if o.startswith("--")]
    for token in argv[i + 1:]:
        if token == "--":
            break
        if not token.startswith("-") or token == "-" or _NUMBER.match(token):
            continue
        opt = token.split("=", 1)[0]
        if opt in known:
            continue
        if opt.startswith("--") and len([o for o in longs if o.startswith(opt)]) == 1:
            continue  # an unambiguous abbreviation, as argparse accepts
        positional = [a.dest for a in sp._actions if not a.option_strings]
        if opt.lstrip("-").replace("-", "_") in positional:
            usage = " ".join(d.upper() for d in positional)
            return (f"unknown option {opt}: {opt.lstrip('-')} is a positional argument of "
                    f"'hybridev {command}', given without an option name: hybridev "
                    f"{command} {usage}")
        return f"unknown option {opt}{_suggest(opt, longs)} (see 'hybridev {command} --help')"
    return None


def _actions(parser: argparse.ArgumentParser, command: str):
    sp = _subparsers(parser).get(command)
    return [] if sp is None else sp._actions


def _display(action: argparse.Action) -> str:
    return action.option_strings[-1] if action.option_strings else action.dest


def check_inputs(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Every input of the command exists (``ValueError`` naming the option otherwise)."""
    from hybridev.core.outputs import os_reason

    for action in _actions(parser, args.command):
        value = getattr(args, action.dest, None)
        if action.dest not in INPUT_DESTS or not isinstance(value, str):
            continue
        what = f"{_display(action)}={value!r}"
        if "\0" in value:
            raise ValueError(f"{what} contains a NUL character")
        if action.dest in _DATASET_DESTS and glob.has_magic(value):
            if not glob.glob(os.path.expanduser(value)):
                raise ValueError(f"{what}: no file matches")
            continue
        try:
            os.stat(os.path.expanduser(value))
        except FileNotFoundError:
            raise ValueError(f"{what} does not exist") from None
        except OSError as exc:
            raise ValueError(f"{what} cannot be read: {os_reason(exc)}") from None
        is_dir = os.path.isdir(os.path.expanduser(value))
        if action.dest == "model" and not is_dir:
            raise ValueError(f"{what} is not a folder: give a model folder written by "
                             "'hybridev fit'")
        if action.dest not in ("model", *_DATASET_DESTS) and is_dir:
            raise ValueError(f"{what} is a folder; give a .csv or .parquet file")


def option_of(parser: argparse.ArgumentParser, args: argparse.Namespace,
              filename: str | None) -> str:
    """The option (``--out``, ``trips``) whose value names ``filename``, or a description."""
    if filename is None:
        return "a file"
    target = os.path.abspath(os.fsdecode(filename))
    best = None
    for action in _actions(parser, args.command):
        value = getattr(args, action.dest, None)
        if not isinstance(value, str) or not value:
            continue
        v = os.path.abspath(os.path.expanduser(value))
        if target == v or target.startswith(v.rstrip("/") + "/") or (
                os.path.basename(target).startswith(f".{os.path.basename(v)}.")
                and os.path.dirname(target) == os.path.dirname(v)):
            best = f"{_display(action)}={value!r}"
            break
    return best or f"file {os.fsdecode(filename)!r}"
