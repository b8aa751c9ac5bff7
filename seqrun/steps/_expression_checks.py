"""The static checks every expression of a step gets against the arm file."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.resolved import ResolvedStep

__all__ = ["check_expression", "check_monitors"]


def check_expression(checker: CheckContext, step: ResolvedStep[Any], text: str,
                     key: str | tuple[str | int, ...], *, condition: bool) -> None:
    """The expression under ``key`` (a key of the step's parameters, or a path to it)
    against the arm: its joint numbers, the gripper it reads, and (``condition``) that it
    is a truth value; each problem at the key."""
    from seqrun.steps.expressions import ExpressionError, parse

    path = key if isinstance(key, tuple) else (key,)
    try:
        expression = parse(text, joints=len(checker.arm.joints), params=step.param_types)
    except ExpressionError as exc:
        checker.errors.append(step.error(f"{exc.message} (at column {exc.column} of "
                                         f"'{text}')", *path))
        return
    if condition and not expression.is_condition:
        checker.errors.append(step.error(
            f"'{text}' is a number, not a condition: compare it (e.g. '{text} < 1')", *path))
    if any(n.startswith("gripper.") for n in expression.names) and checker.arm.gripper is None:
        checker.errors.append(step.error(f"'{text}' reads the gripper, and the arm file has "
                                         "none", *path))


def check_monitors(checker: CheckContext, step: ResolvedStep[Any], monitors: Any) -> None:
    """A step's monitors: each a condition the arm can be read for every cycle (the
    gripper and the motor currents are not read in the control loop, so a monitor cannot
    watch them)."""
    for i, monitor in enumerate(monitors):
        text = monitor.while_
        errors = len(checker.errors)
        check_expression(checker, step, text, ("monitors", i, "while"), condition=True)
        if len(checker.errors) > errors:
            continue
        for name, what in (("gripper.", "the gripper is"), ("current_a", "the currents are")):
            if name in text:
                checker.errors.append(step.error(
                    f"monitor '{text}': {what} not read every cycle; watch it with a "
                    "wait_until or check step", "monitors", i, "while"))
                break
