"""``seqrun`` command line: one typer app (``app.py``), one module per command group.

The command modules only define the commands (options, help); each command imports what it
needs when it runs, so ``seqrun --help`` and the short commands do not pay for pydantic,
numpy, ruckig or python-can (tests/test_startup.py holds this).
"""

from __future__ import annotations

import importlib
import sys

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
    "seqrun.cli.pose",
    "seqrun.cli.zero",
    "seqrun.cli.init",
    "seqrun.cli.runs",
    "seqrun.cli.report",
    "seqrun.cli.console",
)


def _load_commands() -> None:
    for name in COMMAND_MODULES:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as exc:  # a command group not built yet
            if exc.name != name:
                raise


def main(argv: list[str] | None = None) -> None:
    guard_stdout()  # `seqrun … | head`: quiet exit 141, never a run ended by it
    _load_commands()
    app(args=argv if argv is not None else sys.argv[1:], prog_name="seqrun")


_load_commands()
