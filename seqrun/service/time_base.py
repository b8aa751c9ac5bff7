"""One time base: how readings of a run's clock map to wall-clock (epoch) time.

A run's clock is ``time.monotonic`` of the seqrun process (real time) or the run's
virtual clock (``--virtual-time``; two arms share one, :class:`~seqrun.clock.LockstepClock`).
Its reading ``c`` happened at ``epoch_s + (c - clock_s)``: the run log stamps the CAN
trace that way (candump's absolute times) and gives each run's start (``run_started``:
``clock_s`` and ``start_epoch_s``). A campaign run with several arms takes ONE time base
for all of them (``<run>/arms.json`` ``time_base``), so every arm's events and trace lines
lie on one time line: arm X's event at ``t`` happened at its start's ``clock_s + t`` on
the run clock, at ``start_epoch_s + t`` on the wall clock, whichever arm it is.
"""

from __future__ import annotations

import datetime as _dt
import time
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class TimeBase:
    """The run clock's reading ``clock_s`` happened at wall-clock time ``epoch_s``."""

    epoch_s: float
    clock_s: float
    virtual: bool = False

    @classmethod
    def of(cls, clock: Any) -> TimeBase:
        """The time base of ``clock`` taken now. At virtual time the epoch is a whole
        second: the trace keeps microseconds, and with a whole-second origin every stamp
        rounds the same way in every run (the virtual times of two frames compare as
        exactly as the trace allows, run after run)."""
        epoch = time.time()
        virtual = bool(getattr(clock, "is_virtual", False))
        if virtual:
            epoch = float(int(epoch))
        return cls(epoch, float(clock.now()), virtual)

    def epoch(self, reading: float) -> float:
        """The wall-clock time of a reading of the run clock."""
        return self.epoch_s + (reading - self.clock_s)

    def reading(self, epoch: float) -> float:
        """The run clock's reading at a wall-clock time (a trace line's stamp)."""
        return epoch - self.epoch_s + self.clock_s

    def as_dict(self) -> dict[str, Any]:
        return {"clock": "virtual" if self.virtual else "monotonic",
                "clock_s": self.clock_s, "epoch_s": self.epoch_s, "utc": utc(self.epoch_s),
                "rule": "a reading c of the run clock happened at epoch_s + (c - clock_s); "
                        "an arm's event at t: at its start's clock_s + t"}


def utc(epoch: float) -> str:
    """ISO 8601 UTC, to the millisecond."""
    return _dt.datetime.fromtimestamp(epoch, _dt.timezone.utc).isoformat(timespec="milliseconds")
