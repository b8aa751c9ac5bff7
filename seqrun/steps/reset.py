"""reset: clear the modules' error state (broadcast, or per module)."""

from __future__ import annotations

from seqrun.powercube.protocol import StateFlag
from seqrun.steps._modules import addressed_modules

#: Errors that Reset cannot clear (power cycle needed) are reported, not waited for.
SETTLE_TIMEOUT_S = 1.0


def run(step, ex) -> dict:
    modules = addressed_modules(step.params, ex.arm)
    ex.confirm_clearing_latched(modules)  # a fault from before the run: ask first
    if modules is None:
        ex.client.reset(None)
    else:
        for module in modules:
            ex.client.reset(module)
    states = ex.wait_for_states(modules, lambda f: not f & StateFlag.FAULTS,
                                SETTLE_TIMEOUT_S, "still reports a fault after Reset")
    return {"states": {str(m): f.describe() for m, f in states.items()}}
