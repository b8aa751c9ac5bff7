"""The arm session: the one object that owns one arm's bus (the service layer).

Every face (``seqrun run`` and the arm commands, the web console, a future ROS 2 bridge) goes
through an :class:`ArmSession` and its typed results and events (:mod:`seqrun.events`), never
through the executor or the PowerCube client.

What it guarantees:

- **One activity at a time** (a move, a jog, a sequence run, reset/home/arm-up). A second one
  is refused (:class:`~seqrun.errors.Refused`, one line); so are bad inputs (unknown joint or
  pose, a target outside the limits, NaN) and a motion while the arm is halted or faulted.
  A refused command sends nothing.
- **Every motion goes through the sequence machinery**: a console move is a one-step sequence
  built in memory, validated by the same validator and run by the same executor (the same
  per-cycle checks, the same Halt on any fault).
- :meth:`ArmSession.halt` **never waits behind anything**: it sends the Halt broadcast from
  the caller's thread (the client's ``halt_now`` path takes no lock a run holds), posts a Halt
  request to a running activity's stop-request inbox, and then confirms by reading every
  module back.
- **Status without touching the bus**: :meth:`ArmSession.status` returns the latest
  measurement. While idle a background thread polls the arm at a modest rate (paused while an
  activity owns the bus); during an activity the executor's measurements feed it.
- Nothing restarts motion by itself: after a halt or a fault only an explicit reset (or
  arm-up) makes the arm movable again.
"""

from __future__ import annotations

import logging
import math
import re
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

from seqrun.errors import Refused
from seqrun.events import Event, EventHub, Subscription, make_event
from seqrun.service.control import ControlDesk
from seqrun.halt import HaltConfirmation

#: Version of this API (and of the console's /api/v<N>).
API_VERSION = 1

#: What the session is doing (ArmStatus.activity).
ACTIVITY_STATES = ("idle", "moving", "jogging", "running", "paused", "halted", "faulted")

#: A jog that is not renewed within this time ends with a controlled stop (deadman).
JOG_DEADMAN_S = 0.2

#: Idle status poll rate (Hz): modest, the bus is shared with nothing else while idle.
STATUS_POLL_HZ = 5.0

#: Share of each joint's maximum velocity the session's moves use until told otherwise.
DEFAULT_MOVE_SHARE = 0.25

#: halt() waits at most this long (s) for an activity to confirm its Halt.
HALT_CONFIRM_WAIT_S = 5.0

EXIT_FAULT_CODE = 3


@dataclass(frozen=True)
class JointStatus:
    """One joint as last measured."""

    name: str
    module: int
    position_deg: float | None
    velocity_deg_s: float | None
    target_deg: float | None
    #: State flag names of its module (state word where read, else the short state).
    flags: tuple[str, ...]
    fault: bool
    locked: bool = False

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "module": self.module, "position_deg": self.position_deg,
                "velocity_deg_s": self.velocity_deg_s, "target_deg": self.target_deg,
                "flags": list(self.flags), "fault": self.fault, "locked": self.locked}


@dataclass(frozen=True)
class RunInfo:
    """The sequence run under way."""

    file: str
    step: int | None
    label: str | None
    steps: int
    run_dir: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"file": self.file, "step": self.step, "label": self.label,
                "steps": self.steps, "run_dir": self.run_dir}


@dataclass(frozen=True)
class ArmStatus:
    """The arm as last measured, and what the session is doing. Never read from the bus by
    :meth:`ArmSession.status` itself."""

    joints: tuple[JointStatus, ...]
    #: Any module reports a fault.
    fault: bool
    end_effector_mm: tuple[float, float, float] | None
    end_effector_rpy_deg: tuple[float, float, float] | None
    zero_reference: str | None
    bus: str
    simulator: bool
    activity: str
    run: RunInfo | None
    #: Clock reading of the measurement (None: nothing measured yet).
    updated_at: float | None
    #: The last poll got no answer: the values are the previous ones.
    stale: bool = False
    message: str = ""

    @property
    def joints_deg(self) -> dict[str, float | None]:
        return {j.name: j.position_deg for j in self.joints}

    @property
    def velocities_deg_s(self) -> dict[str, float | None]:
        return {j.name: j.velocity_deg_s for j in self.joints}

    @property
    def targets_deg(self) -> dict[str, float | None]:
        return {j.name: j.target_deg for j in self.joints}

    @property
    def flags(self) -> dict[str, tuple[str, ...]]:
        return {j.name: j.flags for j in self.joints}

    def as_dict(self) -> dict[str, Any]:
        return {"v": API_VERSION, "joints": [j.as_dict() for j in self.joints],
                "fault": self.fault,
                "end_effector": (None if self.end_effector_mm is None else
                                 {"position_mm": list(self.end_effector_mm),
                                  "rpy_deg": list(self.end_effector_rpy_deg or ())}),
                "zero_reference": self.zero_reference, "bus": self.bus,
                "simulator": self.simulator, "activity": self.activity,
                "run": self.run.as_dict() if self.run else None,
                "updated_at": self.updated_at, "stale": self.stale, "message": self.message}


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


class Activity:
    """A handle on something the session does in the background (a move, a jog, a run)."""

    def __init__(self, kind: str, activity_id: int, started_by: str | None = None) -> None:
        self.kind = kind
        self.id = activity_id
        #: Who started it (a face's client name), when the face said.
        self.started_by = started_by
        self._done = threading.Event()
        self._result: ActivityResult | None = None

    def _finish(self, result: ActivityResult) -> None:
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


