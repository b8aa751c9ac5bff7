"""Halt, Reset or Home broadcast and confirmed by reading every module's state back.

The one implementation: the executor's emergency Halt, the session's STOP and
``seqrun halt|reset`` all come here (through the driver). "Sent" is not "done": a
broadcast is never acknowledged, and a frame can be lost on a busy or shared bus.
"""

from __future__ import annotations

from collections.abc import Iterable

from seqrun.drivers.base import CommandConfirmation
from seqrun.drivers.powercube.states import joint_state
from seqrun.errors import CodecError
from seqrun.powercube.codec import BroadcastRequest, GetParam, GetParamAck
from seqrun.powercube.protocol import CommandId, ParamId

#: Rounds of "command, read back" before a module counts as not confirming.
DEFAULT_ATTEMPTS = 3

#: Seconds between rounds of ``seqrun halt|reset``: time for a module that was busy to settle.
RETRY_PAUSE_S = 0.02

#: The commands that can be confirmed, and what a module's state must show after each.
CONFIRMED = {CommandId.HALT: lambda state: state.halted,
             CommandId.RESET: lambda state: not state.faulted,
             CommandId.HOME: lambda state: state.homed and not state.faulted}


def confirm_command(client, command: CommandId, modules: Iterable[int], *,
                    attempts: int = DEFAULT_ATTEMPTS, timeout: float | None = None,
                    retry_pause_s: float = 0.0) -> CommandConfirmation:
    """Broadcast Halt, Reset or Home and confirm it on every module by reading its state
    back.

    1. Halt goes out **first** (``client.halt_now()``), before anything already queued on
       the bus is read: a flood of queued frames must not delay a stop. Reset and Home go
       out as their broadcast.
    2. Every module's CubeState is read back (pipelined); Halt is confirmed by HALTED,
       Reset by no fault bit left (a fault Reset cannot clear, e.g. a power fault, leaves
       the module unconfirmed, named with its state), Home by HOME_OK without a fault.
    3. For modules that did not confirm, the broadcast goes out again (after
       ``retry_pause_s``: time for a busy module to settle) and they are read again, up to
       ``attempts`` rounds in all.

    Never raises for the bus: a command that could not be sent gives ``sent=False`` and
    the error; modules that never answer are unconfirmed with "no answer".
    """
    took_effect = CONFIRMED.get(command)
    if took_effect is None:
        raise CodecError(f"confirm_command: {command.name} is not Halt, Reset or Home")
    name = command.name.lower()
    wanted = tuple(dict.fromkeys(modules))
    result = CommandConfirmation(name, wanted, unconfirmed={m: "no answer" for m in wanted})
    clock = client.clock
    t_first: float | None = None
    for attempt in range(1, max(1, attempts) + 1):
        result.attempts = attempt
        if attempt > 1 and retry_pause_s > 0:
            client.idle(retry_pause_s)
        try:
            if command == CommandId.HALT:
                client.halt_now()
            else:
                client.transact([BroadcastRequest(command, 0)])
            result.sent = True
            if t_first is None:
                t_first = clock.now()
        except Exception as exc:  # noqa: BLE001 - any failure of the bus is reported
            result.error = f"sending the {command.name.capitalize()} failed: {exc}"
            break
        waiting = [m for m in wanted if m in result.unconfirmed]
        try:
            acks = client.transact_partial([GetParam(m, ParamId.CUBE_STATE) for m in waiting],
                                           timeout)
        except Exception as exc:  # noqa: BLE001
            result.error = f"reading the modules back failed: {exc}"
            continue
        for module, ack in zip(waiting, acks):
            if not isinstance(ack, GetParamAck):
                result.unconfirmed[module] = "no answer"
                continue
            state = joint_state(int(ack.value))
            result.states[module] = state
            if took_effect(state):
                result.unconfirmed.pop(module, None)
            else:
                result.unconfirmed[module] = f"state {state.text}"
        if not result.unconfirmed:
            result.error = None
            break
    result.duration_s = 0.0 if t_first is None else clock.now() - t_first
    return result


def halt_and_confirm(client, modules: Iterable[int], *,
                     attempts: int = DEFAULT_ATTEMPTS) -> CommandConfirmation:
    """Halt every module of ``modules`` and read back that each one is HALTED."""
    return confirm_command(client, CommandId.HALT, modules, attempts=attempts)


def command_and_confirm(client, command: CommandId, modules: Iterable[int], *,
                        attempts: int = DEFAULT_ATTEMPTS,
                        timeout: float | None = None) -> CommandConfirmation:
    """``seqrun halt|reset``: broadcast ``command``, then confirm it on every module of
    ``modules``, pausing between rounds."""
    return confirm_command(client, command, sorted(set(modules)), attempts=attempts,
                           timeout=timeout, retry_pause_s=RETRY_PAUSE_S)
