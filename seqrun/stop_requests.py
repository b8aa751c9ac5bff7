"""Stop requests (abort, Halt) handed to the control loop by signal handlers and other threads.

A Python signal handler runs in the main thread between two bytecodes of whatever the main
thread is doing: inside a display's lock, inside the executor's, inside a log write. A
handler that takes a lock, or calls listeners that do, can deadlock the run. So posting a
request takes no lock and calls nothing: it appends to a deque (atomic in CPython). The
control loop takes the requests at its next cycle and acts on them there.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

#: Cause of a Halt the operator asked for (second Ctrl-C, SIGTERM, a STOP button): exit 130.
OPERATOR_HALT = "operator_halt"
#: Halts from outside the run (exit 3): a Halt from another process (``seqrun halt`` in
#: another terminal: its broadcast seen on the bus, or its request on the control socket),
#: and a request frame of another master on the bus.
REMOTE_HALT = "remote_halt"
FOREIGN_MASTER = "foreign_master"
FROM_OUTSIDE = (REMOTE_HALT, FOREIGN_MASTER)


@dataclass(frozen=True)
class StopRequest:
    kind: str                      # "abort" (controlled stop) | "halt"
    reason: str
    cause: str = OPERATOR_HALT     # halts only: the fault cause reported (exit 130 or 3)


class StopRequests:
    """Lock-free inbox of stop requests; safe to post from a signal handler."""

    def __init__(self) -> None:
        self._queue: deque[StopRequest] = deque()

    def abort(self, reason: str) -> None:
        """Ask for a controlled stop (a second abort is a Halt)."""
        self._queue.append(StopRequest("abort", reason))

    def halt(self, reason: str, cause: str = OPERATOR_HALT) -> None:
        """Ask for a Halt; ``cause`` other than :data:`OPERATOR_HALT` ends the run as a
        fault (exit 3)."""
        self._queue.append(StopRequest("halt", reason, cause))

    def take(self) -> list[StopRequest]:
        """Every request posted so far, oldest first (control loop only)."""
        out = []
        while True:
            try:
                out.append(self._queue.popleft())
            except IndexError:
                return out

    def __bool__(self) -> bool:
        return bool(self._queue)
