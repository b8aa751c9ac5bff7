"""signal: tell the other arms of the campaign that this arm got here (a named event)."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Annotated, Any, ClassVar

from pydantic import AfterValidator, Field
from pydantic_core import PydanticCustomError

from seqrun.errors import RunAborted
from seqrun.steps.kind import StepKind
from seqrun.steps.params import StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep

_EVENT_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_.-]{0,63}$")


def _event_name(value: str) -> str:
    if not _EVENT_RE.match(value):
        raise PydanticCustomError(
            "event_name", "an event name is a letter, then letters, digits, '_', '.' or '-' "
                          "(at most 64), got '{value}'", {"value": value})
    return value


#: A named event between the arms of a campaign (``A_holding``).
EventName = Annotated[str, AfterValidator(_event_name), Field(
    json_schema_extra={"pattern": _EVENT_RE.pattern},
    description="The event's name: a letter, then letters, digits, '_', '.' or '-'.")]


class SignalParams(StepParams):
    """Signal a named event to the other arms of the campaign (a campaign with several
    arms, docs/two-arms.md): their wait_for steps on it go on. Each event is signalled once
    per run."""

    kind: ClassVar[str] = "signal"
    yaml_name: ClassVar[str] = "signal"
    event: EventName = Field(description="The event's name, e.g. A_holding.")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(event=value)


def describe(params: SignalParams) -> str:
    return f"signal {params.event}"


def check(checker: CheckContext, step: ResolvedStep[SignalParams], params: SignalParams) -> None:
    if checker.arm_id is None:
        checker.errors.append(step.error(
            "signal synchronises the arms of a campaign with several arms ([arms.ID] in "
            "seqrun.toml); this sequence runs one arm", "event"))


def run(step: ResolvedStep[SignalParams], ex: StepContext) -> dict:
    if ex.sync is None:
        raise RunAborted("no_other_arm", "signal needs the other arms of a campaign with "
                                         "several arms")
    ex.sync.signal(step.params.event)
    return {"signalled": step.params.event}


KIND = StepKind(
    name="signal", params=SignalParams, describe=describe, check=check, run=run,
    value=one_key_value("signal", SignalParams, text=("event", EventName)),
    shorthand=" Shorthand: 'signal: A_holding' (the event).", example="signal: A_holding")
