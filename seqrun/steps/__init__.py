"""The step kinds: one module each (parameters, shorthand, description, static check and
handler), listed in :mod:`seqrun.steps.registry`.

A handler is ``run(step, ex) -> dict | None``: it receives the resolved step (its
validated parameters and source location) and the executor as a
:class:`~seqrun.steps.context.StepContext`, whose methods do the bus work and the safety
checks; the returned dict goes into the step's report entry.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from seqrun.steps.registry import KINDS

Handler = Callable[[Any, Any], "dict | None"]

#: The handler of each step kind, by name (what the executor calls).
HANDLERS: dict[str, Handler] = {kind.name: kind.run for kind in KINDS}
