"""What this computer did to a run: the host stalls (stretches in which it did not run
seqrun's control loop), the loop's period, the scheduling the run had and the load.

A busy PC stops the control loop for tenths of a second now and then; the plan is held
meanwhile (``host_stall`` events), but a fault can still follow, and its verdict alone
("j7 does not follow its plan") leaves the engineer guessing. :class:`HostWatch` listens
to the run's events (a recorder: a few operations per event, never blocking) and gives

- :meth:`HostWatch.explain`: the fault of a run that faulted after stalls, with the
  stalls named (how long the process was not scheduled, when, and that the modules kept
  their last command meanwhile), for the terminal verdict and report.json;
- :meth:`HostWatch.summary`: report.json's ``host`` (report.html's "host" section).

:func:`busy_host_note`: the one line ``seqrun run`` says at start on a busy host at normal
priority.
"""

from __future__ import annotations

import dataclasses
import os
from collections import Counter
from typing import Any

from seqrun.events import Event
from seqrun.results import RunResult

#: Stalls this long before a fault are named in its verdict (s of the run's time).
STALL_WINDOW_S = 10.0
#: Stalls listed one by one in report.json (the count and the total cover all).
MAX_LISTED = 50
#: The loop period's histogram bins (s): 0.1 ms.
_BIN_S = 1e-4
#: Faults a descheduled simulator (or interface driver) on a busy host causes: answers
#: that come late or not at all, joints that lag as their answers wait.
_SILENCE = ("no_acknowledge", "bus_error", "following_error")

_POLICIES = {getattr(os, name): name for name in
             ("SCHED_OTHER", "SCHED_FIFO", "SCHED_RR", "SCHED_BATCH", "SCHED_IDLE")
             if hasattr(os, name)}


def scheduling() -> dict[str, Any]:
    """The calling thread's scheduling: policy name, real-time priority, nice value."""
    try:
        policy = os.sched_getscheduler(0)
        priority = os.sched_getparam(0).sched_priority
        nice = os.getpriority(os.PRIO_PROCESS, 0)
    except (OSError, AttributeError):
        return {"policy": "unknown", "priority": None, "nice": None}
    return {"policy": _POLICIES.get(policy, str(policy)), "priority": priority, "nice": nice}


def load_average() -> list[float] | None:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def real_time(sched: dict[str, Any]) -> bool:
    return sched.get("policy") in ("SCHED_FIFO", "SCHED_RR")


def busy_host_note(load: list[float] | None = None, cores: int | None = None,
                   sched: dict[str, Any] | None = None) -> str | None:
    """One line for the start of a run at normal priority on a busy computer (the load
    average over the last minute above its core count); None otherwise. The load, the
    core count and the scheduling are this process's unless given."""
    load = load_average() if load is None else load
    cores = (os.cpu_count() or 1) if cores is None else cores
    if load is None or load[0] <= cores or real_time(scheduling() if sched is None else sched):
        return None
    return (f"note: this computer is busy (load {load[0]:.1f} on {cores} cores) and the run "
            "is at normal priority: other work can keep the control loop off the CPU for "
            "tenths of a second (the plan is held meanwhile, but a fault may follow); "
            "--rt-priority 20 runs the loop at SCHED_FIFO, ahead of that work")


