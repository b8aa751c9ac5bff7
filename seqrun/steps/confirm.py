"""confirm: ask the operator; declining ends the run as an operator abort."""

from __future__ import annotations

from seqrun.executor import OperatorAbort


def run(step, ex) -> dict:
    prompt = step.params.prompt
    if ex.confirm is None:  # dry run: nobody to ask
        ex.not_verified.append(f"step {step.number}: operator confirmation '{prompt}' (assumed yes)")
        return {"confirmed": "assumed (dry run)"}
    ex.waiting_for_operator = True
    try:
        ok = ex.confirm(prompt)
    finally:
        ex.waiting_for_operator = False
    if not ok:
        raise OperatorAbort(f"operator declined: {prompt}")
    return {"confirmed": True}
