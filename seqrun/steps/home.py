"""home: enable the motors; the modules refuse motion until HOME_OK."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from seqrun.steps._modules import addressed_modules, addressed_text
from seqrun.steps.kind import StepKind
from seqrun.steps.params import ModulesParams, modules_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep

#: PRL modules home without moving; a module that travels to its home switch takes
#: seconds (as the driver's confirmed Home, it is waited for). This bounds the wait.
HOME_TIMEOUT_S = 60.0


class HomeParams(ModulesParams):
    """Home: enables the motors (audible click) without moving. The modules refuse motion
    until Home; it needs Reset first."""

    kind: ClassVar[str] = "home"
    yaml_name: ClassVar[str] = "home"


def describe(params: HomeParams) -> str:
    return f"home {addressed_text(params)}"


def check(checker: CheckContext, step: ResolvedStep[HomeParams], params: HomeParams) -> None:
    targets = checker.modules(step, params.joints)
    not_reset = [s.joint.name for s in targets if not s.reset and not s.locked]
    if not_reset and not checker.incomplete:
        checker.errors.append(step.error(
            f"home before reset{checker.which(not_reset)}: reset the modules first (Reset "
            "clears the error state they power up with)"))
    for state in targets:
        state.homed = True


def run(step: ResolvedStep[HomeParams], ex: StepContext) -> dict:
    modules = addressed_modules(step.params, ex.arm)
    ex.home_modules(modules)
    states = ex.wait_for_states(modules, lambda state: state.ready,
                                HOME_TIMEOUT_S, "did not report HOME_OK after Home")
    ex.refresh_measurement("home", states)
    return {"states": {str(m): f.describe() for m, f in states.items()}}


KIND = StepKind(
    name="home", params=HomeParams, describe=describe, check=check, run=run,
    value=modules_value("home", HomeParams),
    shorthand=" Shorthand: '- home', 'home: all', 'home: [j1, j2]'.", bare=True)
