"""The steps only a person at the run answers: a signed confirm, a breakpoint, a step
with ``on_fail: pause`` and a hazardous step (never ``--yes`` or the console's assume-yes;
docs/safety.md, "Who answers what")."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any


def first_attended(steps: Iterable[Any], hazards: Mapping[int, Any] | None = None) -> str | None:
    """The first step that only a person answers (a signed confirm, a breakpoint, an
    ``on_fail: pause``, a step of class hazardous: given by its ``hazard`` key, or derived
    by the validation as ``hazards`` hold it), as "step N (FILE:LINE:COL) is …"; None when
    there is none."""
    found = hazards or {}
    for step in steps:
        params = step.params
        hazard = found.get(step.number)
        what = ("a signed confirm" if getattr(params, "sign", False) else
                "a breakpoint" if getattr(params, "breakpoint", False) else
                "a step with on_fail: pause" if getattr(params, "on_fail", None) == "pause"
                else f"hazardous ({hazard.reason}; a signed confirm before it)"
                if hazard is not None and hazard.needs_signature else
                "hazardous (a signed confirm before it)"
                if getattr(params, "hazard", None) == "hazardous" else None)
        if what is not None:
            return f"step {step.number} ({step.location}) is {what}"
    return None


def yes_refusal(steps: Iterable[Any], hazards: Mapping[int, Any] | None = None) -> str | None:
    """Why ``--yes`` refuses a run of ``steps`` (one line; None: it does not): a run
    started to go unattended must not stop halfway to wait for a person."""
    found = first_attended(steps, hazards)
    if found is None:
        return None
    return (f"--yes: {found}, which only a person at the run answers; run without --yes; "
            "nothing was sent")
