"""Real-time scheduling for the thread that runs the 100 Hz control loop (Linux).

Linux schedules threads one by one, so only the calling thread is changed: the web server,
the telemetry fan-out and the status poll of the same process keep normal priority. Threads
the loop's thread starts later (a run's log writer, the watchdog keeper) start at normal
priority too (``SCHED_RESET_ON_FORK``), as they would without this.
"""

from __future__ import annotations

import os


def use_fifo(priority: int) -> str | None:
    """Run the calling thread at ``SCHED_FIFO`` ``priority`` (1-99). Returns ``None``, or
    why it could not (no right to: needs root or CAP_SYS_NICE; not Linux)."""
    try:
        policy = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
        os.sched_setscheduler(0, policy, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return str(exc) or type(exc).__name__
    return None


def thread_policy() -> tuple[int, int]:
    """The calling thread's scheduling policy (without the reset-on-fork flag) and priority."""
    policy = os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)
    return policy, os.sched_getparam(0).sched_priority
