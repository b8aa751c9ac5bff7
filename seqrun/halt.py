"""Halt the arm and confirm it: the one way seqrun stops every module in an emergency.

``halt_sent`` alone only says that ``send()`` returned; a Halt that a dead connection, a
stalled server or a flooded wire kept from the modules must not be reported as a stop.
:func:`halt_and_confirm` therefore

1. sends the Halt broadcast ``0x100 [02 00]`` **first**, before anything already queued
   on the bus is read (a flood of queued frames must not delay it),
2. reads every module's state word back (pipelined CubeState) and counts a module as
   halted only when it reports HALTED,
3. for the modules that did not confirm, sends the Halt again and reads again, up to
   ``retries`` attempts in all.

It never raises: a bus that fails is recorded in :attr:`HaltConfirmation.error`. Used by
the executor on every fault and operator Halt, and reusable by the ``seqrun halt``
command.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from seqrun.powercube.codec import GetParam, GetParamAck
from seqrun.powercube.protocol import ParamId, StateFlag

#: Attempts (Halt + read back) before a module counts as not halted.
DEFAULT_RETRIES = 3


@dataclass(frozen=True)
class HaltConfirmation:
    """What a Halt reached: ``sent`` (a Halt broadcast left the client at least once) and
    ``confirmed`` (every module read back HALTED)."""

    sent: bool
    confirmed: bool
    modules_confirmed: tuple[int, ...] = ()
    modules_unconfirmed: tuple[int, ...] = ()
    attempts: int = 0
    #: Seconds from the first Halt on the bus to the last confirmation read.
    duration_s: float = 0.0
    error: str | None = None
    states: dict[int, str] = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"halt_sent": self.sent, "halt_confirmed": self.confirmed,
                "modules_not_halted": list(self.modules_unconfirmed),
                "halt_attempts": self.attempts,
                **({"halt_error": self.error} if self.error else {})}

    def describe(self, joint_names: dict[int, str] | None = None) -> str:
        """One line for the operator."""
        if self.confirmed:
            return (f"Halt confirmed by every module ({len(self.modules_confirmed)}) "
                    f"after {self.attempts} attempt{'s' * (self.attempts != 1)}")
        names = joint_names or {}
        missing = ", ".join(f"{m} ({names[m]})" if m in names else str(m)
                            for m in self.modules_unconfirmed)
        if not self.sent:
            return (f"Halt could NOT be sent ({self.error}): the modules may still be "
                    "moving; use the emergency stop")
        text = f"Halt sent but NOT confirmed by module(s) {missing}"
        return text + (f" ({self.error})" if self.error else "")


def halt_and_confirm(client, modules: Iterable[int], *,
                     retries: int = DEFAULT_RETRIES) -> HaltConfirmation:
    """Halt every module and read back that each one is HALTED (module docstring).

    :param client: a :class:`~seqrun.powercube.client.PowerCubeClient`.
    :param modules: the module ids that must confirm.
    :param retries: attempts in all (Halt, then read back), at least 1.
    """
    modules = list(modules)
    clock = client.clock
    sent = False
    error: str | None = None
    confirmed: dict[int, StateFlag] = {}
    states: dict[int, str] = {}
    attempts = 0
    t_first = None
    for attempts in range(1, max(1, retries) + 1):
        try:
            client.halt_now()
            sent = True
            if t_first is None:
                t_first = clock.now()
        except Exception as exc:  # noqa: BLE001 - any failure of the bus is reported
            error = f"sending the Halt failed: {exc}"
            break
        waiting = [m for m in modules if m not in confirmed]
        try:
            acks = client.transact_partial([GetParam(m, ParamId.CUBE_STATE) for m in waiting])
        except Exception as exc:  # noqa: BLE001
            error = f"reading the modules back failed: {exc}"
            continue
        for module, ack in zip(waiting, acks):
            if isinstance(ack, GetParamAck):
                flags = StateFlag(int(ack.value))
                states[module] = flags.describe()
                if flags & StateFlag.HALTED:
                    confirmed[module] = flags
        if len(confirmed) == len(modules):
            error = None
            break
    unconfirmed = tuple(m for m in modules if m not in confirmed)
    return HaltConfirmation(
        sent=sent, confirmed=sent and not unconfirmed,
        modules_confirmed=tuple(m for m in modules if m in confirmed),
        modules_unconfirmed=unconfirmed, attempts=attempts,
        duration_s=0.0 if t_first is None else clock.now() - t_first,
        error=error, states=states)
