"""Home confirmed by reading every module back: ``seqrun home`` (and the console's Home).

Home is not a stop: a module that is halted or in error ignores it (the operator's
Reset comes first, never one of ours), and a module with incremental encoders travels to
its home switch before it reports HOME_OK. So Home is sent once (broadcast for the whole
arm, addressed to each module of a subset) and the modules are then read until each one
reports HOME_OK without MOTION (the travel, if any, is over), or a time limit passes.
"""

from __future__ import annotations

from collections.abc import Sequence

from seqrun.drivers.base import CommandConfirmation
from seqrun.drivers.powercube.states import joint_state
from seqrun.powercube.codec import BroadcastRequest, CommandRequest, GetParam, GetParamAck
from seqrun.powercube.protocol import CommandId, ParamId

#: Seconds between readings while modules home (a travelling module takes seconds).
POLL_S = 0.02


def _read_states(client, modules: Sequence[int], result: CommandConfirmation) -> None:
    acks = client.transact_partial([GetParam(m, ParamId.CUBE_STATE) for m in modules])
    for module, ack in zip(modules, acks):
        if not isinstance(ack, GetParamAck):
            result.unconfirmed[module] = "no answer"
            continue
        state = joint_state(int(ack.value))
        result.states[module] = state
        if state.homed and not state.faulted and not state.moving:
            result.unconfirmed.pop(module, None)
        elif state.faulted:
            result.unconfirmed[module] = f"state {state.text}"
        else:
            result.unconfirmed[module] = (f"still homing (state {state.text})" if state.moving
                                          else f"state {state.text}")


def home_and_confirm(client, modules: Sequence[int], *, whole_arm: bool,
                     timeout_s: float) -> CommandConfirmation:
    """Home ``modules`` and read back that each one is homed and at rest.

    1. Every module is read first; one that is halted or in error is named and nothing is
       sent (``sent`` False, ``error`` says to reset): Home must not look like a Reset.
    2. Home goes out once: the broadcast when ``whole_arm``, else addressed per module.
    3. The modules are read every :data:`POLL_S` until all report HOME_OK without MOTION,
       or ``timeout_s`` passes (those left are unconfirmed, with their state).

    Never raises for the bus: a failure is in the result.
    """
    wanted = tuple(dict.fromkeys(modules))
    result = CommandConfirmation("home", wanted, unconfirmed={m: "no answer" for m in wanted})
    clock = client.clock
    try:
        _read_states(client, wanted, result)
    except Exception as exc:  # noqa: BLE001 - any failure of the bus is reported
        result.error = f"reading the modules failed: {exc}"
        return result
    silent = [m for m in wanted if m not in result.states]
    stopped = [m for m, s in result.states.items() if s.faulted]
    if silent or stopped:
        for module in stopped:
            result.unconfirmed[module] = f"state {result.states[module].text}"
        result.error = "; ".join(
            ([f"module(s) {', '.join(map(str, silent))} did not answer"] if silent else [])
            + ([f"module(s) {', '.join(map(str, stopped))} halted or in error: reset them "
                "first (seqrun reset)"] if stopped else []))
        return result
    result.attempts = 1
    t_first = clock.now()
    try:
        if whole_arm:
            client.transact([BroadcastRequest(CommandId.HOME, 0)])
        else:
            client.transact([CommandRequest(m, CommandId.HOME) for m in wanted])
        result.sent = True
    except Exception as exc:  # noqa: BLE001
        result.error = f"sending the Home failed: {exc}"
        return result
    result.unconfirmed = {m: "no answer" for m in wanted}
    deadline = t_first + timeout_s
    while True:
        try:
            _read_states(client, [m for m in wanted if m in result.unconfirmed], result)
        except Exception as exc:  # noqa: BLE001
            result.error = f"reading the modules back failed: {exc}"
        if not result.unconfirmed or any(result.states[m].faulted for m in result.unconfirmed
                                         if m in result.states):
            break
        if clock.now() >= deadline:
            result.error = f"not homed within {timeout_s:g} s"
            break
        client.idle(POLL_S)
    result.duration_s = clock.now() - t_first
    if not result.unconfirmed:
        result.error = None
    return result
