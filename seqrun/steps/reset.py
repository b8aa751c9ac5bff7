"""reset: clear the modules' error state (broadcast, or per module)."""

from __future__ import annotations

from seqrun.steps._modules import addressed_modules

#: Errors that Reset cannot clear (power cycle needed) are reported, not waited for.
SETTLE_TIMEOUT_S = 1.0


def run(step, ex) -> dict:
    modules = addressed_modules(step.params, ex.arm)
    ex.confirm_clearing_latched(modules)  # a fault from before the run: ask first
    ex.reset_modules(modules)
    states = ex.wait_for_states(modules, lambda state: not state.faulted,
                                SETTLE_TIMEOUT_S, "still reports a fault after Reset")
    ex.refresh_measurement("reset", states)
    return {"states": {str(m): f.describe() for m, f in states.items()}}
