"""halt: a deliberate stop written in the sequence (modules refuse motion until Reset)."""

from __future__ import annotations

from seqrun.steps._modules import addressed_modules


def run(step, ex) -> dict:
    modules = addressed_modules(step.params, ex.arm)
    ex.halt_modules(modules)
    ex.commanded_deg = None  # nothing is commanded any more
    ex.refresh_measurement("halt")
    return {"modules": "all" if modules is None else modules}
