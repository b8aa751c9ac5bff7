"""Faults the modules had latched before the run: told, and never cleared silently.

The preflight records every module whose state shows a fault before anything but reads
was sent (event ``latched_fault``, the report's note); on real hardware a Reset step clears
one only when the operator says so (also with ``--yes``), else the run ends as an operator
abort. The simulator and the dry run are not asked.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from seqrun.results import OperatorAbort, latched_message

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.arm.joint_values import JointState


class LatchedFaults:
    """Faults the modules report before the run sent anything but reads.

    :param confirm: asked before a Reset clears one (real hardware: someone may have
        pressed the emergency stop for a reason); None: not asked (simulator, dry run).
    :param emit: the run's event emitter; ``ask``: how the run asks its operator.
    """

    def __init__(self, arm: ArmDescription, confirm: Callable[[str], bool] | None,
                 emit: Callable[..., None], ask: Callable[[Callable, str], bool]) -> None:
        self._arm = arm
        self._emit = emit
        self._ask = ask
        self.confirm = confirm
        self.at_start: list[dict[str, Any]] = []
        self._cleared_ok = False

    def record(self, states: dict[int, JointState]) -> None:
        """Told on the terminal (event ``latched_fault``) and in the report, never cleared
        silently."""
        names = dict(zip(self._arm.module_ids, self._arm.joint_names))
        self.at_start = [
            {"module": m, "joint": names.get(m, "?"),
             "flags": f.fault_text, "state": f.describe()}
            for m, f in sorted(states.items()) if f.faulted]
        if self.at_start:
            self._emit("latched_fault", modules=self.at_start, message=self.message())

    def message(self) -> str:
        return latched_message(self.at_start)

    def confirm_clearing(self, modules: list[int] | None) -> None:
        """Called by a Reset step before it clears faults: on real hardware a fault that
        was latched before the run is cleared only when the operator says so (also with
        ``--yes``); declining, or no answer, ends the run as an operator abort."""
        if not self.at_start or self._cleared_ok:
            return
        affected = [e for e in self.at_start if modules is None or e["module"] in modules]
        if not affected:
            return
        if self.confirm is not None:
            question = (self.message() + ". This Reset clears it. Has the cause "
                        "been checked, and may it be cleared?")
            if not self._ask(self.confirm, question):
                raise OperatorAbort("operator did not clear the fault latched before the "
                                    "run; nothing was reset")
            self._emit("latched_fault_cleared", modules=[e["module"] for e in affected],
                     confirmed_by="operator")
        else:
            self._emit("latched_fault_cleared", modules=[e["module"] for e in affected],
                     confirmed_by="not asked (simulator)")
        self._cleared_ok = True
