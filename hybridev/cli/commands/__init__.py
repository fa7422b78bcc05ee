"""Subcommands of the ``hybridev`` CLI, one module each.

Each module defines ``NAME`` (the subcommand), ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Raise ``ValueError`` for
bad input: :func:`hybridev.cli.main` turns it into exit code 2 and a one-line
message.
"""

COMMAND_MODULES = (
    "hybridev.cli.commands.demo",
    "hybridev.cli.commands.simulate",
    "hybridev.cli.commands.fit",
    "hybridev.cli.commands.predict",
    "hybridev.cli.commands.plan_charging",
    "hybridev.cli.commands.calibrate",
    "hybridev.cli.commands.range",
    "hybridev.cli.commands.route",
    "hybridev.cli.commands.example_data",
)
"""Modules registered as subcommands, in help order."""
