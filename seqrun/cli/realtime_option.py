"""``--rt-priority N`` of ``seqrun console`` and ``seqrun jog``: the session's control loop
(its activity thread) at SCHED_FIFO N, the process's other threads at SCHED_RR 1 (below
the loop, above every normal process), the interpreter lock handed over within a
millisecond (seqrun/service/realtime.py). ``seqrun run`` drives its loop from the main
thread and sets it up itself (seqrun/cli/run.py)."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

RtPriorityOption = Annotated[Optional[int], typer.Option(
    "--rt-priority", metavar="N", min=1, max=99,
    help="Run the control loop's thread with real-time scheduling (SCHED_FIFO priority N) "
         "and the other threads at SCHED_RR 1, below it (needs the right to, e.g. root or "
         "CAP_SYS_NICE). Keeps the 100 Hz loop (and the modules' watchdog refresh) on time "
         "on a busy host.")]


def use_realtime(priority: int, others: str) -> bool:
    """Every thread of this process at SCHED_RR 1 from now on, the session's loop thread at
    SCHED_FIFO ``priority`` (it asks for it when it starts: ``loop_priority``), the
    interpreter lock's switch interval shortened. Says whether it could (``others``: who
    the other threads are, for the line); tried in a thread of its own first (this one
    must not keep FIFO)."""
    import threading

    from seqrun.service.realtime import (
        SWITCH_INTERVAL_S,
        hand_over_the_lock_often,
        use_fifo,
        use_round_robin,
    )

    outcome: list[str | None] = []
    probe = threading.Thread(target=lambda: outcome.append(use_fifo(priority)))
    probe.start()
    probe.join()
    why = outcome[0] if outcome else "?"
    if why is None:
        why = use_round_robin()
    if why is None:
        hand_over_the_lock_often()
        typer.echo(f"real-time scheduling: the control loop at SCHED_FIFO priority "
                   f"{priority}, {others} at SCHED_RR 1, the interpreter "
                   f"lock handed over within {SWITCH_INTERVAL_S * 1000:g} ms")
        return True
    typer.echo(f"warning: real-time scheduling not available ({why}); the control loop "
               "runs at normal priority", err=True)
    return False
