"""wait: a fixed time, or until in position; monitoring continues every cycle."""

from __future__ import annotations


def run(step, ex) -> dict:
    params = step.params
    if params.seconds is not None:
        ex.wait(params.seconds)
        return {"waited_s": params.seconds}
    tolerance = params.tolerance_deg or ex.arm.control.position_tolerance_deg
    timeout = params.timeout_s or ex.arm.control.settle_timeout_s
    return {"waited_s": round(ex.wait_in_position(tolerance, timeout), 4)}
