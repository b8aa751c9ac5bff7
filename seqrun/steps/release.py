"""release: open the gripper to a width."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from pydantic import Field

from seqrun.steps.kind import StepKind
from seqrun.steps.params import Positive, StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class ReleaseParams(StepParams):
    """Open the gripper's jaws to a width (letting go of a part); passes when they are
    there within the gripper's position_tolerance_mm."""

    kind: ClassVar[str] = "release"
    yaml_name: ClassVar[str] = "release"
    width_mm: Positive = Field(
        ..., description="Opening width to go to, mm (inside the gripper's stroke).")
    speed_mm_s: Positive | None = Field(
        None, description="Opening speed, mm/s (default and at most: the gripper's "
                          "max_velocity_mm_s).")
    timeout_s: Positive | None = Field(
        None, description="Time allowed, s (default: the jaws' travel plus the gripper's "
                          "settle_timeout_s).")


def describe(params: ReleaseParams) -> str:
    return f"open the gripper to {params.width_mm:g} mm"


def check(checker: CheckContext, step: ResolvedStep[ReleaseParams],
          params: ReleaseParams) -> None:
    from seqrun.steps._gripper import check_speed, check_width, gripper_of

    spec = gripper_of(checker, step)
    if spec is None:
        return
    check_width(checker, step, spec, params.width_mm, "width_mm")
    check_speed(checker, step, spec, params.speed_mm_s)


def run(step: ResolvedStep[ReleaseParams], ex: StepContext) -> dict:
    from seqrun.errors import RunAborted
    from seqrun.steps._gripper import gripper_to_use, move_jaws, reading_detail

    params = step.params
    spec = gripper_to_use(ex, "release")
    reading = move_jaws(ex, spec, "release", params.width_mm, params.speed_mm_s,
                        params.timeout_s, on_part=False)
    if abs(reading.width_mm - params.width_mm) > spec.position_tolerance_mm:
        raise RunAborted("release_failed",
                         f"release: the jaws stopped at {reading.width_mm:.1f} mm, not at "
                         f"{params.width_mm:g} mm (tolerance {spec.position_tolerance_mm:g} "
                         "mm)", module=spec.module)
    return reading_detail(reading)


KIND = StepKind(
    name="release", params=ReleaseParams, describe=describe, check=check, run=run,
    value=one_key_value("release", ReleaseParams),
    example="release: {width_mm: 60}")