class ArmSession:
    """The one owner of one arm's bus. Thread-safe; see the module docstring.

    :param arm: the arm description, with the zero reference in force applied
        (:meth:`~seqrun.arm.ArmDescription.with_zero_reference`).
    :param connection: an open :class:`~seqrun.connection.Connection` (the session closes it
        in :meth:`close` when ``own_connection``).
    :param project: the campaign (:class:`~seqrun.project.Project`): poses, run folders.
    :param log_root: where run folders go (default: the project's runs dir, else ``runs/``).
    :param poses_dir: pose search path for named poses (default: the project's, then the
        shipped poses).
    :param zero: the zero reference in force (:class:`~seqrun.zero.ZeroInForce`), for status
        and the run records.
    :param status_hz: idle status poll rate; 0 disables polling (tests poll by hand with
        :meth:`poll_status`).
    :param loop_priority: run each activity's thread (the 100 Hz loop) at ``SCHED_FIFO``
        with this priority (1-99; that thread and the threads it starts:
        :mod:`seqrun.service.realtime`).
    """

    def __init__(self, arm, connection, *, project=None, log_root: Path | None = None,
                 poses_dir=None, zero=None, status_hz: float = STATUS_POLL_HZ,
                 response_timeout_s: float | None = None, own_connection: bool = True,
                 jog_deadman_s: float = JOG_DEADMAN_S,
                 loop_priority: int | None = None) -> None:
        from seqrun.connection import response_timeout_s as default_timeout
        from seqrun.powercube.client import PowerCubeClient
        from seqrun.shipped import shipped_dir

        self.arm = arm
        self.connection = connection
        self.clock = connection.clock
        self.project = project
        self.zero = zero
        self.own_connection = own_connection
        self.jog_deadman_s = jog_deadman_s
        self.loop_priority = loop_priority
        if poses_dir is None:
            poses_dir = (tuple(project.pose_path) if project is not None
                         else (Path("poses"), shipped_dir("poses")))
        self.poses_dir = poses_dir
        self.log_root = Path(log_root) if log_root is not None else (
            project.runs_dir if project is not None else Path("runs"))
        self.client = PowerCubeClient(
            connection.bus, self.clock,
            response_timeout=(response_timeout_s if response_timeout_s is not None
                              else default_timeout(arm)))
        self._hub = EventHub()
        # _state guards the session's fields only (microseconds, never across bus I/O or a
        # wait); _bus is held by whoever talks to the modules through the client (a poll,
        # an activity). halt() takes neither before its broadcast.
        self._state = threading.RLock()
        self._bus = threading.Lock()
        self._closed = False
        self._activity: Activity | None = None
        self._activity_ids = 0
        self._executor: Any = None  # the activity's Executor (it publishes to _hub)
        self._idle_hooks: list[Callable[[float], None]] = []
        self._run_info: RunInfo | None = None
        self._paused = False
        self._halted: str | None = None
        #: The running activity's Halt was sent and the modules read back.
        self._halt_read_back = False
        self._deadman: Any = None  # the jog's Deadman
        self._jog_plan: Any = None  # the jog's JogPlan
        self._questions: dict[str, _Question] = {}
        self._question_ids = 0
        self._move_velocities = {j.name: round(j.max_velocity_deg_s * DEFAULT_MOVE_SHARE, 3)
                                 for j in arm.joints if j.locked is None}
        self._t0 = self.clock.now()
        self._velocity = None
        # The latest measurement.
        n = len(arm.joints)
        self._joints: list[float | None] = [None] * n
        self._velocities: list[float | None] = [None] * n
        self._targets: list[float | None] = [None] * n
        self._flags: dict[str, tuple[str, ...]] = {j.name: () for j in arm.joints}
        self._fault = False
        self._homed: bool | None = None
        #: Clock time of the last successful reset: older fault events no longer count.
        self._cleared_at = -math.inf
        self._updated_at: float | None = None
        self._stale = False
        self._message = ""
        self._status_listener = self._hub.add_listener(self._on_event, "session status",
                                                       maxsize=10_000)
        #: Who holds control and who watches (every face of this session shares it).
        self.control = ControlDesk(publish=self._publish, clock=self.clock.now)
        self._poll_stop = threading.Event()
        self._poller: threading.Thread | None = None
        if status_hz > 0:
            self._poller = threading.Thread(target=self._poll_loop, args=(1.0 / status_hz,),
                                            daemon=True, name="seqrun-status-poll")
            self._poller.start()

    # ------------------------------------------------------------------ lifetime
    def __enter__(self) -> "ArmSession":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Stop any motion (controlled stop; a Halt if that does not end it), stop the
        status poll, close the client and (``own_connection``) the bus."""
        with self._state:
            if self._closed:
                return
            self._closed = True
            activity = self._activity
        if activity is not None and not activity.done:
            self.abort("session closed")
            try:
                activity.wait(timeout=10.0)
            except TimeoutError:
                self.halt("session closed: the activity did not stop")
        self._poll_stop.set()
        if self._poller is not None:
            self._poller.join(timeout=5.0)
        self._status_listener.close(timeout=1.0)
        self.client.close()
        if self.own_connection:
            self.connection.close()

    @property
    def closed(self) -> bool:
        return self._closed

    # ------------------------------------------------------------------ events and status
    @property
    def events(self) -> EventHub:
        """The session's event hub (every run's, move's and poll's typed events)."""
        return self._hub

    def subscribe(self, *, maxsize: int = 1000, name: str = "") -> Subscription:
        """Typed events on a queue of their own (see :class:`seqrun.events.EventHub`)."""
        return self._hub.subscribe(maxsize=maxsize, name=name)

    def add_idle_hook(self, hook: Callable[[float], None]) -> None:
        """Call ``hook(slack_s)`` on the control loop's own thread before it sleeps until
        its next cycle, in every run, move and jog of this session; ``slack_s`` is the time
        left and the hook must return well within it. A terminal view renders there: it
        can neither delay a cycle nor compete with the loop from a thread of its own. A
        hook that raises is dropped (``listener_failed`` event)."""
        with self._state:
            self._idle_hooks.append(hook)
            executor = self._executor
        if executor is not None:
            executor.idle_hooks.append(hook)

    def remove_idle_hook(self, hook: Callable[[float], None]) -> None:
        with self._state:
            if hook in self._idle_hooks:
                self._idle_hooks.remove(hook)
            executor = self._executor
        if executor is not None and hook in executor.idle_hooks:
            executor.idle_hooks.remove(hook)

    def _adopt(self, executor) -> None:
        """The current activity's executor: it publishes to this session's hub (given at
        its construction) and idles through the session's idle hooks."""
        with self._state:
            self._executor = executor
            self._halt_read_back = False
            executor.idle_hooks.extend(self._idle_hooks)
        # A recorder (called on the loop's thread before any subscriber gets the event):
        # the status says "halted" the moment the Halt was read back, while the run still
        # writes its report, and before any face hears of it.
        executor.listeners.append(self._note_halt_read_back)

    #: The executor's events that say a Halt was sent and the modules read back.
    HALT_READ_BACK = frozenset({"halt_confirmed", "halt_unconfirmed", "halt_failed"})

    def _note_halt_read_back(self, event: Event) -> None:
        if event.type in self.HALT_READ_BACK:
            with self._state:
                self._halt_read_back = True
                if self._halted is None:
                    self._halted = "fault"

    def _publish(self, type_: str, **data: Any) -> None:
        now = self.clock.now()
        self._hub.publish(make_event(type_, round(now - self._t0, 6), data, clock_s=now))

    def _on_event(self, event: Event) -> None:
        """Status from the events (its own listener thread)."""
        from seqrun.events import Fault, Measurement, MovePlanned, StepStarted

        kind = event.type
        with self._state:
            if isinstance(event, Measurement):
                self._take_measurement(event)
            elif isinstance(event, MovePlanned):
                for i, value in enumerate(event.target_deg):
                    self._targets[i] = float(value)
            elif isinstance(event, StepStarted) and self._run_info is not None:
                self._run_info = RunInfo(self._run_info.file, event.step, event.label,
                                         self._run_info.steps, self._run_info.run_dir)
            elif kind == "paused":
                self._paused = True
            elif kind in ("resumed", "run_finished"):
                self._paused = False
            elif isinstance(event, Fault) and (event.clock_s or 0) >= self._cleared_at:
                self._message = event.message
                if event.halt_sent:
                    self._halted = event.cause

    def _take_measurement(self, m) -> None:
        if (m.clock_s is not None and self._updated_at is not None
                and m.clock_s < self._updated_at):
            return  # older than a reading the session took itself meanwhile
        if m.states:
            self._homed = all("HOME_OK" in str(w).split("|") for w in m.states.values())
        self._joints = [float(x) for x in m.joints_deg]
        if m.velocities_deg_s is not None:
            self._velocities = [float(v) for v in m.velocities_deg_s]
        if m.flags is not None:
            self._flags = {k: tuple(v) for k, v in m.flags.items()}
            at_rest = not any("MOTION" in f for f in self._flags.values())
            if m.source != "poll" and m.source != "cycle" and at_rest:
                # A reading after a stop: the last windowed estimate must not show motion.
                self._velocities = [0.0] * len(self._joints)
        self._fault = bool(m.fault)
        self._updated_at = m.clock_s
        self._stale = False

    def status(self) -> ArmStatus:
        """The latest measurement and what the session does; never touches the bus."""
        from seqrun import kinematics

        with self._state:
            joints = list(self._joints)
            velocities = list(self._velocities)
            targets = list(self._targets)
            flags = dict(self._flags)
            fault, updated, stale = self._fault, self._updated_at, self._stale
            activity, run, message = self._activity_state(), self._run_info, self._message
        rows = tuple(JointStatus(j.name, j.module, joints[i], velocities[i], targets[i],
                                 flags.get(j.name, ()), _flags_fault(flags.get(j.name, ())),
                                 j.locked is not None)
                     for i, j in enumerate(self.arm.joints))
        xyz = rpy = None
        if all(x is not None for x in joints):
            import numpy as np

            T = kinematics.fk(self._chain, np.radians(np.array(joints, dtype=float)))
            x, y, z = (round(float(v), 3) for v in T[:3, 3])
            roll, pitch, yaw = (round(float(v), 3)
                                for v in np.degrees(kinematics.rpy_from_matrix(T[:3, :3])))
            xyz, rpy = (x, y, z), (roll, pitch, yaw)
        return ArmStatus(rows, fault, xyz, rpy,
                         getattr(self.zero, "pose", None) if self.zero is not None
                         else getattr(self.arm, "zero_reference", None),
                         self.connection.description, bool(self.connection.is_simulator),
                         activity, run, updated, stale, message)

    def status_dict(self) -> dict[str, Any]:
        """:meth:`status` as a JSON-ready dict (the control socket's ``status`` op)."""
        return self.status().as_dict()

    @property
    def _chain(self):
        chain = self.__dict__.get("_chain_cache")
        if chain is None:
            from seqrun import kinematics

            chain = self.__dict__["_chain_cache"] = kinematics.Chain.from_arm(self.arm)
        return chain

    def _activity_state(self) -> str:
        if self._halted is not None and self._halt_read_back:
            return "halted"  # (the activity may still be ending: its report, its log)
        if self._activity is not None:
            kind = self._activity.kind
            if kind == "run":
                return "paused" if self._paused else "running"
            if kind == "jog":
                return "jogging"
            return "moving"
        if self._halted is not None or any("HALTED" in f for f in self._flags.values()):
            return "halted"
        if self._fault:
            return "faulted"
        return "idle"

    def poll_status(self) -> ArmStatus:
        """Read the arm once now (idle only; during an activity the executor feeds status)
        and return the new status. The background poll calls this."""
        if self._bus.acquire(blocking=False):
            try:
                if self._activity is None and not self.client.closed:
                    self._poll_once()
            finally:
                self._bus.release()
        return self.status()

    def _poll_once(self) -> None:
        """One pipelined read of ActPos, ActVel and CubeState of every module (bus held)."""
        from seqrun.service.arm_access import poll_joints
        from seqrun.telemetry import joint_flags

        arm = self.arm
        try:
            joints, velocities, states = poll_joints(self.client, arm)
        except Exception as exc:  # noqa: BLE001 - a poll never raises: status goes stale
            self._poll_failed(str(exc))
            return
        flags, fault = joint_flags(arm.joint_names, arm.module_ids, {}, states)
        now = self.clock.now()
        self._hub.publish(make_event(
            "measurement", round(now - self._t0, 6),
            {"joints_deg": joints, "state": [s.cycle_code for s in states.values()],
             "states": {str(m): s.describe() for m, s in states.items()}},
            clock_s=now, velocities_deg_s=velocities, flags=flags, fault=fault,
            source="poll"))
        with self._state:  # at once, not only when the listener gets to it
            self._joints = list[float | None](joints)
            self._velocities = list[float | None](velocities)
            self._flags, self._fault = flags, fault
            self._homed = all(s.homed for s in states.values())
            self._updated_at, self._stale = now, False

    def _poll_failed(self, error: str) -> None:
        with self._state:
            first = not self._stale
            self._stale = True
        if first:
            self._publish("status_poll_failed", error=error)

    def _poll_loop(self, period: float) -> None:
        while not self._poll_stop.wait(period):
            if self._activity is None:
                try:
                    self.poll_status()
                except Exception:  # noqa: BLE001 - the poll must never die
                    pass

    @property
    def activity(self) -> Activity | None:
        """The activity under way, or None."""
        return self._activity

    # ------------------------------------------------------------------ stopping
    def halt(self, reason: str = "STOP") -> HaltConfirmation:
        """Halt broadcast now from this thread, stop any activity, confirm by reading every
        module back. Never waits behind a lock, a run or a queue before the broadcast."""
        from seqrun.errors import BusError
        from seqrun.halt import halt_and_confirm

        # The running activity's inbox first (a deque append: no lock, no wait), so that
        # the loop takes the modules' HALTED state for the operator's Halt (exit 130),
        # then the broadcast from this thread, whatever holds the client.
        executor, activity = self._executor, self._activity
        if executor is not None:
            executor.halt(reason)
        sent_error = None
        try:
            self.client.halt_now(wait=False)
        except BusError as exc:
            sent_error = str(exc)
        with self._state:
            self._halted = reason
        self._withdraw_questions()
        result: HaltConfirmation | None = None
        if activity is not None:
            try:
                activity.wait(timeout=HALT_CONFIRM_WAIT_S)
            except TimeoutError:
                pass
            if executor is not None and executor.halt_result is not None:
                result = executor.halt_result
        if result is None:
            if self._bus.acquire(timeout=HALT_CONFIRM_WAIT_S):
                try:
                    result = halt_and_confirm(self.client, self.arm.module_ids)
                    if result.confirmed:
                        self._poll_once()
                finally:
                    self._bus.release()
            else:
                modules = tuple(self.arm.module_ids)
                result = HaltConfirmation("halt", modules, sent=sent_error is None,
                                          unconfirmed={m: "not read back" for m in modules},
                                          error="the activity did not hand the bus back "
                                                "in time to read the modules")
        if sent_error is not None and not result.sent:
            modules = tuple(self.arm.module_ids)
            result = HaltConfirmation("halt", modules, sent=False,
                                      unconfirmed={m: "no Halt sent" for m in modules},
                                      attempts=result.attempts, error=sent_error)
        names = dict(zip(self.arm.module_ids, self.arm.joint_names))
        self._publish("session_halt", reason=reason, halt_sent=result.sent,
                      halt_confirmed=result.confirmed,
                      modules_not_halted=list(result.modules_unconfirmed),
                      message=result.describe(names))
        return result

    def halt_dict(self, reason: str = "STOP") -> dict[str, Any]:
        """:meth:`halt` as a JSON-ready dict (the control socket's ``halt`` op)."""
        result = self.halt(reason)
        names = dict(zip(self.arm.module_ids, self.arm.joint_names))
        return {"v": API_VERSION, **result.as_dict(), "message": result.describe(names)}

    def control_handler(self) -> Any:
        """The object a control socket serves: ``status_dict()`` and ``halt(reason) -> dict``."""
        return _ControlHandler(self)

    # ------------------------------------------------------------------ activities
    def _begin(self, kind: str, detail: Mapping[str, Any] | None = None,
               by: str | None = None) -> Activity:
        with self._state:
            if self._closed:
                raise Refused("the session is closed")
            if self._activity is not None:
                raise Refused(f"a {self._activity.kind} is under way: wait for it to end, "
                              "or stop it first")
            self._activity_ids += 1
            activity = Activity(kind, self._activity_ids, by)
            self._activity = activity
        detail = dict(detail or {})
        if by is not None:
            detail["by"] = by
        self._publish("activity_started", kind=kind, detail=detail)
        return activity

    def _end(self, activity: Activity, result: ActivityResult) -> None:
        with self._state:
            self._activity = None
            self._executor = None
            self._run_info = None
            self._paused = False
            self._deadman = None
            if result.exit_code == 3:
                self._halted = self._halted or "fault"
        self._withdraw_questions()
        self._publish("activity_finished", kind=result.kind, status=result.status,
                      exit_code=result.exit_code, message=result.message)
        activity._finish(result)

    def _launch(self, activity: Activity, work: Callable[[], ActivityResult], *,
                background: bool) -> Activity:
        """Run ``work`` holding the bus; in a worker thread when ``background``."""
        def target() -> None:
            result = None
            if background and self.loop_priority is not None:
                self._use_realtime()
            try:
                with self._bus:
                    result = work()
            except BaseException as exc:  # noqa: BLE001 - reported, never lost
                result = ActivityResult(activity.kind, "failed", EXIT_FAULT_CODE,
                                        f"internal error ({type(exc).__name__}: {exc})")
                if not isinstance(exc, Exception):
                    raise
            finally:
                self._end(activity, result or ActivityResult(
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

    def _new_executor(self, loaded=None, **kw: Any):
        from seqrun.executor import Executor
        from seqrun.stop_requests import StopRequests

        executor = Executor(self.client, self.arm, self.clock,
                            poses_dir=(loaded.pose_path or loaded.poses_dir) if loaded
                            else self.poses_dir, requests=StopRequests(), events=self._hub,
                            **kw)
        self.client.on_discard = executor.on_discard
        self._adopt(executor)
        return executor

    def _one_off(self, name: str, steps: list[str]):
        """A sequence built in memory (a file in a private folder, loaded by the same
        loader): the console's moves and commands are sequences like any other."""
        from seqrun.errors import SequenceInvalid, UserInputError
        from seqrun.schema import load_sequence

        folder = self.__dict__.get("_tmp")
        if folder is None:
            import tempfile

            folder = self.__dict__["_tmp"] = Path(tempfile.mkdtemp(prefix="seqrun-session-"))
        path = folder / f"{name}.yaml"
        path.write_text(f"name: {name}\ndescription: seqrun session command\nsteps:\n"
                        + "".join(f"  - {s}\n" for s in steps), encoding="utf-8")
        root = self.project.root if self.project is not None else None
        try:
            return load_sequence(path, project_root=root)
        except SequenceInvalid as exc:
            raise Refused(exc.errors[0].message) from None
        except UserInputError as exc:
            raise Refused(str(exc)) from None

    def _blocking_steps(self, kind: str, steps: list[str]) -> ActivityResult:
        loaded = self._one_off(kind, steps)
        activity = self._begin(kind)

        def work() -> ActivityResult:
            executor = self._new_executor(loaded, confirm_clear_latched=lambda q: True)
            result = executor.run(loaded)
            if result.exit_code == 0 and kind != "home":
                with self._state:
                    self._halted = None
                    self._message = ""
                    self._cleared_at = self.clock.now()
            self._poll_once()
            return _result(kind, result)

        self._launch(activity, work, background=False)
        return activity.wait()

    # ------------------------------------------------------------------ blocking commands
    def reset(self) -> ActivityResult:
        """Reset every module (clears faults and Halt), confirmed by reading back."""
        return self._blocking_steps("reset", ["reset: {label: Reset (session)}"])

    def home(self) -> ActivityResult:
        """Home every module (reset of the power-on error state, then Home; no motion on
        the LWA 3), confirmed (HOME_OK read back). Refused while halted: a Reset after a
        STOP is the operator's explicit decision."""
        self._check_movable("home", homed=False)
        return self._blocking_steps("home", ["reset: {label: Reset (home)}",
                                             "home: {label: Home (session)}"])

    def arm_up(self) -> ActivityResult:
        """"ARM" of the thesis console: reset, then write the arm file's limits."""
        return self._blocking_steps("arm_up", ["reset: {label: Reset (arm up)}",
                                               "set_limits: {label: Write the limits (arm up)}"])

    # ------------------------------------------------------------------ moves
    def set_move_velocities(self, velocities_deg_s: Mapping[str, float]) -> dict[str, float]:
        """Per-joint velocity (deg/s) of the session's moves (the thesis ALLVEL); joints not
        named keep theirs. Returns the velocities in force. Refused: unknown joint, NaN, not
        positive, above the joint's limit."""
        if not isinstance(velocities_deg_s, Mapping):
            raise Refused("move velocities: give a mapping joint -> deg/s")
        new = {}
        for name, value in velocities_deg_s.items():
            joint = self._movable_joint(name, "move velocity")
            v = _finite(value, f"move velocity of {name}")
            if v <= 0:
                raise Refused(f"move velocity of {name}: {v:g} deg/s must be positive")
            if v > joint.max_velocity_deg_s:
                raise Refused(f"move velocity of {name}: {v:g} deg/s is above its limit "
                              f"{joint.max_velocity_deg_s:g} deg/s")
            new[name] = v
        with self._state:
            self._move_velocities.update(new)
            return dict(self._move_velocities)

    def move_velocities(self) -> dict[str, float]:
        with self._state:
            return dict(self._move_velocities)

    def _movable_joint(self, name: Any, what: str):
        if not isinstance(name, str) or name not in self.arm.joint_names:
            raise Refused(f"{what}: unknown joint {name!r} (joints: "
                          f"{', '.join(self.arm.joint_names)})")
        joint = self.arm.joints[self.arm.joint_names.index(name)]
        if joint.locked is not None:
            raise Refused(f"{what}: {name} is locked at {joint.locked:g}° in the arm file")
        return joint

    def _check_movable(self, what: str, *, homed: bool = True) -> None:
        """Refused while halted or faulted, not homed (``homed``), or before anything was
        measured."""
        with self._state:
            halted, flags, fault = self._halted, dict(self._flags), self._fault
            measured = all(x is not None for x in self._joints)
            is_homed = self._homed
        if halted is not None or any("HALTED" in f for f in flags.values()):
            raise Refused(f"{what}: the arm is halted ({halted or 'HALTED'}); reset it first")
        if not homed:
            return
        bad = [f"{n}: {'|'.join(f)}" for n, f in flags.items() if _flags_fault(f)]
        if fault or bad:
            raise Refused(f"{what}: module fault ({'; '.join(bad) or 'NOT_OK'}); reset it first")
        if not measured:
            raise Refused(f"{what}: the arm has not been read yet")
        if is_homed is False:
            raise Refused(f"{what}: the modules are not homed; Arm and Home first")

    def _validated_move(self, kind: str, step: str, what: str):
        """Load and validate a one-step move from the measured joints (Refused on errors)."""
        from seqrun.validation import validate_sequence

        self._check_movable(what)
        loaded = self._one_off(kind, [step])
        with self._state:
            start = {j.name: float(x) for j, x in zip(self.arm.joints, self._joints)
                     if x is not None}
        check = validate_sequence(loaded, self.arm, start, started=True)
        if check.errors:
            raise Refused(f"{what}: {self._own_words(check.errors[0])}")
        return loaded

    def _own_words(self, error) -> str:
        """A finding about a session command in the operator's terms: where it is when that
        is a file of theirs (a pose file), never the session's private one-step file."""
        private = str(self.__dict__.get("_tmp", "\0"))
        message = re.sub(r"\s*\(used at [^()]*" + re.escape(private) + r"[^()]*\)", "",
                         error.message)
        if str(error.file).startswith(private):
            return message
        return f"{error.file}:{error.line}:{error.column}: {message}"

    def _start_move(self, kind: str, loaded, detail: dict, by: str | None = None) -> Activity:
        activity = self._begin(kind, detail, by)

        def work() -> ActivityResult:
            executor = self._new_executor(loaded)
            result = executor.run(loaded)
            self._poll_once()
            return _result(kind, result)

        return self._launch(activity, work, background=True)

    def move_to_pose(self, name: str, *, velocity_scale: float | None = None,
                     by: str | None = None) -> Activity:
        """Move to a named pose (a pose file), as a one-step sequence: validated, executed
        by the executor. Non-blocking."""
        import json

        if not isinstance(name, str) or not name:
            raise Refused(f"move to pose: {name!r} is not a pose name")
        params: dict[str, Any] = {"pose": name, "label": f"Move to {name} (session)"}
        if velocity_scale is not None:
            params["velocity_scale"] = self._scale(velocity_scale)
        else:
            params["velocity_deg_s"] = self.move_velocities()
        loaded = self._validated_move("move", f"move: {json.dumps(params)}",
                                      f"move to {name}")
        return self._start_move("move", loaded, {"pose": name}, by)

    def move_to_joints(self, joints_deg: Mapping[str, float], *,
                       velocity_scale: float | None = None, by: str | None = None) -> Activity:
        """Move the named joints to user-degree targets (others stay). Non-blocking."""
        import json

        if not isinstance(joints_deg, Mapping) or not joints_deg:
            raise Refused("move: give at least one joint target (joint -> degrees)")
        targets = {}
        for name, value in joints_deg.items():
            joint = self._movable_joint(name, "move")
            v = _finite(value, f"move: {name}")
            lo, hi = joint.limits_deg
            if not lo <= v <= hi:
                raise Refused(f"move: {name} target {v:g}° is outside its limits "
                              f"[{lo:g}, {hi:g}]°")
            targets[name] = v
        params: dict[str, Any] = {"joints": targets, "label": "Move joints (session)"}
        if velocity_scale is not None:
            params["velocity_scale"] = self._scale(velocity_scale)
        params["velocity_deg_s"] = {n: v for n, v in self.move_velocities().items()
                                    if n in targets}
        loaded = self._validated_move("move", f"move: {json.dumps(params)}", "move")
        return self._start_move("move", loaded, {"joints": targets}, by)

    @staticmethod
    def _scale(value: Any) -> float:
        v = _finite(value, "velocity scale")
        if not 0 < v <= 1:
            raise Refused(f"velocity scale {v:g} must lie in (0, 1]")
        return v

    # ------------------------------------------------------------------ jog
    def jog(self, joint: str, speed_scale: float, *, by: str | None = None) -> Activity:
        """Jog one joint at ``speed_scale`` (-1..1) of its move velocity. Call again at
        least every :data:`JOG_DEADMAN_S` (same joint and direction: renews; the speed
        stays the first call's) or the jog ends with a controlled stop. Refused near a
        limit (moving towards it) or outside the workspace guards, like a move; another
        joint or the other direction while jogging is refused (release first)."""
        import numpy as np

        from seqrun.service.jog import Deadman, plan_jog, run_jog

        with self._state:
            current = self._activity
            if current is not None and current.kind == "jog" and self._deadman is not None:
                plan = self._jog_plan
                if (plan is not None and plan.joint == joint
                        and isinstance(speed_scale, (int, float))
                        and not isinstance(speed_scale, bool)
                        and speed_scale * plan.direction > 0 and not self._deadman.expired):
                    self._deadman.renew()  # the speed stays the jog's first
                    return current
                raise Refused("jog: another jog is under way (release it first)")
        self._check_movable("jog")
        speed_scale = _finite(speed_scale, "jog: speed scale")
        with self._state:
            joints = np.array(self._joints, dtype=float)
            velocity = self._move_velocities.get(joint, 0.0)
        plan = plan_jog(self.arm, joint, float(speed_scale), joints, velocity)
        deadman = Deadman(self.clock, self.jog_deadman_s)
        activity = self._begin("jog", {"joint": joint, "speed_scale": speed_scale}, by)
        with self._state:
            self._deadman, self._jog_plan = deadman, plan

        def work() -> ActivityResult:
            executor = self._new_executor()
            status, code, message = run_jog(executor, plan, deadman)
            self._poll_once()  # at rest: the modules' own velocities, not the estimate
            return ActivityResult("jog", status, code, message)

        return self._launch(activity, work, background=True)

    def jog_stop(self) -> ActivityResult | None:
        """End the jog with a controlled stop (waits for it); None if no jog ran."""
        activity, deadman = self._activity, self._deadman
        if activity is None or activity.kind != "jog":
            return None
        if deadman is not None:
            deadman.release("jog stopped")
        return activity.wait(timeout=30.0)

    # ------------------------------------------------------------------ sequences
    def run_sequence(self, file: str | Path, *, speed: float = 1.0, step_mode: bool = False,
                     first_step: int = 1, command_mode: str | None = None,
                     log_dir: Path | None = None, html_report: bool = True,
                     loaded=None, assume_yes: bool = False, by: str | None = None) -> Activity:
        """Validate ``file`` (refused with its first error line when invalid), then run it in
        a worker thread with a run folder like ``seqrun run``. Questions (confirm steps,
        ``step_mode``'s before-step question, clearing a latched fault) are published as
        ``confirm_requested`` events; answer them with :meth:`answer`."""
        from seqrun.errors import SequenceInvalid, UserInputError
        from seqrun.runlog import prepare_run_folder
        from seqrun.schema import load_sequence
        from seqrun.validation import validate_sequence

        speed = _finite(speed, "speed")
        if not 0 < speed <= 1:
            raise Refused(f"speed {speed:g} must lie in (0, 1]")
        if command_mode not in (None, "ramp", "step"):
            raise Refused(f"command mode must be ramp or step, got {command_mode!r}")
        if loaded is None:
            try:
                loaded = load_sequence(Path(file), project_root=(
                    self.project.root if self.project is not None else None))
            except SequenceInvalid as exc:
                more = len(exc.errors) - 1
                raise Refused(str(exc.errors[0]) + (f" (and {more} more)" if more else "")) \
                    from None
            except UserInputError as exc:
                raise Refused(str(exc)) from None
        if not isinstance(first_step, int) or not 1 <= first_step <= len(loaded.steps):
            raise Refused(f"first step {first_step!r}: the sequence has steps "
                          f"1-{len(loaded.steps)}")
        with self._state:
            measured = all(x is not None for x in self._joints)
            start = ({j.name: float(x) for j, x in zip(self.arm.joints, self._joints)
                      if x is not None} if measured else None)
        if first_step == 1:  # the executor checks again from the arm's measured state
            check = validate_sequence(loaded, self.arm, start, speed=speed,
                                      started=bool(self._homed))
            if check.errors:
                more = len(check.errors) - 1
                raise Refused(str(check.errors[0]) + (f" (and {more} more)" if more else ""))
        try:
            folder = prepare_run_folder(log_dir, loaded.name, self.log_root)
        except OSError as exc:
            raise Refused(f"cannot create the run folder: {exc.strerror or exc}") from None
        activity = self._begin("run", {"file": str(file), "run_dir": str(folder)}, by)
        with self._state:
            self._run_info = RunInfo(str(file), None, None, len(loaded.steps), str(folder))
        total = len(loaded.steps)

        def before_step(step) -> bool:
            if not step_mode:
                return True
            return self._ask(f"Run step {step.number}/{total}: {step.title}?", step=True)

        def confirm(prompt: str) -> bool:
            return True if assume_yes else self._ask(prompt)

        def work() -> ActivityResult:
            outcome = self.run_loaded(loaded, log_dir=folder, speed=speed,
                                      first_step=first_step, command_mode=command_mode,
                                      confirm=confirm, before_step=before_step,
                                      confirm_clear_latched=(
                                          None if self.connection.is_simulator
                                          else lambda q: self._ask(q)),
                                      html_report=html_report, file=str(file),
                                      bus_held=True)
            result = _result("run", outcome.result, run_dir=folder)
            try:
                self._poll_once()
            except Exception:  # noqa: BLE001
                pass
            return result

        return self._launch(activity, work, background=True)

    def run_loaded(self, loaded, *, log_dir: Path | None, speed: float = 1.0,
                   first_step: int = 1, command_mode: str | None = None,
                   confirm: Callable[[str], bool] | None = None,
                   before_step: Callable | None = None,
                   confirm_clear_latched: Callable[[str], bool] | None = None,
                   on_executor: Callable | None = None, run_control=None, requests=None,
                   warn: Callable[[str], None] | None = None, meta: dict | None = None,
                   html_report: bool = True, file: str | None = None,
                   bus_held: bool = False, cycle_hz: float | None = None,
                   record_zero: Callable[[str], Any] | None = None):
        """Run an already loaded and checked sequence on the caller's thread with the
        session's client and event hub; returns the runner's outcome (result, report, run
        folder). This is how ``seqrun run`` runs (its prompts are the terminal's own); faces
        that answer questions through events use :meth:`run_sequence`. ``record_zero``:
        what a power_off step calls to record the pose the arm is switched off in;
        ``run_control``: the run's :class:`~seqrun.service.run_control.RunControl`
        (``seqrun status|halt`` from another terminal), attached to the run's executor."""
        from seqrun.runner import run_sequence as run_with_log
        from seqrun.stop_requests import StopRequests

        requests = requests if requests is not None else StopRequests()

        def hook(executor) -> None:
            self._adopt(executor)
            if self.zero is not None:  # for the log and any face
                executor.emit("zero_reference", **self.zero.as_dict())
            executor.record_zero = record_zero
            if run_control is not None:  # `seqrun status|halt` from another terminal
                run_control.attach(executor)
            if on_executor is not None:
                on_executor(executor)

        def go():
            return run_with_log(loaded, self.arm, self.connection, log_dir=log_dir, file=file,
                                speed=speed, first_step=first_step,
                                command_mode=command_mode, cycle_hz=cycle_hz,
                                confirm=confirm, before_step=before_step,
                                on_executor=hook, confirm_clear_latched=confirm_clear_latched,
                                meta=meta, html_report=html_report, requests=requests,
                                warn=warn, client=self.client, events=self._hub)

        if bus_held:  # run_sequence's worker: the activity is registered already
            return go()
        activity = self._begin("run", {"file": file or loaded.file, "run_dir": str(log_dir)})
        with self._state:
            self._run_info = RunInfo(file or loaded.file, None, None, len(loaded.steps),
                                     str(log_dir) if log_dir is not None else None)
        result = ActivityResult("run", "failed", EXIT_FAULT_CODE, "interrupted")
        try:
            with self._bus:
                outcome = go()
            result = _result("run", outcome.result, run_dir=log_dir)
            return outcome
        finally:
            self._end(activity, result)

    def pause(self) -> None:
        """Pause the run (controlled stop, hold); :meth:`resume` goes on."""
        executor = self._running_executor("pause")
        executor.pause()
        with self._state:
            self._paused = True

    def resume(self) -> None:
        executor = self._running_executor("resume")
        with self._state:
            if self._halted is not None:
                raise Refused("resume: the arm was halted; nothing restarts it")
        executor.resume()
        with self._state:
            self._paused = False

    def _running_executor(self, what: str):
        with self._state:
            activity, executor = self._activity, self._executor
        if activity is None or activity.kind != "run" or executor is None:
            raise Refused(f"{what}: no sequence is running")
        return executor

    def step(self) -> None:
        """In step mode: let the next step start (answers its before-step question yes)."""
        with self._state:
            waiting = [q for q in self._questions.values() if q.step]
        if not waiting:
            raise Refused("step: no step is waiting to start")
        for q in waiting:
            self.answer(q.id, True)

    def abort(self, reason: str = "operator abort") -> None:
        """Controlled stop of whatever moves (run, move, jog); the activity ends (130 for a
        run or move; a jog ends normally). As with Ctrl-C, a second abort of a run or move
        is a Halt."""
        executor, deadman = self._executor, self._deadman
        if deadman is not None:
            deadman.release(reason)  # at most one abort per jog
        elif executor is not None:
            executor.abort(reason)
        self._withdraw_questions()

    def _ask(self, text: str, *, step: bool = False) -> bool:
        """A question for any face: published, answered by :meth:`answer` (or withdrawn
        -> no when the activity is stopped)."""
        with self._state:
            self._question_ids += 1
            q = _Question(f"q{self._question_ids}", text, step)
            self._questions[q.id] = q
        activity = self._activity
        by = activity.started_by if activity is not None else None
        self._publish("confirm_requested", question_id=q.id, text=text,
                      **({"started_by": by} if by is not None else {}))
        executor = self._executor
        while not q.answered.wait(0.05):
            # A stop request posted meanwhile (abort, STOP) answers no at once.
            if executor is not None and executor.requests:
                self._resolve(q, False)
        return bool(q.yes)

    def answer(self, question_id: str, yes: bool) -> None:
        """Answer a ``confirm_requested`` question (any thread). Refused: unknown or
        already answered question."""
        with self._state:
            q = self._questions.get(question_id)
        if q is None:
            raise Refused(f"answer: no open question {question_id!r}")
        if not isinstance(yes, bool):
            raise Refused(f"answer: yes must be true or false, got {yes!r}")
        self._resolve(q, yes)

    def _resolve(self, q: "_Question", yes: bool) -> None:
        with self._state:
            if self._questions.pop(q.id, None) is None:
                return
            q.yes = yes
        self._publish("confirm_answered", question_id=q.id, yes=yes)
        q.answered.set()

    def _withdraw_questions(self) -> None:
        with self._state:
            open_ = list(self._questions.values())
        for q in open_:
            self._resolve(q, False)

    def pending_questions(self) -> dict[str, str]:
        """Questions waiting for an answer: id -> text."""
        with self._state:
            return {q.id: q.text for q in self._questions.values()}

    # ------------------------------------------------------------------ poses
    def pose_names(self) -> list[str]:
        """Every pose the session can move to (the project's and the shipped ones)."""
        from seqrun.poses import available_poses

        return list(available_poses(self.poses_dir))

    def save_pose(self, name: str, *, overwrite: bool = False, description: str = "") -> Path:
        """Write a pose file from the measured joints (the project's poses folder)."""
        from datetime import datetime, timezone

        from seqrun.errors import UserInputError
        from seqrun.poses import check_pose_name, pose_document, save_pose

        try:
            check_pose_name(name)
        except UserInputError as exc:
            raise Refused(str(exc)) from None
        with self._state:
            joints, stale = list(self._joints), self._stale
        if any(x is None for x in joints) or stale:
            raise Refused("save pose: no current reading of the arm")
        folder = (self.project.poses_dir if self.project is not None else Path("poses"))
        path = Path(folder) / f"{name}.yaml"
        if path.exists() and not overwrite:
            raise Refused(f"save pose: {path} exists (overwrite it explicitly)")
        values = {j.name: round(float(x), 3) for j, x in zip(self.arm.joints, joints)
                  if j.locked is None and x is not None}
        try:
            pose = pose_document(name, self.arm, values, description=description,
                                 source="simulator" if self.connection.is_simulator else "arm",
                                 saved_at=datetime.now(timezone.utc).replace(microsecond=0))
        except ValueError as exc:
            raise Refused(f"save pose: {exc}") from None
        path.parent.mkdir(parents=True, exist_ok=True)
        save_pose(path, pose)
        return path


@dataclass
class _Question:
    id: str
    text: str
    step: bool = False
    yes: bool | None = None

    def __post_init__(self) -> None:
        self.answered = threading.Event()


def _flags_fault(flags: tuple[str, ...]) -> bool:
    from seqrun.powercube.protocol import StateFlag

    return any(n in StateFlag.__members__ and StateFlag[n] & StateFlag.FAULTS for n in flags) \
        or "NOT_OK" in flags


def _result(kind: str, run, run_dir: Path | None = None) -> ActivityResult:
    confirmed = None
    if kind in ("reset", "home", "arm_up"):
        confirmed = run.exit_code == 0
    return ActivityResult(kind, run.status, run.exit_code,
                          run.extra.get("summary") or run.message, run_dir, run, confirmed)


class _ControlHandler:
    """What a control socket (seqrun.service.control_socket) serves for a session."""

    def __init__(self, session: ArmSession) -> None:
        self._session = session

    def status_dict(self) -> dict[str, Any]:
        return self._session.status_dict()

    def halt(self, reason: str) -> dict[str, Any]:
        return self._session.halt_dict(reason)


def _finite(value: Any, what: str) -> float:
    """``value`` as a finite float; a boolean or a text is not a number (``True`` is not 1
    and ``"12"`` not 12: every face passes typed values on)."""
    import numbers

    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise Refused(f"{what}: {value!r} is not a number")
    x = float(value)
    if not math.isfinite(x):
        raise Refused(f"{what}: {value!r} is not a finite number")
    return x


__all__ = ["API_VERSION", "ACTIVITY_STATES", "JOG_DEADMAN_S", "Activity", "ActivityResult",
           "ArmSession", "ArmStatus", "JointStatus", "RunInfo", "Refused", "Event"]
