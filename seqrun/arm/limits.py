"""The velocity and acceleration limits in force for each joint, and where each comes from.

A move is planned within the narrowest of:

- the arm file (``max_velocity_deg_s``, ``max_acceleration_deg_s2``);
- what the modules hold: MaxVel/MaxAcc stay stored in a module until it is written again
  or powered off, so a ``set_limits`` of an earlier run (or another tool) still binds.
  The executor reads them back in its preflight (``read_back``) and a ``set_limits`` step
  replaces them (``written``).

A module never moves faster than its MaxVel nor accelerates faster than its MaxAcc; a plan
above either makes the joint lag behind its plan until the run halts on a following error.
The plan keeps ``control.tracking_reserve`` of the velocity in force for catching up, and
asks the modules for ``control.module_acceleration_factor`` times its acceleration, so the
plan's acceleration stays below MaxAcc divided by that factor.

Pure: no I/O. Values in user degrees (velocities have no offset).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from seqrun.arm.description import ArmDescription

__all__ = ["ARM_FILE", "READBACK", "Bound", "LimitsInForce"]

#: Source of a limit that comes from the arm file.
ARM_FILE = "arm file"
#: Source of a limit read back from a module in the preflight.
READBACK = "module readback"


@dataclass(frozen=True)
class Bound:
    """One limit and where it comes from (``arm file``, ``set_limits at FILE:LINE:COL``,
    ``module readback``)."""

    value: float
    source: str


class LimitsInForce:
    """Per joint: the arm file's maxima and the MaxVel/MaxAcc the modules hold."""

    def __init__(self, arm: ArmDescription) -> None:
        self.arm = arm
        self.factor = arm.control.module_acceleration_factor
        self._velocity: dict[str, Bound] = {}      # what each module holds, deg/s
        self._acceleration: dict[str, Bound] = {}  # deg/s^2

    def copy(self) -> LimitsInForce:
        other = LimitsInForce(self.arm)
        other._velocity, other._acceleration = dict(self._velocity), dict(self._acceleration)
        return other

    # -- what the modules hold
    def read_back(self, values: Mapping[str, tuple[float, float]]) -> None:
        """MaxVel (deg/s) and MaxAcc (deg/s^2) per joint, as read from the modules."""
        for name, (velocity, acceleration) in values.items():
            self._velocity[name] = Bound(float(velocity), READBACK)
            self._acceleration[name] = Bound(float(acceleration), READBACK)

    def written(self, source: str, velocity: Mapping[str, float] | None = None,
                acceleration: Mapping[str, float] | None = None) -> None:
        """A set_limits step wrote these MaxVel/MaxAcc values (``source``: where it is)."""
        for name, value in (velocity or {}).items():
            self._velocity[name] = Bound(float(value), source)
        for name, value in (acceleration or {}).items():
            self._acceleration[name] = Bound(float(value), source)

    # -- what a plan may use
    def velocity(self, name: str) -> Bound:
        """Largest velocity a plan may give joint ``name`` (deg/s), before scaling."""
        arm = Bound(self.arm.joint(name).max_velocity_deg_s, ARM_FILE)
        held = self._velocity.get(name)
        return held if held is not None and held.value < arm.value else arm

    def acceleration(self, name: str) -> Bound:
        """Largest acceleration a plan may give joint ``name`` (deg/s^2), before scaling:
        the module must accelerate ``factor`` times faster than the plan to follow it."""
        arm = Bound(self.arm.joint(name).max_acceleration_deg_s2, ARM_FILE)
        held = self._acceleration.get(name)
        if held is None or held.value / self.factor >= arm.value:
            return arm
        return Bound(held.value / self.factor,
                     f"{held.source} (MaxAcc {_g(held.value)} deg/s^2 / "
                     f"module_acceleration_factor {_g(self.factor)})")

    def narrowed(self, names: Iterable[str] | None = None) -> dict[str, dict[str, object]]:
        """The joints (of ``names``) whose limits in force are below the arm file's:
        ``{joint: {max_velocity_deg_s, velocity_from, max_acceleration_deg_s2,
        acceleration_from}}`` (for reports; empty when the arm file's apply)."""
        out: dict[str, dict[str, object]] = {}
        for name in names if names is not None else self.arm.joint_names:
            velocity, acceleration = self.velocity(name), self.acceleration(name)
            if velocity.source == ARM_FILE and acceleration.source == ARM_FILE:
                continue
            out[name] = {"max_velocity_deg_s": round(velocity.value, 4),
                         "velocity_from": velocity.source,
                         "max_acceleration_deg_s2": round(acceleration.value, 4),
                         "acceleration_from": acceleration.source}
        return out

    def maxima(self) -> tuple[dict[str, float], dict[str, float]]:
        """``(velocity deg/s, acceleration deg/s^2)`` per joint, for the planner."""
        names = self.arm.joint_names
        return ({n: self.velocity(n).value for n in names},
                {n: self.acceleration(n).value for n in names})


def _g(value: float) -> str:
    return f"{round(float(value), 4) + 0.0:g}"
