"""The end of a command that must be confirmed by the modules (halt, reset, home): one line
saying which modules confirmed it, or one error line and the fault exit code."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import typer

from seqrun.cli.common import EXIT_FAULT, fail


class Confirmation(Protocol):
    """What the service layer returns for a confirmed command (the driver's
    ``CommandConfirmation``; a face does not import the driver layer)."""

    sent: bool
    error: str | None

    @property
    def confirmed(self) -> bool: ...

    @property
    def states(self) -> Mapping[int, Any]: ...

    def describe_unconfirmed(self) -> str: ...


def confirmed_or_exit(result: Confirmation, where: str, *, what: str,
                      sent_as: str = "sent", prefix: str = "", unconfirmed_after: str = "",
                      confirmed_in: str = "") -> None:
    """``where``: the bus, as the connection describes it; ``prefix``: ``arm ID: `` in a
    campaign of several arms; ``unconfirmed_after`` / ``confirmed_in``: the attempts or the
    time, said after the modules."""
    if not result.sent:
        fail(f"{prefix}{what} not sent: {result.error}", EXIT_FAULT)
    title = what.capitalize()
    if not result.confirmed:
        error = f"; {result.error}" if result.error else ""
        fail(f"{prefix}{title} {sent_as}, but not confirmed by {result.describe_unconfirmed()}"
             f"{unconfirmed_after} ({where}{error})", EXIT_FAULT)
    typer.echo(f"{prefix}{title} confirmed by modules "
               f"{', '.join(map(str, sorted(result.states)))}{confirmed_in} ({where})")
