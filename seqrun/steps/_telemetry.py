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

__all__ = ["TelemetrySampler", "reading_values", "values_read"]


class TelemetrySampler:
    """Samples the telemetry namespace for one step's expressions."""

    def __init__(self, ex: StepContext, expressions: list[Expression],
                 params: dict[str, Any] | None = None) -> None:
        self.ex = ex
        self.names: set[str] = set().union(*(e.names for e in expressions)) if expressions \
            else set()
        #: The joints whose current an expression reads (a read each, when sampled).
        self.current_joints = sorted(set().union(
            *(e.joints for e in expressions if "current_a" in e.names)))
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
        values = reading_values(ex.arm, reading, self._last, ex.commanded_deg, self.names,
                                step_time_s=reading.t - self.started_at,
                                sequence_time_s=ex.elapsed_s())
        self._last = reading
        if any(n.startswith("gripper.") for n in self.names):
            values.update(self._gripper())
        if "current_a" in self.names:
            values["current_a"] = ex.joint_currents_a(self.current_joints)
        values.update({f"params.{k}": v for k, v in self.params.items()})
        return values

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


def reading_values(arm: Any, reading: JointReading, last: JointReading | None,
                   commanded: Any, names: set[str] | frozenset[str], *,
                   step_time_s: float, sequence_time_s: float) -> dict[str, Any]:
    """The values of ``names`` (the gripper aside) at one reading: ``last`` is the reading
    before (velocities; None: none yet), ``commanded`` what the joints are to be at now
    (None: nothing, or a Halt since). Only what ``names`` reads is computed: a monitor
    runs this every control cycle."""
    values: dict[str, Any] = {"step_time_s": step_time_s, "sequence_time_s": sequence_time_s}
    measured = reading.user_deg
    n = len(measured)
    if "pos_deg" in names:
        values["pos_deg"] = measured.tolist()
    if "moving" in names:
        values["moving"] = any(getattr(s, "moving", False)
                               for s in reading.short_state.values())
    if "target_deg" in names:
        values["target_deg"] = [None] * n if commanded is None else list(commanded)
    if "following_error_deg" in names:
        # nothing commanded: an expression reading it says it has no value
        values["following_error_deg"] = ([None] * n if commanded is None
                                         else (commanded - measured).tolist())
    if "vel_deg_s" in names:
        # between when the joints answered (a late-read answer is not a fast joint)
        t, t_last = _answered(reading), None if last is None else _answered(last)
        values["vel_deg_s"] = ((measured - last.user_deg) / (t - t_last)).tolist() \
            if last is not None and t_last is not None and t > t_last else [None] * n
    if any(name.startswith("tool.") for name in names):
        values.update(_tool(arm, reading, names))
    return values


def _answered(reading: JointReading) -> float:
    """When the joints answered (their mean, where the bus stamps them), else read."""
    return float(getattr(reading, "at", reading.t))


def _tool(arm: Any, reading: JointReading, names: set[str] | frozenset[str]
          ) -> dict[str, float]:
    from seqrun.arm import kinematics
    from seqrun.arm.cartesian import solver_for, tool_pose

    T = tool_pose(solver_for(arm, None), reading.user_deg)
    values = {"tool.x_mm": float(T[0, 3]), "tool.y_mm": float(T[1, 3]),
              "tool.z_mm": float(T[2, 3])}
    if names & {"tool.roll_deg", "tool.pitch_deg", "tool.yaw_deg"}:
        roll, pitch, yaw = np.degrees(kinematics.rpy_from_matrix(T[:3, :3])).tolist()
        values.update({"tool.roll_deg": roll, "tool.pitch_deg": pitch, "tool.yaw_deg": yaw})
    return values


def values_read(values: dict[str, Any], expression: Expression) -> dict[str, Any]:
    """The values ``expression`` read, for a report: per joint only the joints it indexes
    (``pos_deg[2]``), numbers rounded."""
    shown: dict[str, Any] = {}
    for name in sorted(expression.names):
        value = values.get(name)
        if isinstance(value, list):
            for j in sorted(expression.joints):
                v = value[j - 1]
                shown[f"{name}[{j}]"] = None if v is None else round(float(v), 4)
        elif isinstance(value, float):
            shown[name] = round(value, 4)
        else:
            shown[name] = value
    return shown
