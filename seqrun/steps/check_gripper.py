"""check_gripper: a checkpoint on the gripper: holding a part, and/or its opening width."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from pydantic import Field, model_validator
from pydantic_core import PydanticCustomError

from seqrun.steps.kind import StepKind
from seqrun.steps.params import Positive, StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class CheckGripperParams(StepParams):
    """Check the gripper's state: whether it holds a part (the jaws at rest, pushing at
    their current limit) and/or its opening width. A difference is a fault."""

    kind: ClassVar[str] = "check_gripper"
    yaml_name: ClassVar[str] = "check_gripper"
    holding: bool | None = Field(
        None, description="true: the jaws must be holding a part; false: they must not.")
    width_mm: Positive | None = Field(
        None, description="Expected opening width, mm.")
    tolerance_mm: Positive = Field(
        1.0, description="How far the width may be from width_mm, mm.")

    @model_validator(mode="after")
    def _something(self) -> CheckGripperParams:
        if self.holding is None and self.width_mm is None:
            raise PydanticCustomError("check_gripper", "check_gripper needs 'holding', "
                                                       "'width_mm' or both")
        return self


def describe(params: CheckGripperParams) -> str:
    parts = []
    if params.holding is not None:
        parts.append("holding a part" if params.holding else "not holding")
    if params.width_mm is not None:
        parts.append(f"open {params.width_mm:g} mm")
    return "check the gripper: " + ", ".join(parts)


def check(checker: CheckContext, step: ResolvedStep[CheckGripperParams],
          params: CheckGripperParams) -> None:
    from seqrun.steps._gripper import check_width, gripper_of

    spec = gripper_of(checker, step)
    if spec is not None and params.width_mm is not None:
        check_width(checker, step, spec, params.width_mm, "width_mm")


def run(step: ResolvedStep[CheckGripperParams], ex: StepContext) -> dict:
    from seqrun.errors import RunAborted
    from seqrun.steps._gripper import REST_MM_S, reading_detail

    params = step.params
    spec = ex.arm.gripper
    if spec is None:
        raise RunAborted("no_gripper", "check_gripper: the arm file has no gripper")
    reading = ex.gripper_read()
    holding = reading.at_current_limit and abs(reading.velocity_mm_s) < REST_MM_S
    problems = []
    if params.holding is not None and holding != params.holding:
        problems.append("holds a part" if holding else "holds no part")
    if params.width_mm is not None and \
            abs(reading.width_mm - params.width_mm) > params.tolerance_mm:
        problems.append(f"is open {reading.width_mm:.1f} mm, expected {params.width_mm:g} ± "
                        f"{params.tolerance_mm:g} mm")
    if problems:
        raise RunAborted("checkpoint_failed", "gripper check: the gripper "
                         + " and ".join(problems), module=spec.module, retryable=True)
    return {**reading_detail(reading), "holding": holding}


KIND = StepKind(
    name="check_gripper", params=CheckGripperParams, describe=describe, check=check, run=run,
    value=one_key_value("check_gripper", CheckGripperParams),
    example="check_gripper: {holding: true}")
