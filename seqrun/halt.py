"""Halt the arm and confirm it: kept for its callers; the one implementation is
:func:`seqrun.drivers.powercube.confirm_command` (also behind ``seqrun halt|reset``).

The Halt broadcast goes out **first**, before anything already queued on the bus is read;
then every module's state is read back and only HALTED counts; modules that did not
confirm get the Halt again and are read again, up to ``retries`` attempts in all. Never
raises: a bus that fails is recorded in :attr:`HaltConfirmation.error`.
"""

from __future__ import annotations

from collections.abc import Iterable

from seqrun.drivers.base import HaltConfirmation
from seqrun.drivers.powercube import DEFAULT_ATTEMPTS, confirm_command
from seqrun.powercube.protocol import CommandId

__all__ = ["DEFAULT_RETRIES", "HaltConfirmation", "halt_and_confirm"]

#: Attempts (Halt + read back) before a module counts as not halted.
DEFAULT_RETRIES = DEFAULT_ATTEMPTS


def halt_and_confirm(client, modules: Iterable[int], *,
                     retries: int = DEFAULT_RETRIES) -> HaltConfirmation:
    """Halt every module of ``modules`` through ``client`` (a PowerCube client) and read
    back that each one is HALTED."""
    return confirm_command(client, CommandId.HALT, modules, attempts=retries)
