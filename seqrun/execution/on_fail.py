"""A step's ``on_fail: pause``: after a failure that may be retried (its own ``retry``
spent), the arm at rest, the operator chooses Retry, Skip or Abort.

Only the failures ``retry`` follows come here (:attr:`seqrun.errors.RunAborted.retryable`,
no Halt or abort pending): a module fault, a Halt, a guard or monitor halt end the run as
before. Nobody to ask (the input ended, the question withdrawn) is an abort. A Skip leaves
the step failed ("skipped by the operator") and checks the rest of the sequence from the
measured arm, as a Resume does, before anything moves; a refusal ends the run there
(docs/safety.md, "Who answers what").
"""

from __future__ import annotations

from typing import Any

from seqrun.errors import RunAborted
from seqrun.results import OperatorAbort, StepResult

__all__ = ["CHOICES", "pause_on_failure"]

#: What the operator may answer, in the order offered.
CHOICES = ("retry", "skip", "abort")


def pause_on_failure(run: Any, loaded: Any, step: Any, result: StepResult,
                     exc: RunAborted, title: str) -> str:
    """Ask the operator about ``step``'s failure ``exc``; "retry" or "skip" (after the
    rest of ``loaded`` was checked from the measured arm); an abort raises
    :class:`OperatorAbort`. ``run`` is the executor."""
    message = run.describe_error(exc)
    attended = run.attended
    choice: str | None = None
    if attended is not None:
        choice = run.ask_operator(
            lambda prompt: attended.choose(prompt, CHOICES),
            f"{title} failed: {message}. Retry, skip or abort?")
    # who answered where: the terminal, the console (None: nobody, an abort)
    by = (getattr(attended, "where", "operator") if choice is not None else
          "nobody answered")
    chosen = choice or "abort"
    run.emit("operator_choice", choice=chosen, by=by, cause=exc.cause, message=message)
    result.detail.setdefault("operator_choices", []).append(
        {"choice": chosen, "by": by, "after": message})
    if chosen == "abort":
        raise OperatorAbort(f"operator abort after {title} failed: {message}"
                            if choice is not None else
                            f"{title} failed with on_fail: pause and nobody answered: "
                            f"{message}")
    if chosen == "skip":
        result.status = "failed"
        result.finished = run.elapsed_s()
        result.detail["error"] = message
        result.detail["skipped_by"] = "operator"
        _check_the_rest(run, loaded, step)
    return chosen


def _check_the_rest(run: Any, loaded: Any, step: Any) -> None:
    """The steps after ``step``, checked from where the arm stands (the preflight's check,
    as a Resume does); an error ends the run before anything moves."""
    rest = [s.number for s in loaded.steps if s.number > step.number]
    if not rest:
        return
    found = run.preflight(loaded, rest[0])
    run.emit("skip_recheck", first_step=rest[0], steps=len(rest),
             errors=[str(e) for e in found.errors])
    if found.errors:
        raise RunAborted("skip_recheck", "the steps after the skipped step are not valid "
                         "from where the arm stands: "
                         + "; ".join(str(e) for e in found.errors))
