"""confirm: ask the operator; declining ends the run as an operator abort."""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Protocol, TypeVar

from pydantic import Field

from seqrun.results import OperatorAbort
from seqrun.steps.kind import StepKind
from seqrun.steps.params import StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import AttendedQuestions, StepContext
    from seqrun.steps.resolved import ResolvedStep


_Answer = TypeVar("_Answer")


class Signing(Protocol):
    """What asking for a signature needs of the run (a step's context, the executor
    before a hazardous step)."""

    dry_run: bool
    not_verified: list[str]
    inputs_sha256: str | None

    @property
    def attended(self) -> AttendedQuestions | None: ...

    def ask_operator(self, question: Callable[[Any], _Answer], arg: Any) -> _Answer: ...

    def emit(self, type_: str, **data: Any) -> None: ...


class ConfirmParams(StepParams):
    """Stop until the operator confirms (or declines, which ends the run)."""

    kind: ClassVar[str] = "confirm"
    yaml_name: ClassVar[str] = "confirm"
    prompt: str = Field(min_length=1, description="The question or instruction shown to the "
                                                  "operator, e.g. 'Is the desk clear?'.")
    role: str | None = Field(None, min_length=1, max_length=80,
                             description="Who is to answer, e.g. 'test conductor' (shown "
                                         "with the question, kept with the signature).")
    sign: bool = Field(False, description="A signed confirm: whoever answers yes gives "
                                          "their name, recorded with the role, the time "
                                          "(UTC) and the sha256 of the validated inputs in "
                                          "record.json, report.json and report.html; "
                                          "--yes never answers it.")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(prompt=value)


def describe(params: ConfirmParams) -> str:
    signed = f" (signed{f' by the {params.role}' if params.role else ''})" if params.sign else ""
    return f"confirm: {params.prompt}{signed}"


def check(checker: CheckContext, step: ResolvedStep[ConfirmParams], params: ConfirmParams) -> None:
    """Nothing to check against the arm: the question is asked at run time."""


def run(step: ResolvedStep[ConfirmParams], ex: StepContext) -> dict:
    prompt = step.params.prompt
    if step.params.sign:
        return _signed(step, ex)
    if ex.confirm is None:  # dry run: nobody to ask
        ex.not_verified.append(f"step {step.number}: operator confirmation '{prompt}' "
                               "(assumed yes)")
        return {"confirmed": "assumed (dry run)"}
    if not ex.ask_operator(ex.confirm, prompt):
        raise OperatorAbort(f"operator declined: {prompt}")
    return {"confirmed": True}


def _signed(step: ResolvedStep[ConfirmParams], ex: StepContext) -> dict:
    """A signed confirm: only a person answers it, and their name is kept with what they
    signed (the validated inputs' sha256) and when."""
    params = step.params
    return ask_signature(ex, step.number, params.prompt, params.role)


def ask_signature(ex: Signing, number: int, prompt: str, role: str | None) -> dict:
    """Ask ``prompt`` of the person at the run, who answers yes with their name (never
    --yes); the signature as a step's detail keeps it. A no, or nobody to ask:
    OperatorAbort. The dry run assumes yes and says so."""
    by = f" by the {role}" if role else ""
    if ex.dry_run:
        ex.not_verified.append(f"step {number}: signed operator confirmation "
                               f"'{prompt}'{by} (assumed yes)")
        return {"confirmed": "assumed (dry run)"}
    if ex.attended is None:
        raise OperatorAbort(f"nobody to sign '{prompt}'{by} (a signed confirm is "
                            "answered by a person, never by --yes)")
    attended = ex.attended
    name = ex.ask_operator(lambda text: attended.sign(text, role), prompt)
    if not name:
        raise OperatorAbort(f"operator declined: {prompt}")
    signature = {"signed_by": str(name), "signed_role": role,
                 "signed_at_utc": _dt.datetime.now(_dt.timezone.utc)
                 .isoformat(timespec="seconds").replace("+00:00", "Z"),
                 "inputs_sha256": ex.inputs_sha256}
    ex.emit("confirm_signed", text=prompt, **signature)
    return {"confirmed": True, **signature}


KIND = StepKind(
    name="confirm", params=ConfirmParams, describe=describe, check=check, run=run,
    value=one_key_value("confirm", ConfirmParams,
                        text=("prompt", Annotated[str, Field(min_length=1)])),
    shorthand=" Shorthand: 'confirm: Is the desk clear?'.",
    example="confirm: Is the desk clear?")