class HostWatch:
    """Listener of one run's events (see the module docstring)."""

    def __init__(self, *, wall_clock: bool = True) -> None:
        #: The run's clock is the wall clock (at virtual time the host's load is no cause).
        self.wall_clock = wall_clock
        self.stalls: list[dict[str, Any]] = []   # the first MAX_LISTED
        self.count = 0
        self.stalled_s = 0.0
        self.longest_s = 0.0
        self.fault_t: float | None = None
        self._recent: list[tuple[float, float, float, int | None]] = []   # (t, s, plan_t, step)
        self._last_cycle: float | None = None
        self._periods: Counter[int] = Counter()
        self.scheduling = scheduling()
        self.load_start = load_average()

    def __call__(self, event: Event | dict) -> None:
        kind = event.type if isinstance(event, Event) else event.get("type")
        if kind == "setpoint":
            t = float(event.t if isinstance(event, Event) else event["t"])
            if self._last_cycle is not None and t > self._last_cycle:
                self._periods[int((t - self._last_cycle) / _BIN_S + 0.5)] += 1
            self._last_cycle = t
            return
        if kind in ("step_started", "move_planned", "controlled_stop"):
            self._last_cycle = None   # a period is between two cycles of one stream
        if kind == "host_stall":   # (the period across it counts: the loop's own)
            fields = event.as_dict() if isinstance(event, Event) else event
            seconds, t = float(fields["seconds"]), float(fields["t"])
            self.count += 1
            self.stalled_s += seconds
            self.longest_s = max(self.longest_s, seconds)
            self._recent.append((t, seconds, float(fields.get("plan_t") or 0.0),
                                 fields.get("step")))
            while self._recent and t - self._recent[0][0] > STALL_WINDOW_S:
                self._recent.pop(0)
            if len(self.stalls) < MAX_LISTED:
                self.stalls.append({"t": round(t, 4), "seconds": round(seconds, 4),
                                    "held_s": fields.get("held_s"), "step": fields.get("step")})
        elif kind == "fault" and self.fault_t is None:
            self.fault_t = float(event.t if isinstance(event, Event) else event["t"])

    # -- what it says --------------------------------------------------------------------
    def stalls_before_fault(self) -> list[tuple[float, float, float, int | None]]:
        if self.fault_t is None:
            return []
        fault_t = self.fault_t
        return [s for s in self._recent if 0 <= fault_t - s[0] <= STALL_WINDOW_S]

    def explain(self, result: RunResult) -> RunResult:
        """``result`` with its fault's ``host``: the stalls of the last
        :data:`STALL_WINDOW_S` before it (and a busy host for a silent bus), said in one
        line; ``result`` itself when there is nothing to say."""
        if result.fault is None:
            return result
        before = self.stalls_before_fault()
        load, cores = load_average(), os.cpu_count() or 1
        # the busier of the start and now (a minute's average lags a burst)
        peak = max((load or [0.0])[0], (self.load_start or [0.0])[0])
        busy = self.wall_clock and peak > cores
        silent = str(result.fault.get("cause")) in _SILENCE
        if not before and not (busy and silent):
            return result
        parts = []
        if before:
            total = sum(s[1] for s in before)
            t, longest, _, step = max(before, key=lambda s: s[1])
            where = f" in step {step}" if step is not None else ""
            parts.append(
                f"{len(before)} host stall{'s' if len(before) != 1 else ''} in the "
                f"{STALL_WINDOW_S:g} s before the fault: this computer did not run seqrun for "
                f"{total:.2f} s in all, the longest {longest:.2f} s at t = {t:.2f} s{where}; "
                "the modules kept their last command meanwhile")
        if busy and silent:
            parts.append(f"the computer was busy (load {peak:.1f} on {cores} cores): a "
                         "simulator or interface driver on it may not have been scheduled "
                         "to answer")
        if not real_time(self.scheduling):
            parts.append("the loop ran at normal priority (--rt-priority keeps it scheduled)")
        host = {"text": "; ".join(parts),
                "stalls": [{"t": round(t, 4), "seconds": round(s, 4), "plan_t": round(p, 4),
                            "step": step} for t, s, p, step in before],
                "stalled_s": round(sum(s[1] for s in before), 4),
                "load_avg": load, "cpus": cores, "scheduling": self.scheduling}
        return dataclasses.replace(result, fault={**result.fault, "host": host})

    def summary(self) -> dict[str, Any]:
        """report.json's ``host``: stalls, the loop's period, scheduling and load."""
        return {"clock": "wall" if self.wall_clock else "virtual",
                "cpus": os.cpu_count(), "scheduling": self.scheduling,
                "load_avg_start": self.load_start, "load_avg_end": load_average(),
                "stalls": self.count, "stalled_s": round(self.stalled_s, 4),
                "longest_stall_s": round(self.longest_s, 4),
                "stall_list": list(self.stalls), "loop_period_ms": self._period_figures()}

    def _period_figures(self) -> dict[str, Any]:
        n = sum(self._periods.values())
        if n == 0:
            return {"cycles": 0}
        ordered = sorted(self._periods.items())

        def percentile(q: float) -> float:
            rank, seen = q * (n - 1), 0
            for bin_, count in ordered:
                seen += count
                if seen > rank:
                    return round(bin_ * _BIN_S * 1000, 1)
            return round(ordered[-1][0] * _BIN_S * 1000, 1)

        return {"cycles": n, "p50": percentile(0.5), "p90": percentile(0.9),
                "p99": percentile(0.99), "max": round(ordered[-1][0] * _BIN_S * 1000, 1)}
