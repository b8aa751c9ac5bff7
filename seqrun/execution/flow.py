"""A step's flow: ``if`` / ``skip_if`` at its start, ``repeat``, ``retry``, ``on_fail``, and
which branches a run took.

The executor hands each step with flow keys to :meth:`StepFlow.run` with two callables of
its own: ``begin`` (the step's event and monitors for an iteration or an attempt) and
``once`` (the kind's handler, its monitors stopped after it). A step without these keys
never comes here: it runs exactly as before they existed.

Conditions are read from one monitoring cycle of the arm at the moment they are needed
(faults and guards are checked as in any wait), with the same expression language and
telemetry as ``wait_until`` and ``check``. A retry follows only a failure the step marked
retryable (:attr:`seqrun.errors.RunAborted.retryable`: a measurement that did not meet its
bound while nothing moved), and only while no Halt or abort is pending: a module fault, a
Halt, a guard or monitor halt and an operator abort end the run as before
(docs/safety.md, "What may be retried"). After the same failures, ``on_fail: pause`` asks
the operator (seqrun/execution/on_fail.py) once the step's own retries are spent.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from seqrun.errors import RunAborted
from seqrun.results import OperatorAbort, UntakenBranch

if TYPE_CHECKING:
    from seqrun.execution.stops import StopControl
    from seqrun.results import StepResult
    from seqrun.steps.resolved import ResolvedStep

__all__ = ["StepFlow", "has_flow"]


def has_flow(params: Any) -> bool:
    """Whether a step's parameters use any flow key."""
    return (any(getattr(params, key, None) is not None
                for key in ("if_", "skip_if", "repeat", "retry"))
            or getattr(params, "on_fail", None) == "pause")


class _SkippedByOperator(Exception):
    """The operator chose Skip at a step's ``on_fail: pause`` (the step's result says so)."""


@dataclass
class _Seen:
    """What one step's flow did in this run (for the branches not taken)."""

    location: str
    #: per key ("if", "skip_if", "repeat while"): its condition and the values it had
    values: dict[str, tuple[str, set[bool]]] = field(default_factory=dict)
    retry_possible: bool = False
    retried: bool = False
    pause_possible: bool = False
    paused: bool = False


