"""wait: a fixed time, or until in position; monitoring continues every cycle."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar, Literal

from pydantic import ConfigDict, Field, model_validator
from pydantic_core import PydanticCustomError

from seqrun.steps.kind import StepKind
from seqrun.steps.params import Positive, StepParams, exactly_one, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class WaitParams(StepParams):
    """Wait a fixed time, or until every joint is in position."""

    kind: ClassVar[str] = "wait"
    yaml_name: ClassVar[str] = "wait"
    model_config = ConfigDict(json_schema_extra=exactly_one("seconds", "until"))

    seconds: Positive | None = Field(None, description="Time to wait in seconds.")
    until: Literal["in_position"] | None = Field(
        None, description="in_position: wait until every joint is within tolerance_deg of its "
                          "last target.")
    tolerance_deg: Positive | None = Field(
        None, description="For until: in_position; default the arm file's "
                          "control.position_tolerance_deg.")
    timeout_s: Positive | None = Field(
        None, description="For until: in_position; default the arm file's "
                          "control.settle_timeout_s.")

    @model_validator(mode="after")
    def _one(self) -> WaitParams:
        if (self.seconds is None) == (self.until is None):
            raise PydanticCustomError(
                "wait_what", "a wait needs either 'seconds' or 'until'" if self.seconds is None
                else "a wait takes either 'seconds' or 'until', not both")
        if self.seconds is not None and (self.tolerance_deg is not None
                                         or self.timeout_s is not None):
            raise PydanticCustomError("wait_what", "tolerance_deg and timeout_s belong to "
                                                   "'until: in_position', not to 'seconds'")
        return self

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(seconds=value)


def describe(params: WaitParams) -> str:
    return (f"wait {params.seconds:g} s" if params.seconds is not None
            else "wait until in position")


def check(checker: CheckContext, step: ResolvedStep[WaitParams], params: WaitParams) -> None:
    from seqrun.formatting import format_number as f

    checker.after_halt(step, f"{step.kind}")
    bound = checker.arm.control.max_wait_s
    for key in ("seconds", "timeout_s"):
        value = getattr(params, key)
        if value is not None and value > bound:
            checker.errors.append(step.error(
                f"{key} {f(value)} s is longer than the arm file allows "
                f"(control.max_wait_s = {f(bound)} s)", key))


def run(step: ResolvedStep[WaitParams], ex: StepContext) -> dict:
    params = step.params
    if params.seconds is not None:
        ex.wait(params.seconds)
        return {"waited_s": params.seconds}
    tolerance = params.tolerance_deg or ex.arm.control.position_tolerance_deg
    timeout = params.timeout_s or ex.arm.control.settle_timeout_s
    return {"waited_s": round(ex.wait_in_position(tolerance, timeout), 4)}


KIND = StepKind(
    name="wait", params=WaitParams, describe=describe, check=check, run=run,
    value=one_key_value("wait", WaitParams, number=("seconds", Positive)),
    shorthand=" Shorthand: 'wait: 2' (seconds).", example="wait: 2")
