"""Every step kind seqrun knows, in the order the docs list them.

A step kind is one module, ``seqrun/steps/<kind>.py``, ending with ``KIND = StepKind(...)``
(:class:`~seqrun.steps.kind.StepKind`: parameters, shorthand, description, static check,
handler); adding one is that module and one line in :data:`KINDS`. The sequence file's
union (:mod:`seqrun.schema`), the static checks (:mod:`seqrun.sequence.validation`) and the executor
(:data:`HANDLERS`) all take the kinds from here; ``include`` is no step kind
but the loader's (its steps run in its place).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from seqrun.steps import (check, check_gripper, checkpoint, confirm, grip, halt, home, move,
                          move_linear, move_trajectory, move_velocity, power_off, release,
                          reset, set_limits, signal, wait, wait_for, wait_until)
from seqrun.steps.kind import StepKind

__all__ = ["HANDLERS", "KINDS", "Handler", "StepKind", "step_kind"]

KINDS: tuple[StepKind, ...] = (
    reset.KIND,
    home.KIND,
    halt.KIND,
    set_limits.KIND,
    move.KIND,
    move_linear.KIND,
    move_trajectory.KIND,
    move_velocity.KIND,
    wait.KIND,
    wait_until.KIND,
    checkpoint.KIND,
    check.KIND,
    grip.KIND,
    release.KIND,
    check_gripper.KIND,
    confirm.KIND,
    power_off.KIND,
    signal.KIND,
    wait_for.KIND,
)

_BY_NAME: dict[str, StepKind] = {kind.name: kind for kind in KINDS}

Handler = Callable[[Any, Any], "dict | None"]

#: The handler of each step kind, by name (what the executor calls).
HANDLERS: dict[str, Handler] = {kind.name: kind.run for kind in KINDS}


def step_kind(name: str) -> StepKind:
    """The step kind called ``name``; KeyError for a name that is none."""
    return _BY_NAME[name]
