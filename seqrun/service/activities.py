"""One activity at a time: what holds the arm's bus, the executor it runs, how it ends.

An activity is a move, a jog, a sequence run or a reset/home/arm-up. :class:`Activities`
refuses a second one (:class:`~seqrun.errors.Refused`), runs the work holding the bus (in
a worker thread for the non-blocking calls), makes the activity's executor (publishing to
the session's hub, idling through the session's idle hooks) and publishes its start and
end. Part of the arm session (:mod:`seqrun.service.session`).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from seqrun.errors import Refused

#: The exit code of an activity that ended in a fault (as ``seqrun run``).
EXIT_FAULT_CODE = 3


@dataclass(frozen=True)
class ActivityResult:
    """How an activity ended. ``status``: passed | failed | aborted | invalid | halted;
    ``exit_code`` as ``seqrun run`` (0, 1, 3, 130)."""

    kind: str
    status: str
    exit_code: int
    message: str
    #: The run folder (sequence runs, when one was written).
    run_dir: Path | None = None
    #: The executor's full result (runs and moves), for report writers.
    run_result: Any = None
    #: Reset/home/arm-up: every module confirmed by reading its state back.
    confirmed: bool | None = None

    @property
    def ok(self) -> bool:
        return self.exit_code == 0

    def as_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "status": self.status, "exit_code": self.exit_code,
                "message": self.message,
                "run_dir": str(self.run_dir) if self.run_dir else None,
                "confirmed": self.confirmed}


def activity_result(kind: str, run, run_dir: Path | None = None) -> ActivityResult:
    """An executor's :class:`~seqrun.results.RunResult` as the activity's result."""
    confirmed = None
    if kind in ("reset", "home", "arm_up"):
        confirmed = run.exit_code == 0
    return ActivityResult(kind, run.status, run.exit_code,
                          run.extra.get("summary") or run.message, run_dir, run, confirmed)


class Activity:
    """A handle on something the session does in the background (a move, a jog, a run)."""

    def __init__(self, kind: str, activity_id: int, started_by: str | None = None) -> None:
        self.kind = kind
        self.id = activity_id
        #: Who started it (a face's client name), when the face said.
        self.started_by = started_by
        self._done = threading.Event()
        self._result: ActivityResult | None = None

    def finish(self, result: ActivityResult) -> None:
        """Called once by :class:`Activities` when the activity has ended."""
        self._result = result
        self._done.set()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    @property
    def result(self) -> ActivityResult | None:
        """The result once done, else None."""
        return self._result

    def wait(self, timeout: float | None = None) -> ActivityResult:
        """Block until done (up to ``timeout`` s); raises TimeoutError if not done by then."""
        if not self._done.wait(timeout):
            raise TimeoutError(f"{self.kind} still under way after {timeout} s")
        assert self._result is not None
        return self._result

    def __repr__(self) -> str:
        return f"<Activity {self.kind} #{self.id} {'done' if self.done else 'running'}>"


class Activities:
    """The session's one activity at a time.

    :param session: what an activity's executor needs of the session: ``driver``, ``arm``,
        ``clock``, ``events`` (the hub), ``poses_dir``; ``closed``.
    :param publish: the session's ``publish(type, **fields)``.
    :param on_end: called with each activity's result after it has ended and before it is
        announced (the session's status and questions).
    :param loop_priority: SCHED_FIFO priority of each background activity's thread.
    """

    def __init__(self, session: Any, publish: Callable[..., None],
                 on_end: Callable[[ActivityResult], None], *,
                 loop_priority: int | None = None) -> None:
        self._session = session
        self._publish = publish
        self._on_end = on_end
        self.loop_priority = loop_priority
        # _state guards these fields only (microseconds, never across bus I/O or a wait);
        # bus is held by whoever talks to the modules through the driver (a poll, an
        # activity). A STOP takes neither before its broadcast.
        self._state = threading.RLock()
        self.bus = threading.Lock()
        self._current: Activity | None = None
        self._ids = 0
        #: The current activity's Executor (it publishes to the session's hub).
        self.executor: Any = None
        self._idle_hooks: list[Callable[[float], None]] = []
        #: What a jog keeps while it runs: its Deadman and JogPlan.
        self.deadman: Any = None
        self.jog_plan: Any = None
        #: The sequence run under way (a RunInfo) and whether it is paused.
        self.run_info: Any = None
        self.paused = False
        #: The current activity's Halt was sent and the modules read back.
        self.halt_read_back = False

    @property
    def current(self) -> Activity | None:
        """The activity under way, or None."""
        return self._current

    def state(self) -> str | None:
        """What the activity under way does (ArmStatus.activity), None when idle."""
        activity = self._current
        if activity is None:
            return None
        if self.halt_read_back:
            return "halted"  # (the activity may still be ending: its report, its log)
        if activity.kind == "run":
            return "paused" if self.paused else "running"
        return "jogging" if activity.kind == "jog" else "moving"

    def on_event(self, event) -> None:
        """The run's progress from its events (the session's status listener)."""
        from dataclasses import replace

        from seqrun.events import RunPaused, StepStarted

        with self._state:
            info = self.run_info
            if isinstance(event, StepStarted) and info is not None:
                self.run_info = replace(info, step=event.step, label=event.label,
                                        paused_before=None)
            elif event.type == "pause_requested" and info is not None and not self.paused:
                self.run_info = replace(info, pause="requested")
            elif isinstance(event, RunPaused):
                self.paused = True
                if info is not None:
                    self.run_info = replace(info, pause="paused", paused_before=(
                        f"Paused before step {event.step} ({event.location})"))
            elif event.type in ("run_resumed", "run_finished"):
                self.paused = False
                if info is not None:
                    self.run_info = replace(info, pause=None, paused_before=None)

    def pause_withdrawn(self) -> None:
        """A Resume came before the run took its pause: the run never held."""
        from dataclasses import replace

        with self._state:
            if self.run_info is not None and not self.paused:
                self.run_info = replace(self.run_info, pause=None, paused_before=None)

    # ------------------------------------------------------------------ start and end
    def begin(self, kind: str, detail: Mapping[str, Any] | None = None,
              by: str | None = None) -> Activity:
        """Register ``kind`` as the activity under way; Refused if one is, and for every
        kind but a Reset (which moves nothing) unless the modules are still the arm whose
        zero the session uses, powered since it was confirmed (service/arm_identity.py)."""
        with self._state:
            if self._session.closed:
                raise Refused("the session is closed")
            if self._current is not None and self.paused:
                # (a jog while paused would move the arm the Resume then checks again; it
                # is refused instead, like every other motion while a run is under way)
                raise Refused(f"{self.run_info.paused_before if self.run_info else 'paused'}:"
                              f" no {kind} while a run is paused (Abort the run first)")
            if self._current is not None:
                raise Refused(f"a {self._current.kind} is under way: wait for it to end, "
                              "or stop it first")
            self._ids += 1
            activity = Activity(kind, self._ids, by)
            self._current = activity
            self.halt_read_back = False
        if kind != "reset":  # (registered first: no second activity waits for the bus)
            try:
                self.check_identity()
            except BaseException:
                with self._state:
                    self._current = None
                raise
        detail = dict(detail or {})
        if by is not None:
            detail["by"] = by
        self._publish("activity_started", kind=kind, detail=detail)
        return activity

    def check_identity(self) -> None:
        """:func:`~seqrun.service.arm_identity.check_identity` on the session's arm, holding
        the bus (an idle poll may be reading)."""
        from seqrun.service.arm_identity import check_identity

        session = self._session
        with self.bus:
            check_identity(session.driver, session.zero)

    def end(self, activity: Activity, result: ActivityResult) -> None:
        with self._state:
            self._current = None
            self.executor = None
            self.deadman = self.jog_plan = None
            self.run_info, self.paused = None, False
        self._on_end(result)
        self._publish("activity_finished", kind=result.kind, status=result.status,
                      exit_code=result.exit_code, message=result.message)
        activity.finish(result)

    def launch(self, activity: Activity, work: Callable[[], ActivityResult], *,
               background: bool) -> Activity:
        """Run ``work`` holding the bus; in a worker thread when ``background``."""
        def target() -> None:
            result = None
            if background and self.loop_priority is not None:
                self._use_realtime()
            try:
                with self.bus:
                    result = work()
            except BaseException as exc:  # noqa: BLE001 - reported, never lost
                result = ActivityResult(activity.kind, "failed", EXIT_FAULT_CODE,
                                        f"internal error ({type(exc).__name__}: {exc})")
                if not isinstance(exc, Exception):
                    raise
            finally:
                self.end(activity, result or ActivityResult(
                    activity.kind, "failed", EXIT_FAULT_CODE, "ended without a result"))

        if background:
            threading.Thread(target=target, daemon=True,
                             name=f"seqrun-{activity.kind}-{activity.id}").start()
        else:
            target()
        return activity

    def _use_realtime(self) -> None:
        from seqrun.service.realtime import use_fifo

        assert self.loop_priority is not None  # called only when one is set
        why = use_fifo(self.loop_priority)
        if why is not None:
            logging.getLogger(__name__).warning(
                "real-time scheduling of the control loop not available (%s)", why)

    # ------------------------------------------------------------------ the executor
    def new_executor(self, loaded=None, **kw: Any):
        """An executor on the session's driver, publishing to its hub; it is the current
        activity's from now on."""
        from seqrun.executor import Executor
        from seqrun.sequence.checks import check_from_arm
        from seqrun.stop_requests import StopRequests

        s = self._session
        executor = Executor(s.driver, s.arm, s.clock, sequence_check=check_from_arm,
                            poses_dir=(loaded.pose_path or loaded.poses_dir) if loaded
                            else s.poses_dir, requests=StopRequests(), events=s.events,
                            **kw)
        self.adopt(executor)
        if getattr(s, "separation", None) is not None:
            s.separation.watch(executor)  # against the other arms, every cycle
        return executor

    def adopt(self, executor) -> None:
        """The current activity's executor: it publishes to the session's hub (given at
        its construction) and idles through the session's idle hooks."""
        with self._state:
            self.executor = executor
            self.halt_read_back = False
            executor.idle_hooks.extend(self._idle_hooks)
        # A recorder (called on the loop's thread before any subscriber gets the event):
        # the status says "halted" the moment the Halt was read back, while the run still
        # writes its report, and before any face hears of it.
        executor.listeners.append(self._note_halt_read_back)

    #: The executor's events that say a Halt was sent and the modules read back.
    HALT_READ_BACK = frozenset({"halt_confirmed", "halt_unconfirmed", "halt_failed"})

    def _note_halt_read_back(self, event: Any) -> None:
        if event.type in self.HALT_READ_BACK:
            self._session.telemetry.mark_halted("fault", unless_already=True)
            with self._state:
                self.halt_read_back = True

    def stop_pending(self) -> bool:
        """A stop request is posted for the current activity's executor."""
        executor = self.executor
        return executor is not None and bool(executor.requests)

    # ------------------------------------------------------------------ idle hooks
    def add_idle_hook(self, hook: Callable[[float], None]) -> None:
        with self._state:
            self._idle_hooks.append(hook)
            executor = self.executor
        if executor is not None:
            executor.idle_hooks.append(hook)

    def remove_idle_hook(self, hook: Callable[[float], None]) -> None:
        with self._state:
            if hook in self._idle_hooks:
                self._idle_hooks.remove(hook)
            executor = self.executor
        if executor is not None and hook in executor.idle_hooks:
            executor.idle_hooks.remove(hook)
