"""The arm file's gripper: a PowerCube gripper module (Schunk PG 70) on the same bus.

A PG 70 speaks the PowerCube protocol like the joints, but its axis is linear: seqrun speaks
of the jaws' opening width in mm (0: closed, ``stroke_mm``: fully open); the driver alone
converts to the module's units (:mod:`seqrun.drivers.powercube.gripper`). Its grip force is
set through the module's current limit (MaxCur): the arm file gives the force <-> current
table measured for the gripper (:meth:`GripperSpec.current_for`). Optional: an arm without
a ``gripper`` section has none, and the gripper steps are refused for it. Pure data.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["GripperSpec"]

Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]


class GripperSpec(BaseModel):
    """A PowerCube gripper module (e.g. Schunk PG 70) and how hard it may grip."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field("gripper", min_length=1, description="What the operator calls it.")
    module: int = Field(ge=1, le=31, description="PowerCube module id of the gripper on the "
                                                 "CAN bus (not a joint's).")
    stroke_mm: Positive = Field(description="Opening width when fully open, mm (PG 70: 70).")
    max_velocity_mm_s: Positive = Field(
        50.0, description="Jaw speed limit (opening width per second), mm/s.")
    max_acceleration_mm_s2: Positive = Field(
        200.0, description="Jaw acceleration limit, mm/s^2.")
    max_force_n: Positive = Field(
        description="Largest grip force a step may ask for, N (PG 70: 200 N).")
    force_current: list[tuple[NonNegative, Positive]] = Field(
        min_length=2,
        description="The gripper's force <-> current table: [force N, current A] rows, both "
                    "increasing; a grip force is set as the current limit (MaxCur) "
                    "interpolated from it. It must reach max_force_n.")
    position_tolerance_mm: Positive = Field(
        0.5, description="A release is in position within this, mm.")
    settle_timeout_s: Positive = Field(
        3.0, description="Time allowed beyond the jaws' planned travel, s.")

    @model_validator(mode="after")
    def _table(self) -> GripperSpec:
        forces = [f for f, _ in self.force_current]
        currents = [c for _, c in self.force_current]
        if any(b <= a for a, b in zip(forces, forces[1:])) or \
                any(b <= a for a, b in zip(currents, currents[1:])):
            raise ValueError("force_current: forces and currents must both increase row by row")
        if forces[-1] < self.max_force_n:
            raise ValueError(f"force_current ends at {forces[-1]:g} N, below max_force_n "
                             f"{self.max_force_n:g} N")
        return self

    def current_for(self, force_n: float) -> float:
        """The current limit (A) that gives ``force_n``: linear between the table's rows
        (below the first row: its current)."""
        rows = self.force_current
        if force_n <= rows[0][0]:
            return rows[0][1]
        for (f0, c0), (f1, c1) in zip(rows, rows[1:]):
            if force_n <= f1:
                return c0 + (c1 - c0) * (force_n - f0) / (f1 - f0)
        return rows[-1][1]

    def travel_time_s(self, distance_mm: float, speed_mm_s: float) -> float:
        """How long the jaws take for ``distance_mm`` at ``speed_mm_s`` (trapezoid)."""
        v, a = min(speed_mm_s, self.max_velocity_mm_s), self.max_acceleration_mm_s2
        d = abs(distance_mm)
        if d <= v * v / a:
            return 2 * (d / a) ** 0.5
        return d / v + v / a
