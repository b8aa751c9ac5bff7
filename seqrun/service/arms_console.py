"""The arm sessions of one face that serves several arms at once (``seqrun console`` in a
campaign with ``[arms.*]``): one :class:`~seqrun.service.session.ArmSession` per arm, each
with its own bus, driver and zero reference, one control desk for all of them (one operator
commands the whole console), and one STOP that halts every arm and confirms each.

The STOP halts the arms at the same time, each from a thread of its own: an arm whose Halt
is not confirmed (a module that does not answer, a bus gone) does not delay the Halt of
the others, and an error halting one arm is that arm's "not confirmed", never the others'.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from seqrun.service.control import ControlDesk

__all__ = ["ArmHalt", "ArmSessions", "ArmsHalt"]


@dataclass(frozen=True)
class ArmHalt:
    """One arm's part of a STOP: sent, confirmed (every module read back HALTED), the
    operator's line, and which modules did not confirm."""

    arm_id: str
    sent: bool
    confirmed: bool
    message: str
    modules_not_halted: tuple[int, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return {"halt_sent": self.sent, "halt_confirmed": self.confirmed,
                "modules_not_halted": list(self.modules_not_halted), "message": self.message}


@dataclass(frozen=True)
class ArmsHalt:
    """Every arm's Halt; confirmed when every arm's was."""

    arms: dict[str, ArmHalt]

    @property
    def confirmed(self) -> bool:
        return all(a.confirmed for a in self.arms.values())

    @property
    def not_confirmed(self) -> list[str]:
        return [a for a, h in self.arms.items() if not h.confirmed]

    def describe(self) -> str:
        """One line: each arm, halted or not."""
        parts = [f"arm {a}: {h.message}" if h.confirmed else f"arm {a}: STOP FAILED: "
                 f"{h.message}" for a, h in self.arms.items()]
        head = "every arm halted" if self.confirmed else \
            f"STOP FAILED for arm {', '.join(self.not_confirmed)}: use the emergency stop"
        return f"{head} ({'; '.join(parts)})"

    def as_dict(self) -> dict[str, Any]:
        return {"halt_sent": all(h.sent for h in self.arms.values()),
                "halt_confirmed": self.confirmed, "not_confirmed": self.not_confirmed,
                "arms": {a: h.as_dict() for a, h in self.arms.items()},
                "message": self.describe()}


class ArmSessions:
    """The sessions of several arms, in the campaign's order (``sessions``: arm id ->
    session). The sessions share one :class:`ControlDesk` (its events on the first arm's
    hub). :meth:`close` closes every session (a controlled stop of anything moving)."""

    def __init__(self, sessions: Mapping[str, Any]) -> None:
        if not sessions:
            raise ValueError("no arm session")
        self.sessions = dict(sessions)
        first = next(iter(self.sessions.values()))
        self.control = ControlDesk(publish=first.publish, clock=first.clock.now)
        for session in self.sessions.values():
            session.control = self.control

    @property
    def arm_ids(self) -> tuple[str, ...]:
        return tuple(self.sessions)

    def __getitem__(self, arm_id: str) -> Any:
        return self.sessions[arm_id]

    def halt(self, reason: str = "STOP") -> ArmsHalt:
        """Halt every arm at once (a thread each) and confirm each (see the module doc)."""
        results: dict[str, ArmHalt] = {}

        def one(arm_id: str, session: Any) -> None:
            try:
                result = session.halt(reason)
                names = dict(zip(session.arm.module_ids, session.arm.joint_names))
                results[arm_id] = ArmHalt(arm_id, result.sent, result.confirmed,
                                          result.describe(names),
                                          tuple(result.modules_unconfirmed))
            except Exception as exc:  # noqa: BLE001 - this arm's failure, said; others go on
                results[arm_id] = ArmHalt(arm_id, False, False,
                                          f"the Halt failed ({type(exc).__name__}: {exc}): "
                                          "use the emergency stop")

        threads = [threading.Thread(target=one, args=(a, s), name=f"halt-arm-{a}", daemon=True)
                   for a, s in self.sessions.items()]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        return ArmsHalt({a: results[a] for a in self.sessions})

    def close(self) -> None:
        """Close every session, each even when another's close fails."""
        errors: list[BaseException] = []
        for session in self.sessions.values():
            try:
                session.close()
            except Exception as exc:  # noqa: BLE001 - the other arms are still closed
                errors.append(exc)
        if errors:
            raise errors[0]
