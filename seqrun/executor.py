"""The executor: runs a validated sequence step by step against an arm driver.

Safety rules it implements (docs/safety.md tells the operator's side):

- Before the first motion it reads the arm and re-validates the sequence from the
  measured start state; nothing moves if that fails.
- Every cycle (``control.cycle_hz``) of a move or wait it reads every module (from the
  extended acknowledges of the motion commands, or FPosStateDio reads) and checks state
  flags, missing acknowledges, following error against the plan and the workspace guards.
  Any fault -> Halt broadcast at once, the run ends with exit code 3.
- Operator abort -> controlled stop (ruckig to zero velocity, streamed like a move), then
  hold, exit code 130. A second abort, or :meth:`Executor.halt`, -> Halt broadcast.
- Nothing restarts motion by itself: after a stop the executor only holds and reports.

Control methods (:meth:`abort`, :meth:`halt`, :meth:`pause`, :meth:`resume`) may be called
from any thread (signal handler, web console); the run loop acts on them within a cycle.
Events are typed records (seqrun/events.py): the run log records them synchronously
(``listeners``); faces subscribe to ``events`` on queues of their own.

The executor speaks joints: user degrees (planning, checks, events) and the drive's radians
(what the driver reports); everything about the arm's wire protocol (frames, retries, state
words, watchdog, Halt) is behind :class:`seqrun.drivers.base.ArmDriver`.
"""

from __future__ import annotations

import gc
import math
import threading
import time
import traceback
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Callable, Iterable

import numpy as np

from seqrun import kinematics
from seqrun.arm import ArmDescription
from seqrun.clock import Clock
from seqrun.drivers import (ArmDriver, CycleState, HaltConfirmation, JointState, LimitValues,
                            MotionRefused, as_driver)
from seqrun.events import EventHub, make_event
from seqrun.errors import BusError, RunAborted
from seqrun.limits import LimitsInForce
from seqrun.planner import Limits, MovePlan, plan_move, plan_stop
from seqrun.usermessages import user_message
from seqrun.telemetry import VelocityWindow, joint_flags
from seqrun.tracking import MoveTracking, velocity_window
from seqrun.stop_requests import FROM_OUTSIDE, OPERATOR_HALT, StopRequest, StopRequests

# Result types, the operator's abort and exit codes live in seqrun/results.py; imported
# from here too.
from seqrun.results import (EXIT_FAULT, EXIT_INVALID, EXIT_OK,  # noqa: F401
                            EXIT_OPERATOR_ABORT, EXIT_USAGE, OperatorAbort, RunResult,
                            StepResult, fault_cause, halt_fields, latched_message)

if TYPE_CHECKING:
    from seqrun.poses import PoseDirs

#: A synchronous recorder: gets every typed event (it reads like the events.jsonl dict).
Listener = Callable[[Any], None]


@dataclass
class Measurement:
    """One reading of the whole arm."""

    t: float
    user_deg: np.ndarray                 # every joint, user coordinates
    short_state: dict[int, CycleState]   # per module id: the state sent with the reading
    #: Full states, where this reading includes them (after home/reset/halt, a fault).
    state_words: dict[int, JointState] | None = None
    #: When each joint answered (clock times, joint order, from the bus's own stamps;
    #: None: not known, ``t`` stands for all of them).
    answered_at: np.ndarray | None = None

    @property
    def at(self) -> float:
        """The reading's time: when the joints answered (their mean) where known."""
        return self.t if self.answered_at is None else float(self.answered_at.mean())


def _round(x: float | None, nd: int = 4) -> float | None:
    return None if x is None else round(float(x), nd)


