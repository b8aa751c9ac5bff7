"""Halt or Reset the whole arm and confirm it by reading every module's state back.

"Sent" is not "done": a broadcast is never acknowledged, and a frame can be lost on the
way (a busy or shared bus, a server that drops it). :func:`command_and_confirm` sends the
broadcast, reads CubeState of every module, and for the modules that did not confirm
sends the command again (addressed, acknowledged) and reads again, a few times.

Confirmed means: Halt — HALTED is set; Reset — no fault bit is left (a fault Reset
cannot clear, e.g. a power fault, leaves the module unconfirmed, named with its state).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from seqrun.errors import CodecError
from seqrun.powercube.client import PowerCubeClient
from seqrun.powercube.codec import BroadcastRequest, CommandRequest, GetParam, Request
from seqrun.powercube.protocol import CommandId, ParamId, StateFlag

#: Rounds of "command, read back" before a module counts as not confirming.
DEFAULT_ATTEMPTS = 3
#: Seconds between rounds: time for a module that was busy to settle.
_RETRY_PAUSE = 0.02


@dataclass
class Confirmation:
    """What :func:`command_and_confirm` found."""

    command: CommandId
    #: Last state read from each module that answered.
    states: dict[int, StateFlag] = field(default_factory=dict)
    #: Modules that did not confirm -> why ("no answer", or their state).
    unconfirmed: dict[int, str] = field(default_factory=dict)
    attempts: int = 0

    @property
    def confirmed(self) -> bool:
        return not self.unconfirmed

    def describe_unconfirmed(self) -> str:
        return ", ".join(f"module {m} ({why})" for m, why in sorted(self.unconfirmed.items()))


def _took_effect(command: CommandId, state: StateFlag) -> bool:
    if command == CommandId.HALT:
        return bool(state & StateFlag.HALTED)
    return not state.is_fault


def command_and_confirm(client: PowerCubeClient, command: CommandId, modules: Iterable[int],
                        *, attempts: int = DEFAULT_ATTEMPTS,
                        timeout: float | None = None) -> Confirmation:
    """Broadcast ``command`` (HALT or RESET), then confirm it on every module of
    ``modules`` by reading its state, re-sending it addressed to the modules that did not
    confirm, up to ``attempts`` rounds in all.

    The broadcast is the first frame sent, before any read. Raises only what sending
    raises (:class:`~seqrun.errors.BusError`); modules that never answer end up in
    :attr:`Confirmation.unconfirmed`.
    """
    if command not in (CommandId.HALT, CommandId.RESET):
        raise CodecError(f"command_and_confirm: {command.name} is not Halt or Reset")
    result = Confirmation(command)
    waiting = sorted(set(modules))
    for attempt in range(1, max(attempts, 1) + 1):
        result.attempts = attempt
        if attempt == 1 and command == CommandId.HALT:
            client.halt_now()  # before anything queued is read: a stop must not wait
            requests: list[Request] = []
        elif attempt == 1:
            requests = [BroadcastRequest(command, 0)]
        else:
            client.idle(_RETRY_PAUSE)
            requests = [CommandRequest(m, command) for m in waiting]
        reads = [GetParam(m, ParamId.CUBE_STATE) for m in waiting]
        acks = client.transact_partial([*requests, *reads], timeout)[len(requests):]
        still = []
        for module, ack in zip(waiting, acks, strict=True):
            if ack is None:
                result.unconfirmed[module] = "no answer"
                still.append(module)
                continue
            state = StateFlag(int(ack.value))  # type: ignore[union-attr]
            result.states[module] = state
            if _took_effect(command, state):
                result.unconfirmed.pop(module, None)
            else:
                result.unconfirmed[module] = f"state {state.describe()}"
                still.append(module)
        waiting = still
        if not waiting:
            break
    return result
