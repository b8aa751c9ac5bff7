"""One arm's part of a campaign run with several arms (docs/two-arms.md).

Each arm's run writes a whole run folder of its own (``<run>/<id>/``) as one arm's run
does, with two things shared by every arm of the run: the run's one time base (its
events and CAN trace on one time line with the other arms') and the run's one
``<run>/run.mcap`` (that arm's face of it instead of a run.mcap of its own).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from seqrun.service.time_base import TimeBase


@dataclass(frozen=True)
class ArmPart:
    arm_id: str
    time_base: TimeBase
    #: The arm's face of ``<run>/run.mcap`` (:meth:`ArmsMcapLog.for_arm`); None: no
    #: run.mcap (``[ros] mcap = false``, or it could not be opened).
    mcap: Any = None
