"""confirm: ask the operator; declining ends the run as an operator abort."""

from __future__ import annotations

from seqrun.results import OperatorAbort


def run(step, ex) -> dict:
    prompt = step.params.prompt
    if ex.confirm is None:  # dry run: nobody to ask
        ex.not_verified.append(f"step {step.number}: operator confirmation '{prompt}' (assumed yes)")
        return {"confirmed": "assumed (dry run)"}
    if not ex.ask_operator(ex.confirm, prompt):
        raise OperatorAbort(f"operator declined: {prompt}")
    return {"confirmed": True}
