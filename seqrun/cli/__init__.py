"""``seqrun`` command line: one typer app (``app.py``), one module per command group.

The command modules only define the commands (options, help); each command imports what it
needs when it runs, so ``seqrun --help`` and the short commands do not pay for pydantic,
numpy, ruckig or python-can (tests/test_startup.py holds this). The ``seqrun`` program loads
only the module of the command it runs (:data:`COMMAND_WORDS`); importing this package
anywhere else registers every command.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

from seqrun.cli.app import app
from seqrun.cli.output import guard_stdout

#: Command modules; each registers its commands on :data:`app` when imported.
COMMAND_MODULES = (
    "seqrun.cli.fk",
    "seqrun.cli.ik",
    "seqrun.cli.validate",
    "seqrun.cli.sim",
    "seqrun.cli.run",
    "seqrun.cli.arm_commands",
    "seqrun.cli.home",
    "seqrun.cli.limits",
    "seqrun.cli.pose",
    "seqrun.cli.zero",
    "seqrun.cli.init",
    "seqrun.cli.runs",
    "seqrun.cli.report",
    "seqrun.cli.trend",
    "seqrun.cli.console",
    "seqrun.cli.ros",
    "seqrun.cli.jog",
    "seqrun.cli.urdf",
)


#: The first word of a command line -> the module that defines that command (or group).
#: ``seqrun WORD ...`` loads only that module: typer builds the parameters of every
#: registered command at each start.
COMMAND_WORDS = {
    "fk": "seqrun.cli.fk",
    "ik": "seqrun.cli.ik",
    "validate": "seqrun.cli.validate",
    "schema": "seqrun.cli.validate",
    "sim": "seqrun.cli.sim",
    "run": "seqrun.cli.run",
    "status": "seqrun.cli.arm_commands",
    "halt": "seqrun.cli.arm_commands",
    "reset": "seqrun.cli.arm_commands",
    "home": "seqrun.cli.home",
    "limits": "seqrun.cli.limits",
    "pose": "seqrun.cli.pose",
    "zero": "seqrun.cli.zero",
    "init": "seqrun.cli.init",
    "runs": "seqrun.cli.runs",
    "report": "seqrun.cli.report",
    "trend": "seqrun.cli.trend",
    "console": "seqrun.cli.console",
    "ros": "seqrun.cli.ros",
    "jog": "seqrun.cli.jog",
    "urdf": "seqrun.cli.urdf",
}


def _load_commands(argv: Sequence[str] | None = None) -> None:
    """Register commands on :data:`app`: for a command line whose first word names a
    command, that command's module; otherwise (no words, ``--help``, a mistyped command,
    an import by anything but the ``seqrun`` program) every module."""
    word = argv[0] if argv else None
    for name in (COMMAND_WORDS[word],) if word in COMMAND_WORDS else COMMAND_MODULES:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as exc:  # a command group not built yet
            if exc.name != name:
                raise


def main(argv: list[str] | None = None) -> None:
    guard_stdout()  # `seqrun … | head`: quiet exit 141, never a run ended by it
    args = argv if argv is not None else sys.argv[1:]
    _load_commands(args)
    app(args=args, prog_name="seqrun")


def starting_command_line() -> Sequence[str] | None:
    """The command line the ``seqrun`` program (:mod:`seqrun.__main__`) is starting with;
    None when anything else imports this package (tests, tools: they get every command).
    ``python -m seqrun`` runs the program as ``__main__``, the ``seqrun`` script imports it."""
    for program in (sys.modules.get("seqrun.__main__"), sys.modules.get("__main__")):
        spec = getattr(program, "__spec__", None)
        if spec is not None and spec.name == "seqrun.__main__":
            return getattr(program, "command_line", None)
    return None


_load_commands(starting_command_line())
