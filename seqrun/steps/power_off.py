"""power_off: check the arm stands in a power-off pose, then record the zero reference.

The modules take the position they are switched off in as their encoder zero, so the
next power-on needs to know where that was (:mod:`seqrun.service.zero`). Nothing is sent to the
modules: the step measures, compares and records. The record is written through
``ex.record_zero(pose)`` (set by whoever runs the sequence); a dry run records nothing.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from pydantic import Field

from seqrun.errors import RunAborted
from seqrun.steps.kind import StepKind
from seqrun.steps.params import PoseName, Positive, StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class PowerOffParams(StepParams):
    """End of a shutdown: check the arm stands in a power-off pose of the arm file, then
    record that it is powered off there (its modules take their zero there)."""

    kind: ClassVar[str] = "power_off"
    yaml_name: ClassVar[str] = "power_off"
    pose: PoseName = Field(description="A power-off pose of the arm file (power_off_poses), "
                                       "e.g. totem.")
    tolerance_deg: Positive | None = Field(
        None, description="How far each joint may be from the pose, degrees (default the arm "
                          "file's control.position_tolerance_deg).")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(pose=value)


def describe(params: PowerOffParams) -> str:
    return f"power off in {params.pose}"


def check(checker: CheckContext,
          step: ResolvedStep[PowerOffParams], params: PowerOffParams) -> None:
    """The pose must be a power-off pose of the arm, and where the moves before end."""
    from seqrun.formatting import format_number as f

    if params.pose not in checker.arm.power_off_poses:
        known = ", ".join(checker.arm.power_off_poses) or "none"
        checker.errors.append(step.error(
            f"'{params.pose}' is not a power-off pose of arm '{checker.arm.name}' (its "
            f"power-off poses: {known}; power_off_poses in the arm file)", "pose"))
        return
    target = checker.arm.power_off_joints_deg(params.pose)
    tolerance = params.tolerance_deg or checker.arm.control.position_tolerance_deg
    off = [f"{n} {f(s.position)}° (pose {f(target[n])}°)"
           for n, s in checker.joints.items()
           if not s.locked and abs(s.position - target[n]) > tolerance]
    if off:
        checker.errors.append(step.error(
            f"this power_off cannot pass: after the moves before it the arm is not in "
            f"{params.pose}: {', '.join(off)}"))
    checker.powered_off = step


def run(step: ResolvedStep[PowerOffParams], ex: StepContext) -> dict:
    pose = step.params.pose
    target = ex.arm.power_off_joints_deg(pose)  # user degrees: every module reads 0 there
    tolerance = step.params.tolerance_deg or ex.arm.control.position_tolerance_deg
    measured = ex.monitor()
    away = {j.name: float(measured.user_deg[i]) - target[j.name]
            for i, j in enumerate(ex.arm.joints) if j.locked is None}
    off = {name: d for name, d in away.items() if abs(d) > tolerance}
    detail = {"pose": pose, "tolerance_deg": tolerance,
              "deviation_deg": {n: round(d, 4) for n, d in away.items()}}
    if off:
        worst = ", ".join(f"{n} {d:+.2f}°" for n, d in off.items())
        raise RunAborted("power_off", f"power_off: the arm is not in {pose} ({worst} away; "
                                      f"tolerance {tolerance:g}°): nothing recorded",
                         detail=detail)
    recorder = ex.record_zero
    if ex.dry_run or recorder is None:
        ex.not_verified.append(f"step {step.number}: the zero reference '{pose}' is not "
                               "recorded (a dry run, or the built-in simulator, whose zero "
                               "is its power-on pose)")
        return {**detail, "recorded": None}
    record = recorder(pose)
    ex.emit("zero_recorded", pose=pose, text=str(record))
    return {**detail, "recorded": str(record)}


KIND = StepKind(
    name="power_off", params=PowerOffParams, describe=describe, check=check, run=run,
    value=one_key_value("power_off", PowerOffParams, text=("pose", PoseName)),
    shorthand=" Shorthand: 'power_off: totem'.", example="power_off: totem")
