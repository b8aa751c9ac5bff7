"""``seqrun`` command line: one typer app (``app.py``), one module per command group."""

from __future__ import annotations

import importlib
import sys

from seqrun.cli.app import app

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
)


def _load_commands() -> None:
    for name in COMMAND_MODULES:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as exc:  # a command group not built yet
            if exc.name != name:
                raise


def main(argv: list[str] | None = None) -> None:
    _load_commands()
    app(args=argv if argv is not None else sys.argv[1:], prog_name="seqrun")


_load_commands()
