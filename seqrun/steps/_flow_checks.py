"""The static checks of a step's flow keys: ``if``, ``skip_if``, ``repeat``, ``retry`` and
``on_fail``.

Validation follows one path of the arm: the steps that move it or change what the modules
have been told (reset, home, limits, halt, power off) and the signals between arms run
exactly once, where they are written, so their flow is fixed. The others (waits, checks,
checkpoints, questions, the gripper) may be conditional or repeated. Only the steps whose
failures are measurements (docs/safety.md, 'What may be retried') take ``retry``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from seqrun.steps._expression_checks import check_expression

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.resolved import ResolvedStep

__all__ = ["FIXED_FLOW_KINDS", "RETRYABLE_KINDS", "check_block", "check_flow"]

#: Step kinds that always run once, where they are written (besides the kinds that move).
FIXED_FLOW_KINDS = frozenset({"reset", "home", "set_limits", "halt", "power_off", "signal",
                              "wait_for"})
#: Step kinds whose failure may be a measurement that a retry can change.
RETRYABLE_KINDS = frozenset({"check", "wait_until", "checkpoint", "check_gripper"})


def check_flow(checker: CheckContext, step: ResolvedStep[Any], params: Any,
               *, motion: bool) -> None:
    """``params``' flow keys against the step's kind and the arm, each at its key."""
    from seqrun.formatting import format_number as f

    flow = [key for key, value in (("if", params.if_), ("skip_if", params.skip_if),
                                   ("repeat", params.repeat)) if value is not None]
    for key in flow:
        if motion or step.kind in FIXED_FLOW_KINDS:
            why = "moves the arm" if motion else "changes what the modules or arms are told"
            checker.errors.append(step.error(
                f"{key}: a {step.kind} step {why}, and validation follows one path of the "
                "arm: it runs once, where it is written (make the steps around it "
                "conditional instead)", key, key=True))
    if params.if_ is not None:
        check_expression(checker, step, params.if_, "if", condition=True)
    if params.skip_if is not None:
        check_expression(checker, step, params.skip_if, "skip_if", condition=True)
    if params.repeat is not None and params.repeat.while_ is not None:
        check_expression(checker, step, params.repeat.while_, ("repeat", "while"),
                         condition=True)
    if params.retry is not None:
        if step.kind not in RETRYABLE_KINDS:
            checker.errors.append(step.error(
                f"retry: a {step.kind} step does not fail in a way that may be retried (only "
                f"{', '.join(sorted(RETRYABLE_KINDS))} do; a fault is never retried)",
                "retry", key=True))
        bound = checker.arm.control.max_wait_s
        if params.retry.delay_s > bound:
            checker.errors.append(step.error(
                f"delay_s {f(params.retry.delay_s)} s is longer than the arm file allows "
                f"(control.max_wait_s = {f(bound)} s)", "retry", "delay_s"))
    if params.on_fail == "pause":
        check_pause(checker, step)


def check_pause(checker: CheckContext, step: ResolvedStep[Any]) -> None:
    """``on_fail: pause``: on a step whose failure may be retried, outside a block (its
    rescue decides there) and outside a campaign of several arms (a pause changes the
    timing the arms were checked against each other along)."""
    why = (f"a {step.kind} step does not fail in a way the operator may retry or skip "
           f"(only {', '.join(sorted(RETRYABLE_KINDS))} do; a fault is never offered)"
           if step.kind not in RETRYABLE_KINDS else
           "a step in a block: its rescue decides what a failure does (put on_fail on a "
           "step outside the block)" if step.blocks else
           "a campaign of several arms: a pause changes the timing the arms are checked "
           "against each other along" if checker.arm_id is not None else None)
    if why is not None:
        checker.errors.append(step.error(f"on_fail: pause: {why}", "on_fail", key=True))


#: Step kinds that speak to the other arms: never in a rescue or always, whose timing the
#: arms' schedule cannot know (it follows the normal path).
SIGNAL_KINDS = frozenset({"signal", "wait_for"})


def check_block(checker: CheckContext, step: ResolvedStep[Any]) -> None:
    """A step written in a block's rescue or always: not in a campaign of several arms,
    never one that signals the other arms."""
    handler = [f for f in step.blocks if f.part in ("rescue", "always")]
    if handler and checker.arm_id is not None:
        # after a failure these run earlier than on the normal path: the proof that the
        # arms stay clear of each other holds for the normal path's timing only
        checker.errors.append(step.error(
            f"a block's {handler[-1].part} in a campaign of several arms: the arms are "
            "checked against each other along the normal path's timing, which a failure "
            "changes (leave it out: there a failure ends the run and the operator "
            "decides)"))
    elif handler and step.kind in SIGNAL_KINDS:
        checker.errors.append(step.error(
            f"a {step.kind} step in a block's {handler[-1].part} (the arms' schedule follows "
            "the normal path and cannot know when it runs): put it before or after the block"))
