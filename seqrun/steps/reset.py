"""reset: clear the modules' error state (broadcast, or per module)."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from seqrun.steps._modules import addressed_modules, addressed_text
from seqrun.steps.kind import StepKind
from seqrun.steps.params import ModulesParams, modules_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep

#: Errors that Reset cannot clear (power cycle needed) are reported, not waited for.
SETTLE_TIMEOUT_S = 1.0


class ResetParams(ModulesParams):
    """Reset: clears the modules' error state (and a Halt). Parameters can be written after it;
    the first step of every start-up."""

    kind: ClassVar[str] = "reset"
    yaml_name: ClassVar[str] = "reset"


def describe(params: ResetParams) -> str:
    return f"reset {addressed_text(params)}"


def check(checker: CheckContext, step: ResolvedStep[ResetParams], params: ResetParams) -> None:
    for state in checker.modules(step, params.joints):
        state.reset, state.halted = True, False


def run(step: ResolvedStep[ResetParams], ex: StepContext) -> dict:
    modules = addressed_modules(step.params, ex.arm)
    ex.confirm_clearing_latched(modules)  # a fault from before the run: ask first
    ex.reset_modules(modules)
    states = ex.wait_for_states(modules, lambda state: not state.faulted,
                                SETTLE_TIMEOUT_S, "still reports a fault after Reset")
    ex.refresh_measurement("reset", states)
    return {"states": {str(m): f.describe() for m, f in states.items()}}


KIND = StepKind(
    name="reset", params=ResetParams, describe=describe, check=check, run=run,
    value=modules_value("reset", ResetParams),
    shorthand=" Shorthand: '- reset', 'reset: all', 'reset: [j1, j2]'.", bare=True)
