"""grip: close the gripper on a part with a given force; passes when the jaws stop on it."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from pydantic import Field

from seqrun.steps.kind import StepKind
from seqrun.steps.params import Positive, StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class GripParams(StepParams):
    """Close the gripper on a part: the grip force is set as the module's current limit
    (the arm file's force <-> current table), the jaws close, and the step passes when they
    stop on the part, within window_mm of its width. Jaws that close past it (no part) or
    stop short of it are a fault. On the simulator (the dry run and every simulated run
    alike) a part of part_width_mm stands between the jaws, unless the campaign's
    seqrun.toml sets another ([sim] gripper_part_mm; 0: none)."""

    kind: ClassVar[str] = "grip"
    yaml_name: ClassVar[str] = "grip"
    part_width_mm: Positive = Field(
        ..., description="Width of the part between the jaws, mm (inside the gripper's "
                         "stroke).")
    force_n: Positive = Field(
        ..., description="Grip force, N; at most the arm file's gripper.max_force_n.")
    window_mm: Positive = Field(
        2.0, description="The jaws must stop within this of part_width_mm, mm.")
    speed_mm_s: Positive | None = Field(
        None, description="Closing speed, mm/s (default and at most: the gripper's "
                          "max_velocity_mm_s).")
    timeout_s: Positive | None = Field(
        None, description="Time allowed, s (default: the jaws' travel plus the gripper's "
                          "settle_timeout_s).")


def describe(params: GripParams) -> str:
    return f"grip a {params.part_width_mm:g} mm part with {params.force_n:g} N"


def check(checker: CheckContext, step: ResolvedStep[GripParams], params: GripParams) -> None:
    from seqrun.formatting import format_number as f
    from seqrun.steps._gripper import check_speed, check_width, gripper_of

    spec = gripper_of(checker, step)
    if spec is None:
        return
    if params.force_n > spec.max_force_n:
        checker.errors.append(step.error(
            f"force_n {f(params.force_n)} N is above the gripper's limit "
            f"{f(spec.max_force_n)} N (gripper.max_force_n)", "force_n"))
    check_width(checker, step, spec, params.part_width_mm, "part_width_mm")
    check_speed(checker, step, spec, params.speed_mm_s)


def run(step: ResolvedStep[GripParams], ex: StepContext) -> dict:
    from seqrun.errors import RunAborted
    from seqrun.steps._gripper import gripper_to_use, move_jaws, reading_detail

    params = step.params
    spec = gripper_to_use(ex, "grip")
    current = ex.gripper_current_limit(spec.current_for(params.force_n))
    # Closing fully: the part stops the jaws; without one they close (and the step fails).
    reading = move_jaws(ex, spec, "grip", 0.0, params.speed_mm_s, params.timeout_s,
                        on_part=True, force_n=params.force_n, current_a=round(current, 4))
    low, high = params.part_width_mm - params.window_mm, params.part_width_mm + params.window_mm
    if reading.width_mm < low:
        raise RunAborted("grip_failed",
                         f"grip: the jaws closed to {reading.width_mm:.1f} mm, past the part "
                         f"({params.part_width_mm:g} ± {params.window_mm:g} mm): no part "
                         "between the jaws", module=spec.module)
    if reading.width_mm > high:
        raise RunAborted("grip_failed",
                         f"grip: the jaws stopped at {reading.width_mm:.1f} mm, short of the "
                         f"part ({params.part_width_mm:g} ± {params.window_mm:g} mm)",
                         module=spec.module)
    if ex.dry_run:
        ex.not_verified.append(f"step {step.number}: the part between the jaws (the dry run "
                               f"placed a {params.part_width_mm:g} mm part there) and the "
                               "grip force (the force <-> current table is the arm file's)")
    return {**reading_detail(reading), "force_n": params.force_n,
            "current_limit_a": round(current, 4)}


KIND = StepKind(
    name="grip", params=GripParams, describe=describe, check=check, run=run,
    value=one_key_value("grip", GripParams),
    example="grip: {part_width_mm: 40, force_n: 100}")
