"""Real-time scheduling for a process that runs the 100 Hz control loop beside other work
(the console: web server, telemetry; the browser on the same PC). Linux.

The loop's thread runs at ``SCHED_FIFO`` priority N (:func:`use_fifo`, called in that
thread: Linux schedules threads one by one; the threads it starts, such as a run's log
writer, inherit it, as under ``seqrun run --rt-priority``). Every other thread of the process
runs at ``SCHED_RR`` priority 1 (:func:`use_round_robin`): below the loop, above every
normal process. That matters because the loop needs Python's interpreter lock (GIL) several
times a cycle: a web-server thread holding it must not be kept off the CPU by a busy
browser while the loop waits (priority inversion; seen with bench/bench_console.py).
"""

from __future__ import annotations

import gc
import os
import sys
from pathlib import Path

from seqrun import frozen_objects

#: The priority of the process's other threads (the lowest real-time one).
BASE_PRIORITY = 1
#: How long a thread may keep the interpreter lock while another waits for it, under
#: real-time scheduling. Python's default, 5 ms, lets a web-server thread keep the woken
#: loop waiting for up to half a cycle (the console's tabs then showed in the loop's p99
#: period).
SWITCH_INTERVAL_S = 0.001


def use_fifo(priority: int) -> str | None:
    """Run the calling thread at ``SCHED_FIFO`` ``priority`` (1-99). Returns ``None``, or
    why it could not (no right to: needs root or CAP_SYS_NICE; not Linux)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError, OverflowError) as exc:
        return str(exc) or type(exc).__name__
    return None


def use_round_robin(priority: int = BASE_PRIORITY) -> str | None:
    """Run every thread of this process, and the threads they start later, at ``SCHED_RR``
    ``priority``. Returns ``None``, or why it could not (nothing is changed then)."""
    try:
        param = os.sched_param(priority)
        os.sched_setscheduler(0, os.SCHED_RR, param)  # (new threads inherit the caller's)
        tasks = Path("/proc/self/task")
        for task in tasks.iterdir() if tasks.is_dir() else ():
            try:
                os.sched_setscheduler(int(task.name), os.SCHED_RR, param)
            except ProcessLookupError:  # a thread that ended meanwhile
                pass
    except (OSError, AttributeError, OverflowError) as exc:
        return str(exc) or type(exc).__name__
    return None


def hand_over_the_lock_often() -> None:
    """Make a thread holding the interpreter lock hand it over after at most
    :data:`SWITCH_INTERVAL_S` when another thread (the loop) asks for it."""
    sys.setswitchinterval(SWITCH_INTERVAL_S)


def keep_long_lived_objects_out_of_collections() -> int:
    """Move every object made so far (the web stack, the models, the arm, the session: they
    live as long as the process) out of the cyclic garbage collector's view, and return how
    many. A full collection scans every tracked object while holding the interpreter lock,
    in whichever thread allocates, the loop's included: in the console with three pages
    open that stalled the loop for many cycles now and then, and not once in the runs
    after this."""
    gc.collect()
    frozen_objects.keep()
    return gc.get_freeze_count()


def thread_policy() -> tuple[int, int]:
    """The calling thread's scheduling policy and priority."""
    return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
