"""The telemetry an expression reads (:mod:`seqrun.steps.expressions`), from the run.

One :class:`TelemetrySampler` per step: each :meth:`~TelemetrySampler.sample` takes one
monitoring cycle of the executor (faults, guards and the watchdog are checked as in any
wait) and gives the values of the names an expression reads, and only those: the tool's
pose only when a ``tool.*`` name is read, the gripper only when a ``gripper.*`` name is.
Velocities are the slope between this reading and the one before (one cycle apart at
least: a first sample reads the arm twice).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from seqrun.steps.context import JointReading, StepContext
    from seqrun.steps.expressions import Expression

__all__ = ["TelemetrySampler"]


class TelemetrySampler:
    """Samples the telemetry namespace for one step's expressions."""

    def __init__(self, ex: StepContext, expressions: list[Expression],
                 params: dict[str, Any] | None = None) -> None:
        self.ex = ex
        self.names: set[str] = set().union(*(e.names for e in expressions)) if expressions \
            else set()
        self.params = params or {}
        self.started_at: float | None = None
        self._last: JointReading | None = None

    @property
    def cycle_s(self) -> float:
        return 1.0 / self.ex.arm.control.cycle_hz

    def sample(self) -> dict[str, Any]:
        """One monitoring cycle, and the values the expressions read."""
        ex = self.ex
        if "vel_deg_s" in self.names and self._last is None:
            self._last = ex.monitor()
            ex.wait(self.cycle_s)
        reading = ex.monitor()
        if self.started_at is None:
            self.started_at = reading.t
        values: dict[str, Any] = {
            "pos_deg": [float(x) for x in reading.user_deg],
            "step_time_s": reading.t - self.started_at,
            "sequence_time_s": ex.elapsed_s(),
            "moving": any(getattr(s, "moving", False) for s in reading.short_state.values()),
        }
        commanded = ex.commanded_deg
        if commanded is not None:
            values["target_deg"] = [float(x) for x in commanded]
            values["following_error_deg"] = [float(c - m) for c, m
                                             in zip(commanded, reading.user_deg, strict=True)]
        else:  # after a Halt nothing is commanded: an expression reading these says so
            values["target_deg"] = values["following_error_deg"] = [None] * len(reading.user_deg)
        last = self._last
        if last is not None and reading.t > last.t:
            values["vel_deg_s"] = [float(v) for v in
                                   (reading.user_deg - last.user_deg) / (reading.t - last.t)]
        elif "vel_deg_s" in self.names:
            values["vel_deg_s"] = [None] * len(reading.user_deg)
        self._last = reading
        if any(n.startswith("tool.") for n in self.names):
            values.update(self._tool(reading))
        if any(n.startswith("gripper.") for n in self.names):
            values.update(self._gripper())
        values.update({f"params.{k}": v for k, v in self.params.items()})
        return values

    def _tool(self, reading: JointReading) -> dict[str, float]:
        from seqrun.arm import kinematics
        from seqrun.arm.cartesian import solver_for, tool_pose

        T = tool_pose(solver_for(self.ex.arm, None), reading.user_deg)
        rpy = np.degrees(kinematics.rpy_from_matrix(T[:3, :3]))
        return {"tool.x_mm": float(T[0, 3]), "tool.y_mm": float(T[1, 3]),
                "tool.z_mm": float(T[2, 3]), "tool.roll_deg": float(rpy[0]),
                "tool.pitch_deg": float(rpy[1]), "tool.yaw_deg": float(rpy[2])}

    def _gripper(self) -> dict[str, Any]:
        from seqrun.errors import RunAborted
        from seqrun.steps._gripper import REST_MM_S

        if self.ex.arm.gripper is None:
            raise RunAborted("no_gripper", "the expression reads the gripper, and the arm "
                                           "file has none")
        reading = self.ex.gripper_read()
        return {"gripper.width_mm": reading.width_mm,
                "gripper.moving": reading.moving,
                "gripper.holding": bool(reading.at_current_limit
                                        and abs(reading.velocity_mm_s) < REST_MM_S)}
