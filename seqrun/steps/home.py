"""home: enable the motors; the modules refuse motion until HOME_OK."""

from __future__ import annotations

from seqrun.steps._modules import addressed_modules

#: PRL modules home without moving; this bounds the wait for HOME_OK.
HOME_TIMEOUT_S = 5.0


def run(step, ex) -> dict:
    modules = addressed_modules(step.params, ex.arm)
    ex.home_modules(modules)
    states = ex.wait_for_states(modules, lambda state: state.ready,
                                HOME_TIMEOUT_S, "did not report HOME_OK after Home")
    ex.refresh_measurement("home", states)
    return {"states": {str(m): f.describe() for m, f in states.items()}}
