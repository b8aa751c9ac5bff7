"""Halt or Reset the whole arm and confirm it by reading every module's state back
(``seqrun halt``, ``seqrun reset``).

"Sent" is not "done": a broadcast is never acknowledged, and a frame can be lost on the
way (a busy or shared bus, a server that drops it). The one implementation, shared with
the executor's emergency Halt, is :func:`seqrun.drivers.powercube.confirm_command`: it
sends the broadcast, reads CubeState of every module, and for the modules that did not
confirm sends the broadcast again after a short pause and reads again, a few times.

Confirmed means: Halt — HALTED is set; Reset — no fault bit is left (a fault Reset
cannot clear, e.g. a power fault, leaves the module unconfirmed, named with its state).
"""

from __future__ import annotations

from collections.abc import Iterable

from seqrun.drivers.base import CommandConfirmation
from seqrun.drivers.powercube import DEFAULT_ATTEMPTS, confirm_command
from seqrun.powercube.protocol import CommandId

__all__ = ["DEFAULT_ATTEMPTS", "Confirmation", "command_and_confirm"]

#: What :func:`command_and_confirm` found (the driver's confirmation).
Confirmation = CommandConfirmation

#: Seconds between rounds: time for a module that was busy to settle.
RETRY_PAUSE_S = 0.02


def command_and_confirm(client, command: CommandId, modules: Iterable[int], *,
                        attempts: int = DEFAULT_ATTEMPTS,
                        timeout: float | None = None) -> CommandConfirmation:
    """Broadcast ``command`` (HALT or RESET) through ``client`` (a PowerCube client), then
    confirm it on every module of ``modules`` (see the module docstring). Never raises for
    the bus: a command that could not be sent has ``sent`` false and its ``error``."""
    return confirm_command(client, command, sorted(set(modules)), attempts=attempts,
                           timeout=timeout, retry_pause_s=RETRY_PAUSE_S)
