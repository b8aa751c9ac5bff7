"""The steps only a person at the run answers: a signed confirm, a breakpoint and a step
with ``on_fail: pause`` (never ``--yes`` or the console's assume-yes; docs/safety.md, "Who
answers what")."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any


def first_attended(steps: Iterable[Any]) -> str | None:
    """The first step that only a person answers (a signed confirm, a breakpoint, an
    ``on_fail: pause``), as
    "step N (FILE:LINE:COL) is a …"; None when there is none."""
    for step in steps:
        params = step.params
        what = ("a signed confirm" if getattr(params, "sign", False) else
                "a breakpoint" if getattr(params, "breakpoint", False) else
                "a step with on_fail: pause" if getattr(params, "on_fail", None) == "pause"
                else None)
        if what is not None:
            return f"step {step.number} ({step.location}) is {what}"
    return None
