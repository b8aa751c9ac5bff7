"""check: an immediate assertion on the telemetry, reported like a checkpoint."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from pydantic import Field

from seqrun.steps.kind import StepKind
from seqrun.steps.params import ExpressionText, StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep

class CheckParams(StepParams):
    """Check a condition on the telemetry now; if it does not hold, the run ends as a
    failed checkpoint (exit 3, the arm halted)."""

    kind: ClassVar[str] = "check"
    yaml_name: ClassVar[str] = "check"
    that: ExpressionText = Field(description="The condition, e.g. 'tool.z_mm > 40'.")
    message: str | None = Field(None, min_length=1,
                                description="What a failure means, for the operator.")

    @classmethod
    def from_shorthand(cls, value: Any) -> CheckParams:
        return value if isinstance(value, cls) else cls(that=value)


def describe(params: CheckParams) -> str:
    return f"check {params.that}"


def check(checker: CheckContext, step: ResolvedStep[CheckParams], params: CheckParams) -> None:
    from seqrun.steps._expression_checks import check_expression

    check_expression(checker, step, params.that, "that", condition=True)


def run(step: ResolvedStep[CheckParams], ex: StepContext) -> dict:
    from seqrun.errors import RunAborted
    from seqrun.steps._telemetry import TelemetrySampler, values_read
    from seqrun.steps.expressions import ExpressionError, parse

    params = step.params
    condition = parse(params.that, joints=len(ex.arm.joints), params=step.param_types)
    values = TelemetrySampler(ex, [condition], dict(step.param_values)).sample()
    detail: dict[str, Any] = {"condition": params.that, "values": values_read(values, condition)}
    if params.verifies:
        detail["verifies"] = list(params.verifies)
    try:
        holds = bool(condition.evaluate(values))
    except ExpressionError as exc:
        raise RunAborted("expression", f"check '{params.that}': {exc.message}",
                         detail=detail) from None
    detail["passed"] = holds
    ex.emit("check", **detail)
    if not holds:
        why = f" ({params.message})" if params.message else ""
        raise RunAborted("checkpoint", f"check failed: {params.that}{why}", detail=detail,
                         retryable=True)
    return detail


KIND = StepKind(
    name="check", params=CheckParams, describe=describe, check=check, run=run,
    value=one_key_value("check", CheckParams, text=("that", ExpressionText)),
    shorthand=" Shorthand: 'check: tool.z_mm > 40'.", example="check: tool.z_mm > 40")