class Executor:
    """Runs resolved steps; see the module docstring for the safety rules.

    ``driver``: the arm's :class:`~seqrun.drivers.base.ArmDriver`; a PowerCube client is
    accepted too (wrapped in the PowerCube driver)."""

    #: Records the zero reference at a power_off step (set by whoever runs the sequence;
    #: None: a dry run or the built-in simulator, nothing is recorded).
    record_zero: Callable[[str], Any] | None = None

    def __init__(self, driver: ArmDriver | Any, arm: ArmDescription, clock: Clock, *,
                 poses_dir: PoseDirs | None = None, speed: float = 1.0,
                 command_mode: str | None = None, cycle_hz: float | None = None,
                 confirm: Callable[[str], bool] | None = None,
                 before_step: Callable[[Any], bool] | None = None,
                 listeners: Iterable[Listener] = (), dry_run: bool = False,
                 confirm_clear_latched: Callable[[str], bool] | None = None,
                 requests: StopRequests | None = None,
                 events: EventHub | None = None) -> None:
        if not 0 < speed <= 1:
            raise ValueError("speed must lie in (0, 1]")
        self.driver: ArmDriver = as_driver(driver, arm)
        self.arm = arm
        self.clock = clock
        self.poses_dir = poses_dir
        self.speed = speed
        self.command_mode = command_mode or arm.control.command_mode
        self.cycle = 1.0 / (cycle_hz or arm.control.cycle_hz)
        self.confirm = confirm
        self.before_step = before_step
        #: Asked before a Reset clears a fault the modules had latched before the run
        #: (real hardware: someone may have pressed the emergency stop for a reason).
        #: None: not asked (simulator, dry run); the fault is still reported.
        self.confirm_clear_latched = confirm_clear_latched
        self.latched_at_start: list[dict[str, Any]] = []
        self._latched_cleared_ok = False
        #: Synchronous recorders (the run log): called with every typed event on the
        #: loop's thread; they must be fast and never block. Faces subscribe to ``events``.
        self.listeners: list[Listener] = list(listeners)
        #: Typed events for subscribers, each on its own queue (seqrun/events.py).
        self.events = events if events is not None else EventHub()
        self._velocity = VelocityWindow(velocity_window(self.cycle))
        #: Called with the slack (seconds) before the loop sleeps until its next cycle: the
        #: live view renders there, on the loop's own thread, only when it has time.
        self.idle_hooks: list[Callable[[float], None]] = []
        self.dry_run = dry_run
        self.chain = kinematics.Chain.from_arm(arm)
        self.offsets_deg = np.array([j.offset_deg for j in arm.joints])
        self.modules = arm.module_ids
        self.movable = [i for i, j in enumerate(arm.joints) if j.locked is None]
        self.limits = Limits.from_arm(arm, speed=speed)
        # MaxVel/MaxAcc per joint as the modules hold them (preflight readback, set_limits):
        # every plan stays within these and the arm file's.
        self.limits_in_force = LimitsInForce(arm)
        # The poses the sequence was validated with (frozen at load time).
        self.poses: dict = {}
        # Bound on a run's (simulated) time; the dry run sets it (control.max_dry_run_s).
        self.time_limit_s: float | None = None
        self.driver.configure(cycle_s=self.cycle, run_limits=self.limits,
                              command_mode=self.command_mode, emit=self.emit)
        # Stop requests: posted from any thread or signal handler without a lock, acted on
        # by the run loop (see seqrun/stop_requests.py).
        self.requests = requests if requests is not None else StopRequests()
        self._aborts = 0
        self._halt: StopRequest | None = None
        self._taking = False
        self._paused = threading.Event()
        self.waiting_for_operator = False
        # Last sign of life of the run loop (time.monotonic): the watchdog keeper refreshes
        # only while the loop makes progress.
        self._heartbeat = time.monotonic()
        #: The result of a run that a BaseException (KeyboardInterrupt, SystemExit) ended.
        self.interrupted_result: RunResult | None = None
        # Run bookkeeping.
        self._t0 = clock.now()
        self.last: Measurement | None = None
        self.commanded_deg: np.ndarray | None = None
        self.min_heights_mm: dict[str, float] = {}
        #: Smallest clearance seen per pair of link volumes / obstacles (the closest pair of
        #: each cycle), mm.
        self.min_distances_mm: dict[str, float] = {}
        self.not_verified: list[str] = []
        self._current_step: StepResult | None = None
        self._move_limits = self.limits
        self._tracking: MoveTracking | None = None
        #: Joint solutions of end-effector targets as validated from the measured start
        #: (step number -> user degrees); the steps solve again and must land close.
        self.validated_targets: dict[int, np.ndarray] = {}
        #: Measured joints where the last move started (relative checkpoints).
        self.motion_start_deg: np.ndarray | None = None
        #: Extra check of every streamed cycle (a straight-line move's deviation).
        self.path_check: Callable[[Measurement], None] | None = None
        #: The emergency Halt of this run and what confirmed it (None: no Halt yet).
        self.halt_result: HaltConfirmation | None = None

    # ------------------------------------------------------------------ control (any thread)
    def abort(self, reason: str = "operator abort") -> None:
        """First call: controlled stop. Second call: Halt. Takes no lock and calls no
        listener (safe in a signal handler); the run loop acts within a cycle."""
        self.requests.abort(reason)

    def halt(self, reason: str = "STOP", cause: str = OPERATOR_HALT) -> None:
        """Immediate Halt (second Ctrl-C, SIGTERM, STOP button); like :meth:`abort` safe
        in a signal handler. A ``cause`` other than operator_halt ends the run as a fault."""
        self.requests.halt(reason, cause)

    def _take_requests(self) -> None:
        """Run loop only: act on the stop requests posted since the last cycle."""
        self._heartbeat = time.monotonic()
        if self._taking or not self.requests:
            return
        self._taking = True   # a listener reading the flags must not re-enter
        try:
            for request in self.requests.take():
                self._paused.clear()
                if request.kind == "abort":
                    self._aborts += 1
                    self.emit("abort_requested", reason=request.reason, count=self._aborts)
                    if self._aborts >= 2 and self._halt is None:
                        self._halt = request
                elif self._halt is None:
                    self._halt = request
                    self.emit("halt_requested", reason=request.reason, cause=request.cause)
        finally:
            self._taking = False

    @property
    def _abort_requests(self) -> int:
        self._take_requests()
        return self._aborts

    @property
    def _halt_requested(self) -> bool:
        self._take_requests()
        return self._halt is not None

    def pause(self) -> None:
        self._paused.set()
        self.emit("pause_requested")

    def resume(self) -> None:
        self._paused.clear()
        self.emit("resumed")

    @property
    def abort_requested(self) -> bool:
        return self._aborts > 0

    def ask_operator(self, question: Callable[[Any], bool], arg: Any) -> bool:
        """Ask the operator; while asking, Ctrl-C may interrupt the question."""
        self.waiting_for_operator = True
        try:
            return question(arg)
        finally:
            self.waiting_for_operator = False

    @property
    def client(self) -> Any:
        """The PowerCube driver's client (tests and benches look at its frames and
        counters); None for another driver."""
        return getattr(self.driver, "client", None)

    def on_discard(self, msg: Any, reason: Any) -> None:
        """Kept for callers that wire ``client.on_discard`` to the executor: the driver
        logs the discarded frame."""
        handler = getattr(self.driver, "on_discard", None)
        if handler is not None:
            handler(msg, reason)

    # ------------------------------------------------------------------ events
    def emit(self, type_: str, **data: Any) -> None:
        """Make the typed record (seqrun/events.py) and hand it to the synchronous
        recorders (``listeners``: the run log, which must be on disk before the next
        instant) and to the hub's subscribers (each on its own queue: never waits)."""
        now = self.clock.now()
        if self._current_step is not None and "step" not in data:
            data["step"] = self._current_step.number
        derived = self._derived(type_, data) if self.events.subscribers else {}
        event = make_event(type_, round(now - self._t0, 6), data, clock_s=now,
                           **derived.get(type_, {}))
        for listener in list(self.listeners):
            try:
                listener(event)
            # A broken display must never stop a run: rich, for one, answers a closed
            # stdout pipe with SystemExit from inside the listener.
            except (Exception, SystemExit) as exc:
                self.listeners.remove(listener)
                self.emit("listener_failed", error=repr(exc))
        self.events.publish(event)
        if "cycle" in derived:
            # Faces get every streamed cycle as a measurement too (not logged: the
            # setpoint holds it).
            self.events.publish(make_event("measurement", event.t, derived["cycle"],
                                           clock_s=now, **derived["cycle_derived"]))

    def _derived(self, type_: str, data: dict) -> dict[str, dict]:
        """Velocities and flag names of a measurement or a setpoint, for subscribers."""
        if type_ == "measurement":
            joints = data.get("joints_deg")
        elif type_ == "setpoint":
            joints = data.get("measured_deg")
        else:
            return {}
        short = data.get("state") or []
        if joints is None:
            return {}
        # the reading's time: when the joints answered (a stalled host stamps late)
        self._velocity.add(self.last.at if self.last is not None else self.clock.now(),
                           joints)
        # The reading this event reports (read_arm and refresh_measurement set it first),
        # decoded by the driver; its full states only for a measurement that shows them.
        m = self.last
        flags, fault = joint_flags(
            self.arm.joint_names, self.modules, m.short_state if m is not None else {},
            m.state_words if m is not None and type_ == "measurement" else None)
        extra = {"velocities_deg_s": self._velocity.velocity(), "flags": flags,
                 "fault": fault}
        if type_ == "measurement":
            return {"measurement": {**extra, "source": "step" if "after" in data
                                    else "monitor"}}
        cycle = {"joints_deg": joints, "state": short}
        if "step" in data:
            cycle["step"] = data["step"]
        return {"cycle": cycle, "cycle_derived": {**extra, "source": "cycle"}}

    def _idle_until(self, t: float) -> None:
        """Sleep until ``t``; the idle hooks may use the slack first."""
        for hook in list(self.idle_hooks):
            slack = t - self.clock.now()
            if slack <= 0:
                break
            try:
                hook(slack)
            except (Exception, SystemExit) as exc:  # a broken display never stops a run
                self.idle_hooks.remove(hook)
                self.emit("listener_failed", error=repr(exc))
        self.clock.sleep_until(t)

    def _idle(self, seconds: float) -> None:
        self._idle_until(self.clock.now() + seconds)

    def refresh_measurement(self, after: str,
                            words: dict[int, JointState] | None = None) -> None:
        """Emit the arm's state after a step that changes the modules without moving them
        (home, reset, halt) and after a fault's Halt, so the display and the event log show
        the modules' state, not the last motion cycle's. ``words``: full states the step has
        just read (home, reset: nothing moved, positions stand); otherwise the whole arm is
        read, full states included."""
        try:
            if words is None or self.last is None:
                m = self.read_arm()
                words = self.read_state_words()
            else:
                m = self.last
                words = {**(m.state_words or {}), **words}
        except Exception as exc:  # noqa: BLE001 - a module that does not answer after a
            # Halt is reported by the Halt path; this reading is only for the display
            self.emit("measurement_failed", after=after, error=str(exc))
            return
        self.last = replace(m, state_words=words)
        short = [words[module].cycle_code if module in words
                 else int(m.short_state.get(module, 0)) for module in self.modules]
        self.emit("measurement", after=after, joints_deg=_r(m.user_deg), state=short,
                  states={str(k): v.describe() for k, v in words.items()})

    # ------------------------------------------------------------------ conversions
    def to_module_rad(self, user_deg: np.ndarray) -> np.ndarray:
        return np.radians(np.asarray(user_deg) + self.offsets_deg)

    def to_user_deg(self, module_rad: np.ndarray) -> np.ndarray:
        return np.degrees(np.asarray(module_rad)) - self.offsets_deg

    # ------------------------------------------------------------------ the driver
    # Every call below reaches the bus: each one counts as a sign of life of the run loop
    # (the watchdog keeper feeds the modules only while the loop makes progress).
    def read_arm(self) -> Measurement:
        """Read position and state of every joint (lost reads retried by the driver)."""
        self._heartbeat = time.monotonic()
        return self._measured(self.driver.read())

    def _measured(self, reading) -> Measurement:
        m = Measurement(self.clock.now(), self.to_user_deg(reading.positions_rad),
                        reading.states,
                        answered_at=getattr(reading, "answered_at", None))
        self.last = m
        return m

    def read_state_word(self, module: int) -> JointState:
        """The full state of one module."""
        return self.driver.read_state(module)

    def read_state_words(self, modules: list[int] | None = None) -> dict[int, JointState]:
        """The full state of several modules (all: None)."""
        self._heartbeat = time.monotonic()
        return self.driver.read_states(modules)

    def reset_modules(self, modules: list[int] | None) -> None:
        """Reset (clear errors) of ``modules``; None: all of them at once."""
        self._heartbeat = time.monotonic()
        self.driver.reset(modules)

    def home_modules(self, modules: list[int] | None) -> None:
        """Home ``modules``; None: all of them at once."""
        self._heartbeat = time.monotonic()
        self.driver.home(modules)

    def halt_modules(self, modules: list[int] | None) -> None:
        """A deliberate Halt of ``modules`` (a ``halt`` step); None: all at once."""
        self._heartbeat = time.monotonic()
        self.driver.halt(modules)

    def write_limits(self, values: dict[str, LimitValues]) -> int:
        """Write MinPos/MaxPos (and MaxVel/MaxAcc where given) per joint and read them
        back; a value that reads back different is a fault. Returns the values written."""
        self._heartbeat = time.monotonic()
        return self.driver.write_limits(values)

    def wait_for_states(self, modules: list[int] | None, ok: Callable[[JointState], bool],
                        timeout_s: float, failure: str) -> dict[int, JointState]:
        """Poll the full state every cycle until ``ok`` holds for every module."""
        deadline = self.clock.now() + timeout_s
        while True:
            self._check_halt_request()
            states = self.read_state_words(modules)
            bad = {m: f for m, f in states.items() if not ok(f)}
            if not bad:
                return states
            if self.clock.now() >= deadline:
                module, flags = next(iter(bad.items()))
                raise self.module_fault(module, flags, failure)
            self._idle(self.cycle)

    # ------------------------------------------------------------------ checks
    def check_states(self, m: Measurement, *, require_homed: bool = True) -> None:
        """Raise a RunAborted naming module and flags for a module whose reading says it
        refuses motion and whose full state shows a fault (or, with ``require_homed``, it
        is not homed)."""
        for module, state in m.short_state.items():
            if state.refuses_motion:
                flags = self.read_state_word(module)
                if flags.faulted or (require_homed and not flags.homed):
                    raise self.module_fault(module, flags)

    def _fault_after_halt(self, module: int, short: CycleState) -> RunAborted:
        """The fault of a module whose acknowledge said NOT_OK during a move, named from
        its state word (read after the Halt)."""
        try:
            flags = self.read_state_word(module)
        except BusError as exc:
            return RunAborted("module_fault", f"module {module}: NOT_OK in its acknowledge "
                              f"[short state {short.describe()}]; its state word could not be "
                              f"read: {exc}", module=module)
        if not flags.ready:
            return self.module_fault(module, flags)
        joint = self.arm.joint_names[self.modules.index(module)]
        return RunAborted("motion_refused", f"module {module} ({joint}): refused a motion "
                          f"command during the move (NOT_OK in its acknowledge) "
                          f"[state {flags.describe()}]", module=module)

    def module_fault(self, module: int, flags: JointState, context: str = "") -> RunAborted:
        """A RunAborted naming the module, its joint and the decoded fault flags."""
        joint = self.arm.joint_names[self.modules.index(module)] if module in self.modules else "?"
        what = flags.fault_text if flags.faulted else "not homed (HOME_OK clear)"
        text = f"module {module} ({joint}): {what}"
        if context:
            text += f" {context}"
        return RunAborted(flags.cause, f"{text} [state {flags.describe()}]", module=module)

    def check_guards(self, m: Measurement) -> None:
        q = np.radians(m.user_deg)
        self.check_geometry(q)
        guards = self.arm.workspace.guards
        if not guards:
            return
        heights = kinematics.point_heights(self.chain, q)
        for guard in guards:
            for name in guard.points:
                z = heights[name]
                key = f"{guard.name}:{name}"
                self.min_heights_mm[key] = min(self.min_heights_mm.get(key, math.inf), z)
                if z < guard.min_z_mm:
                    raise RunAborted("workspace_guard",
                                     f"workspace guard '{guard.name}': {name} at z = {z:.1f} mm, "
                                     f"below {guard.min_z_mm:.1f} mm")

    def check_geometry(self, q_rad: np.ndarray) -> None:
        """Link volumes against the arm file's obstacles and each other (measured joints)."""
        geometry = self.__dict__.get("_geometry")
        if geometry is None:
            from seqrun.geometry import Geometry

            geometry = self.__dict__["_geometry"] = Geometry(self.arm)
        if geometry.empty:
            return
        smallest = geometry.smallest(q_rad)
        if smallest is None:
            return
        key = smallest.pair
        self.min_distances_mm[key] = min(self.min_distances_mm.get(key, math.inf),
                                         smallest.distance_mm)
        if smallest.distance_mm < geometry.margin_mm:
            a, b = smallest.pair.split("~", 1)
            raise RunAborted("collision",
                             f"geometry: {a} {smallest.distance_mm:.1f} mm from {b}, closer than "
                             f"the margin {geometry.margin_mm:g} mm")

    def monitor(self) -> Measurement:
        """One monitoring cycle without motion commands (waits, checkpoints). A module
        that is not homed yet is no fault here: nothing is commanded to move."""
        self._check_halt_request()
        m = self.read_arm()
        self.check_states(m, require_homed=False)
        self.check_guards(m)
        self.emit("measurement", joints_deg=_r(m.user_deg), state=self._states(m))
        return m

    def _states(self, m: Measurement) -> list[int]:
        """The short state of every joint's module, for the event log (compact ints)."""
        return [int(m.short_state.get(module, 0)) for module in self.modules]

    def _operator_halt_seen(self, exc: Exception) -> Exception:
        """A module reporting HALTED while an operator's Halt is posted is that Halt (an
        arm session sends the broadcast from the operator's thread at once and posts the
        request; the loop may read HALTED before it takes the request): exit 130."""
        if (isinstance(exc, RunAborted) and exc.cause == "halted" and self._halt_requested
                and self._halt.cause == OPERATOR_HALT):
            return RunAborted(OPERATOR_HALT, f"Halt requested by the operator "
                                             f"({self._halt.reason})")
        return exc

    def _check_halt_request(self) -> None:
        if self._halt_requested:
            halt = self._halt
            if halt.cause == OPERATOR_HALT:
                raise RunAborted(OPERATOR_HALT, f"Halt requested by the operator ({halt.reason})")
            raise RunAborted(halt.cause, f"{halt.reason}: Halt")
        if self.time_limit_s is not None and self.clock.now() - self._t0 > self.time_limit_s:
            raise RunAborted("time_limit", f"stopped after {self.time_limit_s:g} s of simulated "
                             "time (control.max_dry_run_s of the arm file): the sequence takes "
                             "longer than a dry run may; raise the bound to check it all")

    # ------------------------------------------------------------------ motion
    def move(self, target_deg: np.ndarray, active: list[int], limits: Limits, *,
             tolerance_deg: float, timeout_s: float | None) -> dict[str, Any]:
        """Plan from the measured state to ``target_deg`` and stream it; returns metrics."""
        m = self.read_arm()
        self.check_states(m)
        self._move_limits = limits
        start_deg = m.user_deg.copy()
        self.motion_start_deg = start_deg.copy()  # for relative checkpoints
        moving = [i for i in active if abs(target_deg[i] - start_deg[i]) > 1e-9]
        plan = plan_move(np.radians(start_deg), np.radians(target_deg), limits, moving)
        self.commanded_deg = np.where(np.isin(np.arange(len(target_deg)), moving),
                                      target_deg, start_deg)
        velocity_limit = _r(np.degrees(limits.velocity))
        self.emit("move_planned", duration_s=_round(plan.duration),
                  start_deg=_r(start_deg), target_deg=_r(target_deg),
                  joints=[self.arm.joints[i].name for i in moving],
                  velocity_limit_deg_s=velocity_limit)
        if self._current_step is not None:
            self._current_step.planned_duration_s = plan.duration
        if timeout_s is not None and plan.duration > timeout_s:
            raise RunAborted("timeout", f"the move is planned to take {plan.duration:.3g} s, "
                             f"longer than its timeout_s {timeout_s:g} s; nothing was moved")
        self._tracking = MoveTracking(velocity_window(self.cycle))
        t_move = self.clock.now()
        if moving:
            self._heartbeat = time.monotonic()
            self.driver.start_motion(moving, limits)
            # A step's timeout covers the whole move; the default allows the plan plus
            # the arm's settle time.
            deadline = (timeout_s if timeout_s is not None
                        else plan.duration + self.arm.control.settle_timeout_s)
            try:
                self._stream(plan, moving, tolerance_deg, deadline, stop_on_abort=True)
            finally:
                self.driver.end_motion()
        elapsed = self.clock.now() - t_move
        return {"planned_duration_s": plan.duration, "executed_duration_s": elapsed,
                "duration_ratio": _round(elapsed / plan.duration) if plan.duration > 0 else None,
                "peak_velocity_deg_s": _r(np.degrees(plan.peak_velocity())),
                "peak_measured_velocity_deg_s": [0.0] * len(target_deg),
                "velocity_limit_deg_s": velocity_limit,
                **self.tracking_figures(target_deg)}

    def tracking_figures(self, target_deg=None) -> dict[str, Any]:
        """The current move's tracking figures (seqrun/tracking.py) up to now."""
        if self._tracking is None:
            return {}
        target = self.commanded_deg if target_deg is None else target_deg
        return self._tracking.figures(target)

    def follow(self, plan, *, tolerance_deg: float, timeout_s: float | None,
               path_check: Callable[[Measurement], None] | None = None,
               command_mode: str | None = None) -> dict[str, Any]:
        """Stream a precomputed plan (a :class:`~seqrun.planner.SampledPlan`) that starts
        where the arm stands; ``path_check`` runs on every cycle's measurement;
        ``command_mode`` overrides the run's setpoint law for this plan."""
        m = self.read_arm()
        self.check_states(m)
        self.motion_start_deg = m.user_deg.copy()  # for relative checkpoints
        moving = list(plan.active)
        self.commanded_deg = np.degrees(plan.target)
        self.emit("move_planned", duration_s=_round(plan.duration), start_deg=_r(m.user_deg),
                  target_deg=_r(np.degrees(plan.target)),
                  joints=[self.arm.joints[i].name for i in moving], sampled=True)
        if self._current_step is not None:
            self._current_step.planned_duration_s = plan.duration
        self._tracking = MoveTracking(velocity_window(self.cycle))
        t_move = self.clock.now()
        if moving:
            deadline = (timeout_s if timeout_s is not None
                        else plan.duration + self.arm.control.settle_timeout_s)
            self.path_check = path_check
            try:
                self._heartbeat = time.monotonic()
                self.driver.start_motion(moving, self.limits, command_mode=command_mode)
                self._stream(plan, moving, tolerance_deg, deadline, stop_on_abort=True)
            finally:
                self.path_check = None
                self.driver.end_motion()
        elapsed = self.clock.now() - t_move
        return {"planned_duration_s": plan.duration, "executed_duration_s": elapsed,
                "duration_ratio": _round(elapsed / plan.duration) if plan.duration > 0 else None,
                "peak_velocity_deg_s": _r(np.degrees(plan.peak_velocity())),
                "peak_measured_velocity_deg_s": [0.0] * self.arm.dof,
                **self.tracking_figures(np.degrees(plan.target))}

    def _cycle(self, plan: MovePlan, t: float, moving: list[int],
               measured_deg: np.ndarray) -> Measurement:
        """One control cycle through the driver: ``plan``'s setpoints at plan time ``t``
        for ``moving``, and a reading of every joint.

        The driver looks at every answer as it arrives: the first that refuses motion
        ends the cycle at once, and the arm is halted before anything else; then the
        module's full state names the cause.
        """
        self._heartbeat = time.monotonic()
        try:
            reading = self.driver.cycle(plan, t, moving, measured_deg)
        except MotionRefused as refused:
            self.emergency_halt()
            raise self._fault_after_halt(refused.module, refused.state) from None
        return self._measured(reading)

    def _stream(self, plan: MovePlan, moving: list[int], tolerance_deg: float,
                deadline: float, *, stop_on_abort: bool) -> None:
        """Stream ``plan`` cycle by cycle until every moving joint is in tolerance."""
        t_start = self.clock.now()
        bound = self.arm.control.max_following_error_deg
        measured = self.last.user_deg if self.last is not None else np.degrees(plan.start)
        k = 0
        while True:
            t_cycle = t_start + k * self.cycle
            self._idle_until(t_cycle)
            t = self.clock.now() - t_start
            self._check_halt_request()
            if stop_on_abort and (self._abort_requests or self._paused.is_set()):
                self._controlled_stop(plan, t, moving)
                if self._abort_requests:
                    raise OperatorAbort("operator abort: controlled stop, arm holding")
                self._wait_while_paused()
                # Resumed: re-plan from where the arm stands to the same target.
                m = self.read_arm()
                plan = plan_move(np.radians(m.user_deg), plan.target, self._move_limits, moving)
                t_start, k = self.clock.now(), 0
                deadline = plan.duration + self.arm.control.settle_timeout_s
                continue
            m = self._cycle(plan, t, moving, measured)
            measured = m.user_deg
            self.check_states(m)
            self.check_guards(m)
            if self.path_check is not None:
                self.path_check(m)
            planned_rad, planned_vel, _ = plan.at(t)
            planned_deg = np.degrees(planned_rad)
            error = np.abs(planned_deg - measured)
            worst = int(error.argmax())  # (np.argmax's Python-level dispatch, once a cycle)
            if error[worst] > bound and t <= plan.duration + self.arm.control.settle_timeout_s:
                name = self.arm.joints[worst].name
                raise RunAborted("following_error",
                                 f"{name} (module {self.modules[worst]}) does not follow its plan: "
                                 f"{error[worst]:.2f}° from the planned position (limit {bound}°)"
                                 + self._lag_diagnosis(plan, planned_deg, measured, moving),
                                 module=self.modules[worst])
            logged_planned, logged_measured = _r(planned_deg), _r(measured)
            event_t = round(self.clock.now() - self._t0, 6)
            # When the joints answered (the bus's own stamps): after a host stall the
            # event's time is late, the reading's is not.
            read_t = self._read_t(m)
            if self._tracking is not None:
                # The figures come from the logged values, so events.jsonl reproduces them.
                self._tracking.add(read_t, logged_planned, logged_measured)
            self.emit("setpoint", t=event_t, read_t=read_t, plan_t=round(t, 4),
                      planned_deg=logged_planned, measured_deg=logged_measured,
                      planned_vel_deg_s=_r(np.degrees(planned_vel), 2), state=self._states(m))
            if t >= plan.duration:
                final_error = np.abs(np.degrees(plan.target) - measured)[moving]
                if np.all(final_error <= tolerance_deg):
                    return
                if t > deadline:
                    i = moving[int(np.argmax(final_error))]
                    raise RunAborted("timeout",
                                     f"{self.arm.joints[i].name} (module {self.modules[i]}) not in "
                                     f"position {deadline:.1f} s after the move started: "
                                     f"{float(np.max(final_error)):.2f}° off (tolerance "
                                     f"{tolerance_deg}°)", module=self.modules[i])
            # Next cycle slot; slots missed while waiting on the bus are skipped, not
            # made up in a burst.
            k = max(k + 1, math.ceil((self.clock.now() - t_start) / self.cycle))

    #: Joints that answered further apart than this (s) in one reading get a time each in
    #: the log (a host stall split the cycle's exchange); closer, one time stands for all.
    READ_SPREAD_S = 0.002

    def _read_t(self, m: Measurement) -> float | list[float]:
        """A reading's time as logged (``read_t``): s since the run start, one for all
        joints, or one per joint when they answered far apart."""
        if m.answered_at is None:
            return round(m.t - self._t0, 6)
        at = m.answered_at - self._t0
        if float(at.max() - at.min()) > self.READ_SPREAD_S:
            return [round(float(x), 6) for x in at]
        return round(float(at.mean()), 6)

    #: Below this share of its planned travel a lagging joint counts as hardly moving.
    SLOW_SHARE = 0.5
    #: Travel (deg) below which a joint counts as not moving at all.
    STILL_DEG = 0.02

    def _lag_diagnosis(self, plan: MovePlan, planned_deg: np.ndarray, measured: np.ndarray,
                       moving: list[int]) -> str:
        """The likely cause of a following error, for the operator: every moving joint
        travelling the right way at a small share of its plan points at modules whose FRAMP
        does not blend (each FRAMP restarts from standstill), one joint not moving at all
        at a stuck or blocked joint."""
        start = np.degrees(plan.start)
        direction = np.sign(np.degrees(plan.target) - start)
        planned = (planned_deg - start) * direction
        done = (measured - start) * direction
        shares = {i: done[i] / planned[i] for i in moving if planned[i] > self.STILL_DEG}
        if not shares:
            return ""
        text = ", ".join(f"{self.arm.joints[i].name} {100 * r:.0f} %" for i, r in shares.items())
        if (self.command_mode == "ramp" and len(shares) == len(moving)
                and all(done[i] > self.STILL_DEG and r < self.SLOW_SHARE
                        for i, r in shares.items())):
            return (f"; the module does not seem to blend FRAMP commands: every moving joint "
                    f"travels the right way at a small share of its plan ({text} of the "
                    f"planned travel), as if each FRAMP started from standstill (see "
                    f"docs/safety.md, 'FRAMP blending')")
        still = [self.arm.joints[i].name for i in shares if abs(done[i]) <= self.STILL_DEG]
        if still:
            return f"; {', '.join(still)} did not move at all (stuck, blocked or not enabled?)"
        return ""

    def _controlled_stop(self, plan: MovePlan, t: float, moving: list[int]) -> None:
        """ruckig to zero velocity from the plan's current state, streamed, then hold."""
        pos, vel, acc = plan.at(t)
        velocity, acceleration = self.limits_in_force.maxima()
        limits = Limits.from_arm(self.arm, speed=self.speed, max_velocity_deg_s=velocity,
                                 max_acceleration_deg_s2=acceleration)
        stop = plan_stop(pos, vel, acc, limits, moving)
        self.emit("controlled_stop", duration_s=_round(stop.duration))
        tol = self.arm.control.position_tolerance_deg
        self._stream(stop, moving, max(tol, 0.5), stop.duration + 2.0, stop_on_abort=False)
        self.emit("holding", joints_deg=_r(self.last.user_deg) if self.last else None)

    def _wait_while_paused(self) -> None:
        self.emit("paused")
        while self._paused.is_set() and not self._abort_requests and not self._halt_requested:
            self.monitor()
            self._idle(self.cycle)
        self._check_halt_request()
        if self._abort_requests:
            raise OperatorAbort("operator abort while paused")

    def wait(self, seconds: float) -> None:
        """Wait while monitoring every cycle (keeps faults and watchdog in view)."""
        end = self.clock.now() + seconds
        while self.clock.now() < end:
            self.monitor()
            if self._abort_requests:
                raise OperatorAbort("operator abort during a wait")
            self._idle(min(self.cycle, end - self.clock.now()))

    def wait_in_position(self, tolerance_deg: float, timeout_s: float) -> float:
        """Wait until every commanded joint is within tolerance; returns the time taken."""
        start = self.clock.now()
        target = self.commanded_deg
        while True:
            m = self.monitor()
            if target is None:
                return 0.0
            err = np.abs(m.user_deg - target)[self.movable]
            if np.all(err <= tolerance_deg):
                return self.clock.now() - start
            if self._abort_requests:
                raise OperatorAbort("operator abort during a wait")
            if self.clock.now() - start > timeout_s:
                i = self.movable[int(np.argmax(err))]
                raise RunAborted("timeout", f"{self.arm.joints[i].name} not in position within "
                                 f"{timeout_s} s: {float(np.max(err)):.2f}° off", module=self.modules[i])
            self._idle(self.cycle)

    # ------------------------------------------------------------------ halt
    def emergency_halt(self) -> bool:
        """Halt every module before reading anything, then confirm it by reading every
        module's state back (the driver's :meth:`~seqrun.drivers.base.ArmDriver.halt_and_confirm`).
        Done once per run: a later call returns the first result. Returns whether the Halt
        was sent; the confirmation is in :attr:`halt_result`."""
        if self.halt_result is not None:
            return self.halt_result.sent
        result = self.halt_result = self.driver.halt_and_confirm()
        names = dict(zip(self.modules, self.arm.joint_names))
        if not result.sent:
            self.emit("halt_failed", error=result.error, message=result.describe(names))
        elif result.confirmed:
            self.emit("halt_confirmed", modules=list(result.modules_confirmed),
                      attempts=result.attempts, duration_s=_round(result.duration_s))
        else:
            self.emit("halt_unconfirmed", modules=list(result.modules_unconfirmed),
                      attempts=result.attempts, duration_s=_round(result.duration_s),
                      states={str(k): v.describe() for k, v in
                                                        result.states.items()},
                      message=result.describe(names))
        return result.sent

    def _show_state_after_halt(self) -> None:
        """After a confirmed Halt, the modules' state for the display and the event log
        (an unconfirmed Halt has its own event naming the modules that did not answer)."""
        if self.halt_result is not None and self.halt_result.confirmed:
            self.refresh_measurement("halt")

    def _halt_fields(self) -> dict[str, Any]:
        """``halt_sent``, ``halt_confirmed``, ``modules_not_halted`` for a fault record."""
        return halt_fields(self.halt_result)

    def elapsed_s(self) -> float:
        """Seconds since the run started (the events' time base)."""
        return self.clock.now() - self._t0

    def _halt_note(self) -> str:
        """What the operator must know about the Halt beyond "sent", or ''."""
        result = self.halt_result
        if result is None or result.confirmed:
            return ""
        return "; " + result.describe(dict(zip(self.modules, self.arm.joint_names)))

    # ------------------------------------------------------------------ run
    # ------------------------------------------------------------------ preflight
    def preflight(self, loaded, first_step: int = 1):
        """Read the arm and validate the sequence (from ``first_step``) from the measured
        state. Returns the ValidationResult; only reads reach the bus."""
        from seqrun.validation import validate_sequence

        m = self.read_arm()
        states = self.read_state_words()
        # MinPos/MaxPos/MaxVel/MaxAcc stay stored in the modules across runs.
        self._heartbeat = time.monotonic()
        stored = self.driver.read_limits()
        written = all(
            abs(held.min_position - j.to_module_rad(j.limits_deg[0])) < 1e-5
            and abs(held.max_position - j.to_module_rad(j.limits_deg[1])) < 1e-5
            for j, held in zip(self.arm.joints, stored))
        module_limits = {j.name: (math.degrees(held.max_velocity),
                                  math.degrees(held.max_acceleration))
                         for j, held in zip(self.arm.joints, stored)}
        self.limits_in_force.read_back(module_limits)
        ready = all(f.ready for f in states.values())
        self._record_latched(states)
        started = ready and written
        start_deg = {j.name: float(v) for j, v in zip(self.arm.joints, m.user_deg)}
        steps_before, steps_from = loaded.split_at(first_step)  # as `seqrun run --from`
        result = validate_sequence(steps_from,
                                   self.arm, start_deg, started=started, speed=self.speed,
                                   module_limits=module_limits)
        if first_step > 1:
            before = validate_sequence(steps_before,
                                       self.arm)
            tol = max(1.0, 5 * self.arm.control.position_tolerance_deg)
            for j in self.arm.joints:
                expected = before.final_deg.get(j.name)
                if expected is not None and abs(expected - start_deg[j.name]) > tol:
                    result.errors.append(loaded.steps[first_step - 1].location.error(
                        f"--from {first_step}: the arm is not where this step expects it: "
                        f"{j.name} at {start_deg[j.name]:.2f}°, expected {expected:.2f}° "
                        f"(after steps 1-{first_step - 1})"))
        self.validated_targets = dict(getattr(result, "targets_deg", {}))
        self.emit("preflight", start_deg=_r(m.user_deg), homed=ready, limits_written=written,
                  module_limits={n: _r(v) for n, v in module_limits.items()},
                  states={str(k): v.describe() for k, v in states.items()},
                  errors=[str(e) for e in result.errors], notes=[str(n) for n in result.notes])
        if self.events.subscribers:
            # Faces get the first reading as a measurement too (not logged: the preflight
            # event holds it), its flags decoded by the driver like every other one.
            flags, fault = joint_flags(self.arm.joint_names, self.modules, m.short_state,
                                       states)
            now = self.clock.now()
            self.events.publish(make_event(
                "measurement", round(now - self._t0, 6),
                {"joints_deg": _r(m.user_deg),
                 "state": [states[k].cycle_code if k in states else int(m.short_state[k])
                           for k in self.modules]},
                clock_s=now, flags=flags, fault=fault, source="preflight"))
        return result

    def _record_latched(self, states: dict[int, JointState]) -> None:
        """Faults the modules report before the run sent anything but reads: told on the
        terminal (event ``latched_fault``) and in the report, never cleared silently."""
        names = dict(zip(self.modules, self.arm.joint_names))
        self.latched_at_start = [
            {"module": m, "joint": names.get(m, "?"),
             "flags": f.fault_text, "state": f.describe()}
            for m, f in sorted(states.items()) if f.faulted]
        if self.latched_at_start:
            self.emit("latched_fault", modules=self.latched_at_start,
                      message=self.latched_message())

    def latched_message(self) -> str:
        return latched_message(self.latched_at_start)

    def confirm_clearing_latched(self, modules: list[int] | None) -> None:
        """Called by a Reset step before it clears faults: on real hardware a fault that
        was latched before the run is cleared only when the operator says so (also with
        ``--yes``); declining, or no answer, ends the run as an operator abort."""
        if not self.latched_at_start or self._latched_cleared_ok:
            return
        affected = [e for e in self.latched_at_start
                    if modules is None or e["module"] in modules]
        if not affected:
            return
        if self.confirm_clear_latched is not None:
            question = (self.latched_message() + ". This Reset clears it. Has the cause "
                        "been checked, and may it be cleared?")
            if not self.ask_operator(self.confirm_clear_latched, question):
                raise OperatorAbort("operator did not clear the fault latched before the "
                                    "run; nothing was reset")
            self.emit("latched_fault_cleared", modules=[e["module"] for e in affected],
                      confirmed_by="operator")
        else:
            self.emit("latched_fault_cleared", modules=[e["module"] for e in affected],
                      confirmed_by="not asked (simulator)")
        self._latched_cleared_ok = True

    def _enable_watchdog(self) -> None:
        """Arm the modules' watchdogs (if the arm file asks): the driver keeps them fed
        while the run loop shows signs of life (:meth:`loop_alive`)."""
        self._heartbeat = time.monotonic()
        self.driver.enable_watchdog(self.loop_alive)

    def loop_alive(self, within_s: float) -> bool:
        """True while the run loop made progress within ``within_s`` (real seconds) or
        waits for the operator's answer (a question comes only between steps)."""
        return (self.waiting_for_operator
                or time.monotonic() - self._heartbeat < within_s)

    def _disable_watchdog(self) -> None:
        """After a clean end the arm keeps holding: the watchdogs are disarmed again."""
        self._heartbeat = time.monotonic()
        self.driver.disable_watchdog()

    # ------------------------------------------------------------------ run
    def run(self, loaded, *, first_step: int = 1) -> RunResult:
        """Preflight, then run the steps of ``loaded`` from ``first_step`` (1-based)."""
        from seqrun.steps import HANDLERS

        if not self.clock.is_virtual:
            # The garbage that earlier work left in reference cycles (a report's figures,
            # a web request) is collected now, while nothing moves: left to the collector,
            # a full collection in the loop holds the interpreter as long as it scans
            # (70-100 ms cycles after a report.html, bench/README.md).
            gc.collect()
        self._t0 = self.clock.now()
        self.poses = dict(getattr(loaded, "poses", {}))
        steps = list(loaded.steps)
        results = [StepResult(s.number, s.kind, _label(s), _location(s)) for s in steps]
        # clock_s: the run clock's reading at t = 0, so that the run log can put event
        # times and frame times on one (wall-clock) time base.
        self.emit("run_started", steps=len(steps), first_step=first_step, speed=self.speed,
                  command_mode=self.command_mode, dry_run=self.dry_run, clock_s=self._t0,
                  virtual_time=self.clock.is_virtual, cycle_s=self.cycle,
                  velocity_window_s=velocity_window(self.cycle),
                  arm=self.arm.model_dump(mode="json"))
        status, code, message, fault = "passed", EXIT_OK, "sequence completed", None
        try:
            check = self.preflight(loaded, first_step)
            if check.errors:
                summary = "not valid from the arm's measured state"
                return self._finish(results, "invalid", EXIT_INVALID,
                                    f"{summary}: " + "; ".join(str(e) for e in check.errors),
                                    None, errors=[e.as_dict() for e in check.errors],
                                    summary=summary)
            self._enable_watchdog()
        except Exception as exc:  # noqa: BLE001 - nothing moves yet, but be sure
            self.emergency_halt()
            cause, module = fault_cause(exc)
            message = user_message(exc, self.arm) + self._halt_note()
            fault = {"cause": cause, "module": module, "message": message, "step": None,
                     **self._halt_fields()}
            self.emit("fault", **fault)
            self._show_state_after_halt()
            return self._finish(results, "failed", EXIT_FAULT, message, fault)
        for step, result in zip(steps, results):
            if step.number < first_step:
                result.status = "skipped"
                continue
            self._current_step = result
            try:
                # A request that came before the question is acted on without asking.
                self._check_halt_request()
                if self._abort_requests:
                    raise OperatorAbort("operator abort")
                if self.before_step is not None and not self.ask_operator(self.before_step, step):
                    raise OperatorAbort("operator declined the step")
                self._check_halt_request()
                if self._abort_requests:
                    raise OperatorAbort("operator abort")
                result.started = self.clock.now() - self._t0
                self.emit("step_started", kind=step.kind, label=result.label,
                          location=result.location,
                          **({"include": list(step.include_labels)}
                             if getattr(step, "include_labels", ()) else {}))
                self._tracking = None
                detail = HANDLERS[step.kind](step, self) or {}
                result.detail.update({k: v for k, v in detail.items()
                                      if k != "planned_duration_s"})
                if "planned_duration_s" in detail:
                    result.planned_duration_s = detail["planned_duration_s"]
                result.status = "passed"
                result.finished = self.clock.now() - self._t0
                self.emit("step_finished", status="passed",
                          duration_s=_round(result.duration_s),
                          planned_duration_s=_round(result.planned_duration_s),
                          **_jsonable(result.detail))
            except OperatorAbort as exc:
                status, code, message = "aborted", EXIT_OPERATOR_ABORT, str(exc)
                if self._halt_requested:
                    # A Halt asked for while nothing moved (a question, between steps): it
                    # is sent and reported like any Halt.
                    halted = self.emergency_halt()
                    self._show_state_after_halt()
                    message += (f"; {self._halt.reason}: Halt "
                                + ("sent" if halted else "could not be sent")
                                + self._halt_note())
                    cause = self._halt.cause
                    if cause != OPERATOR_HALT:
                        status, code = "failed", EXIT_FAULT
                    fault = {"cause": cause, "module": None, "message": message,
                             "step": step.number, **self._halt_fields()}
                    self.emit("fault", **fault)
                result.status = "aborted"
                result.finished = self.clock.now() - self._t0
                result.detail.update(self.tracking_figures())
                self.emit("operator_abort", message=message)
                break
            except Exception as exc:  # noqa: BLE001 - every failure, even a bug, halts
                self.emergency_halt()
                exc = self._operator_halt_seen(exc)
                cause, module = fault_cause(exc)
                if cause == "internal_error":
                    self.emit("internal_error", traceback=traceback.format_exc())
                    exc = RunAborted(cause, f"internal error ({type(exc).__name__}: {exc}); "
                                            "the arm was halted; the traceback is in the event log")
                if cause == OPERATOR_HALT:
                    status, code = "aborted", EXIT_OPERATOR_ABORT
                else:
                    status, code = "failed", EXIT_FAULT
                message = user_message(exc, self.arm) + self._halt_note()
                if self._halt_requested and self._halt.cause in FROM_OUTSIDE \
                        and cause != self._halt.cause:
                    # What the modules showed (HALTED) came from outside: name the source.
                    cause, message = self._halt.cause, f"{self._halt.reason}: {message}"
                fault = {"cause": cause, "module": module, "message": message,
                         "step": step.number, **self._halt_fields()}
                result.status = "failed" if code == EXIT_FAULT else "aborted"
                result.finished = self.clock.now() - self._t0
                result.detail.update(_jsonable(getattr(exc, "detail", None) or {}))
                result.detail.update(self.tracking_figures())   # up to the fault
                result.detail.setdefault("error", message)
                self.emit("fault", **fault)
                self._show_state_after_halt()
                break
            except BaseException as exc:
                # Anything else leaving a step (KeyboardInterrupt, SystemExit) still halts
                # the arm before it propagates.
                self.emergency_halt()
                fault = {"cause": "interrupted", "module": None, "message": repr(exc),
                         "step": step.number, **self._halt_fields()}
                self.emit("fault", **fault)
                result.status = "failed"
                result.finished = self.clock.now() - self._t0
                self._current_step = None
                self.driver.stop_watchdog_keeper()
                # The run folder is finished with this result before the exception goes on.
                self.interrupted_result = self._finish(
                    results, "failed", EXIT_FAULT, f"interrupted ({exc!r}); the arm was halted",
                    fault)
                raise
        self._current_step = None
        if code == EXIT_OK and self._halt_requested:
            # A Halt asked for after the last step: nothing moves, but it is sent as asked.
            self.emergency_halt()
            cause = self._halt.cause
            status, code = (("aborted", EXIT_OPERATOR_ABORT) if cause == OPERATOR_HALT
                            else ("failed", EXIT_FAULT))
            message = f"{self._halt.reason} after the last step; Halt sent" + self._halt_note()
            fault = {"cause": cause, "module": None, "message": message, "step": None,
                     **self._halt_fields()}
            self.emit("fault", **fault)
        if code in (EXIT_OK, EXIT_OPERATOR_ABORT) and not self._halt_requested:
            self._disable_watchdog()
        else:
            self.driver.stop_watchdog_keeper()
        return self._finish(results, status, code, message, fault)

    def _finish(self, results: list[StepResult], status: str, code: int, message: str,
                fault: dict | None, **extra: Any) -> RunResult:
        end = self.clock.now() - self._t0
        run = RunResult(status, code, message, results, 0.0, end, fault,
                        list(dict.fromkeys(self.not_verified)),
                        {k: round(v, 1) for k, v in self.min_heights_mm.items()})
        run.extra = extra
        run.latched_at_start = list(self.latched_at_start)
        self.emit("run_finished", status=status, exit_code=code, message=message,
                  duration_s=_round(run.duration_s),
                  planned_duration_s=_round(run.planned_duration_s), **extra)
        return run


def _label(step) -> str:
    return getattr(step, "title", None) or step.kind


def _location(step) -> str:
    loc = step.location
    return f"{loc.file}:{loc.line}:{loc.column}" if hasattr(loc, "file") else str(loc)


def _r(a, nd: int = 3) -> list[float]:
    # An array's floats via tolist(): iterating it would make a numpy scalar per element
    # (several times a cycle).
    return [round(float(x), nd) for x in (a.tolist() if isinstance(a, np.ndarray) else a)]


def _jsonable(d: dict) -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, np.ndarray):
            v = _r(v)
        elif isinstance(v, (np.floating,)):
            v = float(v)
        out[k] = v
    return out
