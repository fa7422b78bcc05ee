"""Subcommands of the ``hybridev`` CLI, one module each.

Each module defines ``NAME`` (the subcommand), ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Raise ``ValueError`` for
bad input: :func:`hybridev.cli.main` turns it into exit code 2 and a one-line
message.
"""

COMMAND_MODULES = (
    "hybridev.commands.demo",
    "hybridev.commands.simulate",
    "hybridev.commands.fit",
    "hybridev.commands.predict",
    "hybridev.commands.plan_charging",
    "hybridev.commands.calibrate",
    "hybridev.commands.range",
)
"""Modules registered as subcommands, in help order."""
