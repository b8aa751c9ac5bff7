"""The part between the simulated gripper's jaws: one answer for the dry run and for every
simulated run (``run --virtual-time``, ``run --sim``, ``console --sim``, ``sim serve``).

Declared where the engineer sees it: the campaign's ``seqrun.toml`` (``[sim]
gripper_part_mm``) first, else the part the sequence's first ``grip`` step names
(``part_width_mm``). Before this, the dry run placed the grip's part while a run on the
built-in simulator had none, so ``validate`` passed and ``run --virtual-time`` faulted.
A simulator switch given by hand (``--bus-kwargs gripper_part_mm=…``,
``SEQRUN_SIM_OPTIONS``) still wins: it is the engineer's explicit rehearsal.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

#: The simulator switch that puts a part between the jaws (``ModuleOptions``).
PART_SWITCH = "gripper_part_mm"


@dataclass(frozen=True)
class SimulatedPart:
    """A part of ``width_mm`` (0: none) between the simulated jaws, and who said so."""

    width_mm: float
    source: str

    def describe(self) -> str:
        what = (f"a {self.width_mm:g} mm part" if self.width_mm > 0 else "no part")
        return f"gripper: {what} between the simulated jaws ({self.source})"


def campaign_part(project: Any) -> SimulatedPart | None:
    """The campaign's ``[sim] gripper_part_mm`` (None: not set, or no campaign)."""
    config = getattr(project, "config", None)
    width = None if config is None else config.sim.gripper_part_mm
    if width is None:
        return None
    return SimulatedPart(float(width), "seqrun.toml [sim] gripper_part_mm")


def simulated_part(steps: Iterable[Any], project: Any = None) -> SimulatedPart | None:
    """The part for a sequence of ``steps`` (resolved steps: ``kind``, ``number``,
    ``params``) in ``project``: the campaign's setting, else the first grip's part,
    else None (no grip: nothing to place)."""
    declared = campaign_part(project)
    if declared is not None:
        return declared
    for step in steps:
        if step.kind == "grip":
            return SimulatedPart(float(step.params.part_width_mm),
                                 f"step {step.number}'s grip part_width_mm")
    return None


def switch_given(bus_kwargs: Mapping[str, Any], environ: Mapping[str, str] | None = None
                 ) -> bool:
    """The engineer set the part by hand: ``--bus-kwargs`` or ``SEQRUN_SIM_OPTIONS``."""
    from seqrun.sim.module import SIM_OPTIONS_ENV

    env = os.environ if environ is None else environ
    return PART_SWITCH in bus_kwargs or PART_SWITCH in env.get(SIM_OPTIONS_ENV, "")
