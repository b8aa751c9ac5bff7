"""A simulated PowerCube gripper module (Schunk PG 70 model) and the part between its jaws.

The same protocol and state machine as a joint (:class:`~seqrun.sim.module.SimModule`),
on a linear axis: its position is the jaws' opening width in metres [I: the PG 70's unit;
seqrun's driver converts], 0 closed, :data:`STROKE_M` fully open. A part of a given width
(``ModuleOptions.gripper_part_mm``; 0: no part) stands between the jaws: closing onto it,
the jaws stop at its width while the module keeps pushing towards its target (velocity 0,
CURLIMIT set: the motor at its current limit). Without a part the jaws close fully.
"""

from __future__ import annotations

from seqrun.clock import Clock
from seqrun.powercube.protocol import ParamId, StateFlag
from seqrun.sim.module import ModuleOptions, SimModule

__all__ = ["STROKE_M", "SimGripper", "gripper_parameters"]

#: PG 70: 70 mm of opening [I: datasheet stroke per jaw 35 mm].
STROKE_M = 0.070
_CURLIMIT = int(StateFlag.CURLIMIT)


def gripper_parameters() -> dict[ParamId, float | int]:
    """A PG 70's stored limits in module units (m, m/s, m/s², A) [I]."""
    return {ParamId.DEF_MIN_POS: 0.0, ParamId.DEF_MAX_POS: STROKE_M,
            ParamId.MIN_POS: 0.0, ParamId.MAX_POS: STROKE_M,
            ParamId.DEF_MAX_VEL: 0.082, ParamId.MAX_VEL: 0.082,
            ParamId.DEF_MAX_ACC: 0.4, ParamId.MAX_ACC: 0.4,
            ParamId.TARGET_VEL: 0.05, ParamId.TARGET_ACC: 0.4,
            ParamId.DEF_MAX_CUR: 4.0, ParamId.MAX_CUR: 4.0}


class SimGripper(SimModule):
    """A gripper module with an optional part of ``part_m`` width between its jaws."""

    def __init__(self, module_id: int, clock: Clock, *, part_m: float = 0.0,
                 options: ModuleOptions | None = None,
                 parameters: dict[ParamId, float | int] | None = None) -> None:
        super().__init__(module_id, clock, position=STROKE_M, options=options,
                         parameters={**gripper_parameters(), **(parameters or {})})
        self.part_m = part_m

    def _on_part(self) -> bool:
        return self.part_m > 0 and super()._actual_position() < self.part_m

    def _actual_position(self) -> float:
        position = super()._actual_position()
        return self.part_m if self.part_m > 0 and position < self.part_m else position

    def _actual_velocity(self) -> float:
        return 0.0 if self._on_part() else super()._actual_velocity()

    def _state_bits(self) -> int:
        return super()._state_bits() | (_CURLIMIT if self._on_part() else 0)