class StepFlow:
    """Runs steps with flow keys and remembers which branches the run took."""

    def __init__(self, ex: Any, stops: StopControl) -> None:
        #: The executor as a step handler sees it (a StepContext; the handlers take it
        #: untyped too, seqrun.steps.registry.Handler: its readings are the executor's).
        self.ex = ex
        self.stops = stops
        self._seen: dict[int, _Seen] = {}

    # ------------------------------------------------------------------ the step
    def run(self, step: ResolvedStep[Any], result: StepResult,
            begin: Callable[..., None], once: Callable[[], dict]) -> dict | None:
        """Run ``step`` as its flow keys say; returns the detail of its last run, or
        None when it did not run or the operator skipped it after a failure (``result``
        then says skipped, or failed and skipped by the operator)."""
        seen = self._seen.setdefault(step.number, _Seen(result.location))
        try:
            return self._run(step, result, begin, once, seen)
        except _SkippedByOperator:
            return None

    def _run(self, step: ResolvedStep[Any], result: StepResult,
             begin: Callable[..., None], once: Callable[[], dict], seen: _Seen) -> dict | None:
        params = step.params
        for key, text, runs_when in (("if", params.if_, True),
                                     ("skip_if", params.skip_if, False)):
            if text is None:
                continue
            value, values = self._evaluate(step, key, text, seen)
            if value is not runs_when:
                self._skip(step, result, key, text, value, values)
                return None
        repeat = params.repeat
        if repeat is None:
            begin(step, result)
            return self._attempts(step, result, begin, once, seen)
        bound = repeat.count if repeat.count is not None else repeat.max
        # what the lines show: "(2/3)" for a count, "(2, at most 10)" for a while
        told = ({"iterations": repeat.count} if repeat.count is not None
                else {"max_iterations": repeat.max})
        detail: dict = {}
        iteration = 0
        while True:
            if repeat.while_ is not None:
                value, values = self._evaluate(step, "repeat while", repeat.while_, seen)
                if not value:
                    if iteration == 0:
                        self._skip(step, result, "repeat while", repeat.while_, value, values)
                        return None
                    break
                if iteration == bound:
                    raise RunAborted("repeat", f"repeat: '{repeat.while_}' still held after "
                                               f"max {bound} iterations", detail=values)
            elif iteration == bound:
                break
            iteration += 1
            begin(step, result, iteration=iteration, bound=told)
            detail = self._attempts(step, result, begin, once, seen)
        return {**detail, "iterations": iteration}

    def _attempts(self, step: ResolvedStep[Any], result: StepResult,
                  begin: Callable[..., None], once: Callable[[], dict], seen: _Seen) -> dict:
        """The step's run, retried as its ``retry`` allows, then (``on_fail: pause``) as
        the operator chooses: Retry, Skip or Abort. The dry run never pauses: its failure
        ends it as without on_fail (what the operator would choose is not verified)."""
        retry = step.params.retry
        pause = step.params.on_fail == "pause"
        seen.retry_possible = seen.retry_possible or retry is not None
        seen.pause_possible = seen.pause_possible or pause
        attempt = retried = 0   # every run again; those of the step's own retry
        while True:
            try:
                return once()
            except RunAborted as exc:
                if (not exc.retryable or self.stops.halt_request is not None
                        or self.stops.aborts):
                    raise
                if retry is not None and retried < retry.times:
                    retried += 1
                    seen.retried = True
                    self.ex.emit("step_retry", attempt=retried, times=retry.times,
                                 cause=exc.cause, message=str(exc), delay_s=retry.delay_s)
                    result.detail.setdefault("retries", []).append(
                        {"attempt": retried, "after": str(exc)})
                    if retry.delay_s > 0:
                        self.ex.wait(retry.delay_s)
                elif pause and not self.ex.dry_run:
                    seen.paused = True
                    if self.ex.pause_on_failure(step, result, exc) == "skip":
                        raise _SkippedByOperator() from None
                else:
                    raise
                attempt += 1
            if self.stops.aborts:
                raise OperatorAbort("operator abort")
            begin(step, result, attempt=attempt)

    # ------------------------------------------------------------------ conditions
    def _evaluate(self, step: ResolvedStep[Any], key: str, text: str,
                  seen: _Seen) -> tuple[bool, dict[str, Any]]:
        """The condition now, on one reading of the arm; and the values it read."""
        from seqrun.steps._telemetry import TelemetrySampler, values_read
        from seqrun.steps.expressions import ExpressionError, parse

        condition = parse(text, joints=len(self.ex.arm.joints), params=step.param_types)
        values = TelemetrySampler(self.ex, [condition], dict(step.param_values)).sample()
        try:
            value = bool(condition.evaluate(values))
        except ExpressionError as exc:
            raise RunAborted("expression", f"{key} '{text}': {exc.message}") from None
        seen.values.setdefault(key, (text, set()))[1].add(value)
        return value, values_read(values, condition)

    def _skip(self, step: ResolvedStep[Any], result: StepResult, key: str, text: str,
              value: bool, values: dict[str, Any]) -> None:
        result.status = "skipped"
        result.detail.update({"skipped_by": key, "condition": text, "value": value,
                              "values": values})
        self.ex.emit("step_skipped", kind=step.kind, label=result.label,
                     location=result.location, key=key, condition=text, value=value,
                     values=values)

    # ------------------------------------------------------------------ coverage
    def not_taken(self) -> list[UntakenBranch]:
        """Every branch of the steps with flow keys that this run did not take, each with
        its line (what a dry run lists as not verified)."""
        branches = []
        for number, seen in sorted(self._seen.items()):
            where = f"step {number} ({seen.location})"
            for key, (text, values) in seen.values.items():
                for value in (True, False):
                    if value not in values:
                        branches.append(UntakenBranch(
                            number, key, value,
                            f"{where}: {key} '{text}' was never "
                            f"{'true' if value else 'false'}, so {_branch(key, value)} was "
                            "not exercised"))
            if seen.retry_possible and not seen.retried:
                branches.append(UntakenBranch(
                    number, "retry", None, f"{where}: its retry was never exercised (the "
                                           "step never failed in a way that may be retried)"))
            if seen.pause_possible and not seen.paused:
                branches.append(UntakenBranch(
                    number, "on_fail", None, f"{where}: on_fail: pause: the operator's "
                                             "choice (retry, skip, abort) is not verified"))
        return branches


def _branch(key: str, value: bool) -> str:
    """What a value of a flow key's condition leads to."""
    runs = value if key != "skip_if" else not value
    if key == "repeat while":
        return "an iteration" if value else "the loop's end by its condition"
    return "running the step" if runs else "skipping the step"
