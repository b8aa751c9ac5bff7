"""confirm: ask the operator; declining ends the run as an operator abort."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, ClassVar

from pydantic import Field

from seqrun.results import OperatorAbort
from seqrun.steps.kind import StepKind
from seqrun.steps.params import StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class ConfirmParams(StepParams):
    """Stop until the operator confirms (or declines, which ends the run)."""

    kind: ClassVar[str] = "confirm"
    yaml_name: ClassVar[str] = "confirm"
    prompt: str = Field(min_length=1, description="The question or instruction shown to the "
                                                  "operator, e.g. 'Is the desk clear?'.")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(prompt=value)


def describe(params: ConfirmParams) -> str:
    return f"confirm: {params.prompt}"


def check(checker: CheckContext, step: ResolvedStep[ConfirmParams], params: ConfirmParams) -> None:
    """Nothing to check against the arm: the question is asked at run time."""


def run(step: ResolvedStep[ConfirmParams], ex: StepContext) -> dict:
    prompt = step.params.prompt
    if ex.confirm is None:  # dry run: nobody to ask
        ex.not_verified.append(f"step {step.number}: operator confirmation '{prompt}' "
                               "(assumed yes)")
        return {"confirmed": "assumed (dry run)"}
    if not ex.ask_operator(ex.confirm, prompt):
        raise OperatorAbort(f"operator declined: {prompt}")
    return {"confirmed": True}


KIND = StepKind(
    name="confirm", params=ConfirmParams, describe=describe, check=check, run=run,
    value=one_key_value("confirm", ConfirmParams,
                        text=("prompt", Annotated[str, Field(min_length=1)])),
    shorthand=" Shorthand: 'confirm: Is the desk clear?'.",
    example="confirm: Is the desk clear?")
