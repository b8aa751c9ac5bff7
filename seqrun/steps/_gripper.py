"""Shared by grip, release and check_gripper: the gripper's checks and waiting on its jaws."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from seqrun.arm.gripper import GripperSpec
    from seqrun.arm.joint_values import GripperReading
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep

#: The jaws are at rest below this speed (mm/s) ...
REST_MM_S = 0.5
#: ... for this many readings in a row.
REST_READINGS = 3


def gripper_of(checker: CheckContext, step: ResolvedStep) -> GripperSpec | None:
    """The arm's gripper; an error at the step when the arm file has none."""
    spec = checker.arm.gripper
    if spec is None:
        checker.errors.append(step.error(
            f"{step.kind}: the arm file has no gripper (add a 'gripper' section: its module "
            "id, stroke and force <-> current table)"))
    return spec


def check_width(checker: CheckContext, step: ResolvedStep, spec: GripperSpec, value: float,
                key: str) -> None:
    from seqrun.formatting import format_number as f

    if value > spec.stroke_mm:
        checker.errors.append(step.error(
            f"{key} {f(value)} mm is beyond the gripper's stroke {f(spec.stroke_mm)} mm", key))


def check_speed(checker: CheckContext, step: ResolvedStep, spec: GripperSpec,
                value: float | None) -> None:
    from seqrun.formatting import format_number as f

    if value is not None and value > spec.max_velocity_mm_s:
        checker.errors.append(step.error(
            f"speed_mm_s {f(value)} mm/s is above the gripper's maximum "
            f"{f(spec.max_velocity_mm_s)} mm/s", "speed_mm_s"))


def gripper_to_use(ex: StepContext, what: str) -> GripperSpec:
    """The arm's gripper at run time (validation has refused a step without one)."""
    from seqrun.errors import RunAborted

    if ex.arm.gripper is None:
        raise RunAborted("no_gripper", f"{what}: the arm file has no gripper")
    return ex.arm.gripper


def move_jaws(ex: StepContext, spec: GripperSpec, what: str, target_mm: float,
              speed_mm_s: float | None, timeout_s: float | None, *, on_part: bool,
              **command: Any) -> GripperReading:
    """Drive the jaws to ``target_mm`` (default speed: the gripper's fastest; default time
    allowed: their travel from where they stand plus the settle time) and wait for rest;
    the ``gripper_command`` event carries ``command``'s fields too."""
    start = ex.gripper_read()
    speed = speed_mm_s or spec.max_velocity_mm_s
    timeout = timeout_s or (spec.travel_time_s(target_mm - start.width_mm, speed)
                            + spec.settle_timeout_s)
    ex.emit("gripper_command", command=what, target_mm=target_mm, speed_mm_s=speed, **command)
    ex.gripper_move(target_mm, speed)
    return wait_for_rest(ex, spec, timeout, what, on_part=on_part)


def wait_for_rest(ex: StepContext, spec: GripperSpec, timeout_s: float, what: str, *,
                  on_part: bool) -> GripperReading:
    """Monitor the arm every cycle and read the gripper until its jaws are at rest (its
    ramp ended; ``on_part``: or stopped pushing at its current limit, on a part); a gripper
    fault or the timeout is a fault (RunAborted)."""
    from seqrun.errors import RunAborted

    cycle = 1.0 / ex.arm.control.cycle_hz
    waited, still = 0.0, 0
    while True:
        ex.wait(cycle)
        waited += cycle
        reading = ex.gripper_read()
        if not reading.ready:
            how = "faulted" if reading.faulted else "is not homed"
            raise RunAborted("gripper_fault", f"{what}: the gripper (module {spec.module}) "
                             f"{how}: {reading.text}", module=spec.module)
        still = still + 1 if abs(reading.velocity_mm_s) < REST_MM_S else 0
        if still >= REST_READINGS and (not reading.moving
                                       or (on_part and reading.at_current_limit)):
            return reading
        if waited > timeout_s:
            raise RunAborted("timeout", f"{what}: the jaws did not come to rest within "
                             f"{timeout_s:.1f} s (at {reading.width_mm:.1f} mm, "
                             f"{reading.velocity_mm_s:+.1f} mm/s)", module=spec.module)


def reading_detail(reading: GripperReading) -> dict[str, Any]:
    return {"width_mm": round(reading.width_mm, 3),
            "at_current_limit": reading.at_current_limit, "state": reading.text}
