"""One handler per step type.

A handler is ``run(step, executor) -> dict | None``: it receives the resolved step (its
validated parameters and source location) and the executor, whose methods do the bus
work and the safety checks; the returned dict goes into the step's report entry.
"""

from __future__ import annotations

from typing import Any, Callable

from seqrun.steps import (checkpoint, confirm, halt, home, move, move_tool, power_off, reset,
                          set_limits, wait)

Handler = Callable[[Any, Any], "dict | None"]

HANDLERS: dict[str, Handler] = {
    "reset": reset.run,
    "home": home.run,
    "halt": halt.run,
    "set_limits": set_limits.run,
    "move": move.run,
    "move_linear": move_tool.run_linear,
    "wait": wait.run,
    "checkpoint": checkpoint.run,
    "confirm": confirm.run,
    "power_off": power_off.run,
}
