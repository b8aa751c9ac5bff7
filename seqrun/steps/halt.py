"""halt: a deliberate stop written in the sequence (modules refuse motion until Reset)."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from seqrun.steps._modules import addressed_modules, addressed_text
from seqrun.steps.kind import StepKind
from seqrun.steps.params import ModulesParams, modules_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class HaltParams(ModulesParams):
    """Halt: stops at once; the modules then refuse motion until Reset."""

    kind: ClassVar[str] = "halt"
    yaml_name: ClassVar[str] = "halt"


def describe(params: HaltParams) -> str:
    return f"halt {addressed_text(params)}"


def check(checker: CheckContext, step: ResolvedStep[HaltParams], params: HaltParams) -> None:
    for state in checker.modules(step, params.joints):
        state.halted = True


def run(step: ResolvedStep[HaltParams], ex: StepContext) -> dict:
    modules = addressed_modules(step.params, ex.arm)
    ex.halt_modules(modules)
    ex.commanded_deg = None  # nothing is commanded any more
    ex.refresh_measurement("halt")
    return {"modules": "all" if modules is None else modules}


KIND = StepKind(
    name="halt", params=HaltParams, describe=describe, check=check, run=run,
    value=modules_value("halt", HaltParams),
    shorthand=" Shorthand: '- halt', 'halt: all', 'halt: [j1, j2]'.", bare=True)
