"""move_linear: the tool in a straight line at a given speed, sampled and checked sample by sample.

Validation solves every sample from the tracked joints; the run solves the line again from
the measured joints, streams it and measures the tool's distance from the line every cycle.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Literal

from pydantic import Field, model_validator

from seqrun.errors import RunAborted
from seqrun.steps.kind import StepKind
from seqrun.steps.params import (HazardKey, Positive, StepParams, Vector3, check_pose_target,
                                 one_key_value)

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class MoveLinearParams(StepParams):
    """Move the tool in a straight line to an end-effector pose at a given speed (mm/s, and
    deg/s for the rotation), as a densely sampled, jerk-limited joint trajectory. Every
    sample is solved and checked before anything moves (reachable, joint and velocity
    limits, away from singularities, the guards); during the run the tool's distance from
    the line is measured and a fault beyond max_deviation_mm."""

    kind: ClassVar[str] = "move_linear"
    yaml_name: ClassVar[str] = "move_linear"

    position_mm: Vector3 = Field(
        description="Tool position at the end of the line [x, y, z] in mm (base frame); with "
                    "relative: true, the displacement in the base or the tool frame (frame).")
    rpy_deg: Vector3 | None = Field(
        None, description="Tool orientation at the end [roll, pitch, yaw] in degrees; required "
                          "unless relative (then a rotation, default none).")
    relative: bool = Field(False, description="true: position_mm/rpy_deg are offsets from "
                                              "where the tool is.")
    frame: Literal["base", "tool"] = Field(
        "base", description="With relative: the frame of the displacement (tool: [0, 0, 50] is "
                            "50 mm along the tool's z axis).")
    tool: str | None = Field(None, min_length=1, description="The arm file's tool that moves "
                                                             "on the line (default: the arm's "
                                                             "default_tool, else the "
                                                             "end-effector frame).")
    speed_mm_s: Positive = Field(description="Speed along the line, mm/s.")
    rotation_speed_deg_s: Positive = Field(
        10.0, description="Largest turning speed of the tool, deg/s.")
    acceleration_mm_s2: Positive = Field(
        50.0, description="Acceleration along the line, mm/s^2 (the rotation's scales alike).")
    jerk_mm_s3: Positive = Field(500.0, description="Jerk along the line, mm/s^3.")
    max_deviation_mm: Positive = Field(
        1.0, description="Largest distance of the tool from the line during the run, mm; "
                         "beyond it the arm is halted.")
    tolerance_deg: Positive | None = Field(
        None, description="In-position tolerance per joint at the end, degrees (default: the "
                          "arm file's control.position_tolerance_deg).")
    timeout_s: Positive | None = Field(
        None, description="Time allowed for the whole move in seconds (default: the planned "
                          "duration plus the arm file's control.settle_timeout_s).")
    hazard: HazardKey = None

    @model_validator(mode="after")
    def _target(self) -> MoveLinearParams:
        check_pose_target(self, "a linear move")
        return self


def describe(params: MoveLinearParams) -> str:
    xyz = ", ".join(f"{v:g}" for v in params.position_mm)
    if params.relative:
        return f"move in a line by [{xyz}] mm ({params.frame} frame)"
    return f"move in a line to [{xyz}] mm"


def check(checker: CheckContext,
          step: ResolvedStep[MoveLinearParams], params: MoveLinearParams) -> None:
    """A straight line of the tool: every sample solved and checked now (reachable,
    limits, joint speeds, manipulability, guards along the samples)."""
    import numpy as np

    from seqrun.arm.cartesian import PathError, plan_linear, pointing_up_hint

    checker.motion_allowed(step, checker.unlocked_names())
    target = checker.tool_target(step, params)
    if target is None:
        return
    keep = 1 - checker.arm.control.tracking_reserve
    max_velocity = np.array([checker.limits.velocity(n).value
                             for n in checker.arm.joint_names]) * keep
    start = checker.tracked()

    def plan(cap: float):
        # The hazard class's speed cap bounds the joint speeds the line may need (the line
        # is not slowed down: a line too fast for it is refused, lower speed_mm_s).
        return plan_linear(
            checker.arm, params.tool, start, target,
            speed_mm_s=params.speed_mm_s * checker.speed,
            rotation_speed_deg_s=params.rotation_speed_deg_s * checker.speed,
            acceleration_mm_s2=params.acceleration_mm_s2 * checker.speed,
            jerk_mm_s3=params.jerk_mm_s3 * checker.speed,
            max_velocity_deg_s=max_velocity * cap)

    cap = checker.hazard_speed_scale(step)
    try:
        linear = plan(cap)
    except PathError as exc:
        hint = pointing_up_hint(checker.arm, params.tool, target) if exc.unreachable else ""
        if cap < 1 and not exc.unreachable:
            hint += f" (the speed cap of its hazard class, {cap * 100:g} %)"
        checker.errors.append(step.error(f"straight line: {exc}{hint}", "position_mm"))
        checker.lost_at = step  # the run ends here: no second error about the steps after
        return
    if checker.outside_limits(step, linear.joints_deg[1:], "the straight line"):
        checker.lost_at = step
        return
    checker.check_path_guards(step, linear.plan.times, linear.plan.positions,
                              what="straight line of the tool")
    derived = checker.hazard_speed_scale(step)  # a class its clearance derives
    if derived < cap:
        try:
            plan(derived)
        except PathError as exc:
            checker.errors.append(step.error(
                f"straight line: {exc} (the speed cap of its hazard class, "
                f"{derived * 100:g} %)", "speed_mm_s"))
    checker.solution_note(step, linear.joints_deg[-1],
                          f" ({linear.path.length_mm:.1f} mm in {linear.plan.duration:.2f} s, "
                          f"smallest manipulability {linear.min_manipulability:.3f})")
    checker.arrive(step, linear.joints_deg[-1])


def run(step: ResolvedStep[MoveLinearParams], ex: StepContext) -> dict:
    import numpy as np

    from seqrun.arm.cartesian import PathError, plan_linear, solver_for, tool_pose
    from seqrun.steps.move_tool import agree, tool_target

    """``move_linear``: the line solved from the measured joints, streamed sample by
    sample; the tool's distance from the line is checked every cycle."""
    params = step.params
    reading = ex.read_arm()
    measured = reading.user_deg
    keep = 1 - ex.arm.control.tracking_reserve
    hazard = ex.hazards.get(step.number)  # its class's speed cap, as validated
    cap = hazard.speed_scale if hazard is not None else 1.0
    max_velocity = (np.array([j.max_velocity_deg_s for j in ex.arm.joints]) * keep * ex.speed
                    * cap)
    try:
        linear = plan_linear(ex.arm, params.tool, measured, tool_target(params, ex, measured),
                             speed_mm_s=params.speed_mm_s * ex.speed,
                             rotation_speed_deg_s=params.rotation_speed_deg_s * ex.speed,
                             acceleration_mm_s2=params.acceleration_mm_s2 * ex.speed,
                             jerk_mm_s3=params.jerk_mm_s3 * ex.speed,
                             max_velocity_deg_s=max_velocity)
    except PathError as exc:
        raise RunAborted("linear_path", f"straight line: {exc}") from None
    detail = agree(step, ex, linear.joints_deg[-1])
    solver = solver_for(ex.arm, params.tool)
    path, limit = linear.path, params.max_deviation_mm
    worst = {"mm": 0.0}

    def deviation(m) -> None:
        off = float(path.deviation_mm(tool_pose(solver, m.user_deg)[:3, 3]))
        worst["mm"] = max(worst["mm"], off)
        if off > limit:
            raise RunAborted("path_deviation",
                             f"the tool is {off:.2f} mm off the straight line (allowed "
                             f"{limit:g} mm)", detail={"max_deviation_mm": round(off, 3)})

    tolerance = params.tolerance_deg or ex.arm.control.position_tolerance_deg
    ex.emit("ik_solved", joints_deg=detail["ik_solution_deg"], samples=len(linear.plan.times),
            length_mm=round(path.length_mm, 3))
    metrics = ex.follow(linear.plan, tolerance_deg=tolerance, timeout_s=params.timeout_s,
                        path_check=deviation, command_mode=ex.arm.cartesian.linear_command_mode,
                        start=reading)
    return {**detail, **metrics, "length_mm": round(path.length_mm, 3),
            "max_deviation_mm": round(worst["mm"], 4),
            "min_manipulability": round(linear.min_manipulability, 4)}


KIND = StepKind(
    name="move_linear", params=MoveLinearParams, describe=describe, check=check, run=run,
    value=one_key_value("move_linear", MoveLinearParams),
    example="move_linear: {position_mm: [0, 0, 50], relative: true, frame: tool, "
            "speed_mm_s: 10}", motion=True)
