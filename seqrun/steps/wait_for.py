"""wait_for: hold (monitored every cycle) until another arm signals a named event."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from pydantic import Field

from seqrun.errors import RunAborted
from seqrun.steps.kind import StepKind
from seqrun.steps.params import Positive, StepParams, one_key_value
from seqrun.steps.signal import EventName

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep

#: How long a wait_for waits when its file says nothing, s.
DEFAULT_TIMEOUT_S = 60.0


class WaitForParams(StepParams):
    """Hold until another arm of the campaign signals an event (a campaign with several
    arms, docs/two-arms.md); the arm is monitored every cycle while it waits. The run
    faults (and halts) when the event does not come within timeout_s, or when the arm that
    would signal it has ended."""

    kind: ClassVar[str] = "wait_for"
    yaml_name: ClassVar[str] = "wait_for"
    event: EventName = Field(description="The event to wait for, e.g. A_holding.")
    # None: a wait the campaign's order adds (the step before, on another arm): bounded by
    # that step's own timeouts, never written in a file (the schema requires a number).
    timeout_s: Positive = Field(
        DEFAULT_TIMEOUT_S, description=f"Longest wait, s (default {DEFAULT_TIMEOUT_S:g}); at "
                                       "most the arm file's control.max_wait_s.")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(event=value)


def describe(params: WaitForParams) -> str:
    return f"wait for {params.event}"


def check(checker: CheckContext, step: ResolvedStep[WaitForParams],
          params: WaitForParams) -> None:
    from seqrun.formatting import format_number as f

    if checker.arm_id is None:
        checker.errors.append(step.error(
            "wait_for synchronises the arms of a campaign with several arms ([arms.ID] in "
            "seqrun.toml); this sequence runs one arm", "event"))
    bound = checker.arm.control.max_wait_s
    if params.timeout_s is not None and params.timeout_s > bound:
        checker.errors.append(step.error(
            f"timeout_s {f(params.timeout_s)} s is longer than the arm file allows "
            f"(control.max_wait_s = {f(bound)} s)", "timeout_s"))


def run(step: ResolvedStep[WaitForParams], ex: StepContext) -> dict:
    params = step.params
    sync = ex.sync
    if sync is None:
        raise RunAborted("no_other_arm", "wait_for needs the other arms of a campaign with "
                                         "several arms")
    period = 1.0 / ex.arm.control.cycle_hz
    waited = 0.0
    while not sync.fired(params.event):
        gone = sync.never(params.event)
        if gone is not None:
            raise RunAborted("other_arm_ended", f"waiting for {_shown(params.event)}: {gone}")
        if params.timeout_s is not None and waited >= params.timeout_s - 1e-9:
            raise RunAborted("event_timeout", f"{_shown(params.event)} did not come within "
                                              f"{params.timeout_s:g} s")
        ex.wait(period)
        waited += period
    return {"waited_s": round(waited, 4), "event": params.event}


def _shown(event: str) -> str:
    """An event for people: the order's own (``~3.A``) as the arm's earlier step."""
    if event.startswith("~"):
        item, _, arm = event[1:].partition(".")
        return f"arm {arm} to finish item {item} of the sequence"
    return f"'{event}'"


KIND = StepKind(
    name="wait_for", params=WaitForParams, describe=describe, check=check, run=run,
    value=one_key_value("wait_for", WaitForParams, text=("event", EventName)),
    shorthand=" Shorthand: 'wait_for: A_holding' (the event, default timeout).",
    example="wait_for: A_holding")
