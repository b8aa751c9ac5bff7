"""wait_until: wait until a condition on the telemetry holds (for persist_s), or time out."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Literal

from pydantic import Field

from seqrun.steps.kind import StepKind
from seqrun.steps.params import ExpressionText, Positive, StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class WaitUntilParams(StepParams):
    """Wait, monitoring every cycle, until a condition on the telemetry has held for
    persist_s; at timeout_s fail (a fault: the arm halts) or continue, as on_timeout says."""

    kind: ClassVar[str] = "wait_until"
    yaml_name: ClassVar[str] = "wait_until"
    until: ExpressionText = Field(description="The condition, e.g. 'gripper.holding' or "
                                              "'abs(vel_deg_s[1]) < 0.1'.")
    timeout_s: Positive = Field(description="How long to wait at most, seconds.")
    persist_s: float = Field(0.0, ge=0, allow_inf_nan=False,
                             description="How long the condition must hold without a break, "
                                         "seconds (0: the first time it holds).")
    poll_hz: Positive | None = Field(None, description="How often to evaluate it (default: "
                                                       "every control cycle).")
    on_timeout: Literal["fail", "continue"] = Field(
        "fail", description="fail: the run ends as a fault (exit 3); continue: the step ends "
                            "and says it timed out, the sequence goes on.")


def describe(params: WaitUntilParams) -> str:
    return f"wait until {params.until}"


def check(checker: CheckContext, step: ResolvedStep[WaitUntilParams],
          params: WaitUntilParams) -> None:
    from seqrun.formatting import format_number as f
    from seqrun.steps._expression_checks import check_expression

    check_expression(checker, step, params.until, "until", condition=True)
    bound = checker.arm.control.max_wait_s
    if params.timeout_s > bound:
        checker.errors.append(step.error(
            f"timeout_s {f(params.timeout_s)} s is longer than the arm file allows "
            f"(control.max_wait_s = {f(bound)} s)", "timeout_s"))
    if params.persist_s >= params.timeout_s:
        checker.errors.append(step.error(
            f"persist_s {f(params.persist_s)} s is not shorter than timeout_s "
            f"{f(params.timeout_s)} s: the condition could never be seen to persist",
            "persist_s"))
    if params.poll_hz is not None and params.poll_hz > checker.arm.control.cycle_hz:
        checker.errors.append(step.error(
            f"poll_hz {f(params.poll_hz)} is faster than the control loop "
            f"({f(checker.arm.control.cycle_hz)} Hz)", "poll_hz"))


def run(step: ResolvedStep[WaitUntilParams], ex: StepContext) -> dict:
    from seqrun.errors import RunAborted
    from seqrun.steps._telemetry import TelemetrySampler
    from seqrun.steps.expressions import ExpressionError, parse

    params = step.params
    condition = parse(params.until, joints=len(ex.arm.joints), params=step.param_types)
    sampler = TelemetrySampler(ex, [condition], dict(step.param_values))
    period = 1.0 / (params.poll_hz or ex.arm.control.cycle_hz)
    held_since: float | None = None
    while True:
        values = sampler.sample()
        elapsed = values["step_time_s"]
        try:
            holds = bool(condition.evaluate(values))
        except ExpressionError as exc:
            raise RunAborted("expression", f"wait_until '{params.until}': {exc.message}") \
                from None
        if holds:
            held_since = elapsed if held_since is None else held_since
            if elapsed - held_since >= params.persist_s:
                return {"waited_s": round(elapsed, 4), "condition": params.until,
                        "held_s": round(elapsed - held_since, 4)}
        else:
            held_since = None
        if elapsed >= params.timeout_s:
            detail = {"waited_s": round(elapsed, 4), "condition": params.until,
                      "timed_out": True}
            ex.emit("wait_timed_out", condition=params.until,
                    timeout_s=params.timeout_s, on_timeout=params.on_timeout)
            if params.on_timeout == "continue":
                return detail
            raise RunAborted("timeout", f"wait_until: '{params.until}' did not hold within "
                             f"{params.timeout_s:g} s", detail=detail, retryable=True)
        if period > sampler.cycle_s:
            ex.wait(period - sampler.cycle_s)


KIND = StepKind(
    name="wait_until", params=WaitUntilParams, describe=describe, check=check, run=run,
    value=one_key_value("wait_until", WaitUntilParams),
    example="wait_until: {until: 'gripper.holding', timeout_s: 5}")
