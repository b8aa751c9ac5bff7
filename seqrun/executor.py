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

The executor speaks joints in user degrees (planning, checks, events, what the driver
reports); everything about the arm's wire protocol (units and offsets, frames, retries,
state words, watchdog, Halt) is behind :class:`seqrun.drivers.base.ArmDriver`.

This module is the loop and the face a step sees (:class:`~seqrun.steps.context.StepContext`);
its parts are rooms of their own in :mod:`seqrun.execution`: the preflight
(``preflight``), the stream of a plan and the waits (``streaming``), the checks of every
reading (``checks``), the stop requests (``stops``), the Halt and how a run ends
(``ending``), the subscribers' fields (``telemetry``).
"""

from __future__ import annotations

import gc
import time
from functools import partial
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable, Iterable, Sequence, TypeVar

import numpy as np

from seqrun.arm import kinematics
from seqrun.arm.description import ArmDescription
from seqrun.arm.limits import LimitsInForce
from seqrun.arm.planner import Limits
from seqrun.arm.tracking import velocity_window
from seqrun.clock import Clock
from seqrun.arm.joint_values import JointState, LimitValues
from seqrun.drivers import ArmDriver, HaltConfirmation, as_driver
from seqrun.events import EventHub, make_event
from seqrun.errors import RunAborted
from seqrun.execution import ending
from seqrun.execution.blocks import BlockRun, recoverable
from seqrun.execution.checks import ReadingChecks
from seqrun.execution.flow import StepFlow, has_flow
from seqrun.execution.latched import LatchedFaults
from seqrun.execution.monitors import Monitors
from seqrun.execution.on_fail import pause_on_failure
from seqrun.execution.preflight import Findings, SequenceCheck, preflight, recheck
from seqrun.execution.run import Measurement, rounded
from seqrun.execution.stops import ResumeAsk, StopControl
from seqrun.execution.streaming import Streaming
from seqrun.execution.telemetry import SubscriberFields
from seqrun.results import (EXIT_FAULT, EXIT_INVALID, EXIT_OK,  # noqa: F401 (re-exported)
                            EXIT_OPERATOR_ABORT, OperatorAbort, RunResult, StepResult)
from seqrun.stop_requests import OPERATOR_HALT, StopRequests

if TYPE_CHECKING:
    from seqrun.arm.poses import PoseDirs
    from seqrun.arm.trajectory_tolerances import TrajectoryTolerances
    from seqrun.steps.context import AttendedQuestions
    from seqrun.arm.joint_values import GripperReading
    from seqrun.drivers.base import GripperDriver

#: What an operator's question answers (yes/no, a name).
_Answer = TypeVar("_Answer")

#: A synchronous recorder: gets every typed event (it reads like the events.jsonl dict).
Listener = Callable[[Any], None]


class Executor:
    """Runs resolved steps; see the module docstring for the safety rules.

    ``driver``: the arm's :class:`~seqrun.drivers.base.ArmDriver`; a PowerCube client is
    accepted too (wrapped in the PowerCube driver)."""

    #: Records the zero reference at a power_off step (set by whoever runs the sequence;
    #: None: a dry run or the built-in simulator, nothing is recorded).
    record_zero: Callable[[str], Any] | None = None
    #: The events between the arms of a campaign run (signal, wait_for; None: one arm).
    sync: Any = None
    #: This arm against the other arms of a campaign run, every reading
    #: (:class:`seqrun.service.arm_separation.ArmWatch`; None: one arm).
    separation: Any = None
    #: The planned path of each move as the preflight validated it from the measured
    #: start (step number -> (times s, joints rad)); None before the preflight.
    planned_paths: dict[int, Any] | None = None
    #: Who answers a signed confirm, a breakpoint and an on_fail: pause (never --yes;
    #: None: nobody attends).
    attended: AttendedQuestions | None = None
    #: The sha256 of the validated inputs, kept with a signature (None: not recorded).
    inputs_sha256: str | None = None

    def __init__(self, driver: ArmDriver | Any, arm: ArmDescription, clock: Clock, *,
                 sequence_check: SequenceCheck,
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
        #: The preflight's check of the sequence from the measured arm (the service gives
        #: seqrun.sequence.checks.check_from_arm): nothing moves when it finds an error.
        self.sequence_check = sequence_check
        self.arm = arm
        self.clock = clock
        self.poses_dir = poses_dir
        self.speed = speed
        self.command_mode = command_mode or arm.control.command_mode
        self.cycle = 1.0 / (cycle_hz or arm.control.cycle_hz)
        self.confirm = confirm
        self.before_step = before_step
        #: Faults the modules had latched before the run; a Reset clears one only when
        #: ``confirm_clear_latched`` says so (None: not asked, simulator and dry run).
        self.latched = LatchedFaults(arm, confirm_clear_latched, self.emit, self.ask_operator)
        #: Synchronous recorders (the run log): called with every typed event on the
        #: loop's thread; they must be fast and never block. Faces subscribe to ``events``.
        self.listeners: list[Listener] = list(listeners)
        #: Typed events for subscribers, each on its own queue (seqrun/events.py).
        self.events = events if events is not None else EventHub()
        self._fields = SubscriberFields(self)
        #: Called with the slack (seconds) before the loop sleeps until its next cycle: the
        #: live view renders there, on the loop's own thread, only when it has time.
        self.idle_hooks: list[Callable[[float], None]] = []
        self.dry_run = dry_run
        self.chain = kinematics.Chain.from_arm(arm)
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
        # by the run loop (seqrun/execution/stops.py).
        self.stops = StopControl(requests if requests is not None else StopRequests(),
                                 self.emit, self.beat)
        self.requests = self.stops.requests
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
        #: The plan's position at this cycle while a plan streams (None: none streams).
        self.setpoint_deg: np.ndarray | None = None
        #: The checks of every reading (guard heights and clearances kept for the report).
        self.checks = ReadingChecks(arm, self.chain, self.read_state_word)
        #: The running step's monitors, held against every reading.
        self.monitors = Monitors(arm, self.emit)
        self.not_verified: list[str] = []
        #: Lost answers the driver retried (``retry`` events): time spent on the bus.
        self.bus_retries = 0
        #: The step under way (its result is filled in as it runs).
        self.current_step: StepResult | None = None
        #: Joint solutions of end-effector targets as validated from the measured start
        #: (step number -> user degrees); the steps solve again and must land close.
        self.validated_targets: dict[int, np.ndarray] = {}
        #: The steps of class caution or hazardous as the preflight validated them (step
        #: number -> seqrun.sequence.hazard_classes.HazardFinding): their speed caps, and
        #: the signed confirm before a hazardous one.
        self.hazards: dict[int, Any] = {}
        #: Measured joints where the last move started (relative checkpoints).
        self.motion_start_deg: np.ndarray | None = None
        #: The moves and waits (seqrun/execution/streaming.py).
        self.streaming = Streaming(self)
        #: The emergency Halt of this run and what confirmed it (None: no Halt yet).
        self.halt_result: HaltConfirmation | None = None
        # The sequence under way (a Resume checks the rest of it again).
        self._loaded: Any = None
        #: The steps' if/skip_if, repeat and retry, and the branches the run took.
        self.flow = StepFlow(self, self.stops)
        #: How each block of the sequence ended (block/rescue/always; empty: none).
        self.block_outcomes: list[dict[str, Any]] = []

    # ------------------------------------------------------------------ control (any thread)
    def abort(self, reason: str = "operator abort") -> None:
        """First call: controlled stop. Second call: Halt. Takes no lock and calls no
        listener (safe in a signal handler); the run loop acts within a cycle."""
        self.stops.abort(reason)

    def halt(self, reason: str = "STOP", cause: str = OPERATOR_HALT) -> None:
        """Immediate Halt (second Ctrl-C, SIGTERM, STOP button); like :meth:`abort` safe
        in a signal handler. A ``cause`` other than operator_halt ends the run as a fault."""
        self.stops.halt(reason, cause)

    def pause(self) -> None:
        """Hold before the next step (the step under way finishes first)."""
        self.stops.pause()

    def resume(self) -> ResumeAsk:
        """Go on after a pause: the loop answers the returned ask (seqrun/execution/stops.py)."""
        return self.stops.resume()

    @property
    def abort_requested(self) -> bool:
        return self.stops.abort_requested

    def ask_operator(self, question: Callable[[Any], _Answer], arg: Any) -> _Answer:
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

    def describe_error(self, exc: BaseException) -> str:
        """``exc`` in the operator's words: a driver's error (a lost answer to a request)
        in user degrees and joint names, as the driver describes it."""
        return self.driver.describe_error(exc)

    # ------------------------------------------------------------------ events
    def emit(self, type_: str, **data: Any) -> None:
        """Make the typed record (seqrun/events.py) and hand it to the synchronous
        recorders (``listeners``: the run log, which must be on disk before the next
        instant) and to the hub's subscribers (each on its own queue: never waits)."""
        now = self.clock.now()
        if type_ == "retry":
            self.bus_retries += 1
        if self.current_step is not None and "step" not in data:
            data["step"] = self.current_step.number
        derived = self._fields.derive(type_, data) if self.events.subscribers else {}
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

    def idle_until(self, t: float) -> None:
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

    def idle(self, seconds: float) -> None:
        self.idle_until(self.clock.now() + seconds)

    def elapsed_s(self) -> float:
        """Seconds since the run started (the events' time base)."""
        return self.clock.now() - self._t0

    def since_start(self, t: float) -> float:
        """Clock time ``t`` as seconds since the run started (the events' time base)."""
        return t - self._t0

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
        self.emit("measurement", after=after, joints_deg=rounded(m.user_deg), state=short,
                  states={str(k): v.describe() for k, v in words.items()})

    # ------------------------------------------------------------------ the driver
    # Every call below reaches the bus: each one counts as a sign of life of the run loop
    # (the watchdog keeper feeds the modules only while the loop makes progress).
    def beat(self) -> None:
        """A sign of life of the run loop."""
        self._heartbeat = time.monotonic()

    def read_arm(self) -> Measurement:
        """Read position and state of every joint (lost reads retried by the driver)."""
        self.beat()
        return self.take_reading(self.driver.read())

    def take_reading(self, reading) -> Measurement:
        """A driver's reading as the run's latest measurement."""
        m = Measurement(self.clock.now(), reading.positions_deg, reading.states,
                        answered_at=getattr(reading, "answered_at", None),
                        holds_at_rad=getattr(reading, "holds_at_rad", None))
        self.last = m
        if self.monitors.active:
            setpoint = self.setpoint_deg if self.setpoint_deg is not None else self.commanded_deg
            self.monitors.observe(m, setpoint, self.elapsed_s())
        return m

    def read_state_word(self, module: int) -> JointState:
        """The full state of one module."""
        return self.driver.read_state(module)

    def read_state_words(self, modules: list[int] | None = None) -> dict[int, JointState]:
        """The full state of several modules (all: None)."""
        self.beat()
        return self.driver.read_states(modules)

    def reset_modules(self, modules: list[int] | None) -> None:
        """Reset (clear errors) of ``modules``; None: all of them at once."""
        self.beat()
        self.driver.reset(modules)

    def home_modules(self, modules: list[int] | None) -> None:
        """Home ``modules``; None: all of them at once."""
        self.beat()
        self.driver.home(modules)

    def halt_modules(self, modules: list[int] | None) -> None:
        """A deliberate Halt of ``modules`` (a ``halt`` step); None: all at once."""
        self.beat()
        self.driver.halt(modules)

    def write_limits(self, values: dict[str, LimitValues]) -> int:
        """Write MinPos/MaxPos (and MaxVel/MaxAcc where given) per joint and read them
        back; a value that reads back different is a fault. Returns the values written."""
        self.beat()
        return self.driver.write_limits(values)

    def wait_for_states(self, modules: list[int] | None, ok: Callable[[JointState], bool],
                        timeout_s: float, failure: str) -> dict[int, JointState]:
        """Poll the full state every cycle until ``ok`` holds for every module."""
        deadline = self.clock.now() + timeout_s
        while True:
            self.check_halt_request()
            states = self.read_state_words(modules)
            bad = {m: f for m, f in states.items() if not ok(f)}
            if not bad:
                return states
            if self.clock.now() >= deadline:
                module, flags = next(iter(bad.items()))
                raise self.module_fault(module, flags, failure)
            self.idle(self.cycle)

    # ------------------------------------------------------------------ checks
    def check_states(self, m: Measurement, *, require_homed: bool = True) -> None:
        """A module whose reading refuses motion and whose full state shows a fault (or,
        with ``require_homed``, no Home) is a fault (seqrun/execution/checks.py)."""
        self.checks.check_states(m.short_state, require_homed=require_homed)

    def check_guards(self, m: Measurement) -> None:
        """Workspace guards and link volumes at the measured joints, and against the other
        arms of a campaign run."""
        self.checks.check_guards(m.user_deg)
        if self.separation is not None:
            # (at when the joints answered: a reading handled late after a stall is not
            # taken for a fast arm)
            self.separation.check(m.at, m.user_deg, self.cycle, holds_at_rad=m.holds_at_rad)

    def module_fault(self, module: int, flags: JointState, context: str = ""):
        """A RunAborted naming the module, its joint and the decoded fault flags."""
        return self.checks.module_fault(module, flags, context)

    @property
    def min_heights_mm(self) -> dict[str, float]:
        return self.checks.min_heights_mm

    def monitor(self) -> Measurement:
        """One monitoring cycle without motion commands (waits, checkpoints). A module
        that is not homed yet is no fault here: nothing is commanded to move."""
        self.check_halt_request()
        m = self.read_arm()
        self.check_states(m, require_homed=False)
        self.check_guards(m)
        self.emit("measurement", joints_deg=rounded(m.user_deg), state=self.states_of(m))
        return m

    def states_of(self, m: Measurement) -> list[int]:
        """The cycle state of every joint's module, for the event log (compact ints)."""
        return [int(m.short_state.get(module, 0)) for module in self.modules]

    def check_halt_request(self) -> None:
        """A Halt taken, or a dry run past its time bound, ends the step."""
        self.stops.raise_for_halt()
        if self.time_limit_s is not None and self.elapsed_s() > self.time_limit_s:
            from seqrun.errors import RunAborted

            raise RunAborted("time_limit", f"stopped after {self.time_limit_s:g} s of simulated "
                             "time (control.max_dry_run_s of the arm file): the sequence takes "
                             "longer than a dry run may; raise the bound to check it all")

    # ------------------------------------------------------------------ motion
    def move(self, target_deg: np.ndarray, active: list[int], limits: Limits, *,
             tolerance_deg: float, timeout_s: float | None,
             start: Measurement | None = None) -> dict[str, Any]:
        """Plan from the measured state to ``target_deg`` and stream it; returns metrics.
        ``start``: the reading the caller has just taken to find the target (the arm is
        read once at the start of a move); None: read it now."""
        return self.streaming.move(target_deg, active, limits, tolerance_deg=tolerance_deg,
                                   timeout_s=timeout_s, start=start)

    def follow(self, plan, *, tolerance_deg: float, timeout_s: float | None,
               path_check: Callable[[Measurement], None] | None = None,
               command_mode: str | None = None,
               start: Measurement | None = None,
               tolerances: TrajectoryTolerances | None = None) -> dict[str, Any]:
        """Stream a precomputed plan (a :class:`~seqrun.arm.planner.SampledPlan`) that starts
        where the arm stands (``start``: the reading it was planned from; None: read it
        now); ``path_check`` runs on every cycle's measurement; ``command_mode`` overrides
        the run's setpoint law for this plan; ``tolerances``: a trajectory's path and
        goal tolerances (seqrun/arm/trajectory_tolerances.py)."""
        return self.streaming.follow(plan, tolerance_deg=tolerance_deg, timeout_s=timeout_s,
                                     path_check=path_check, command_mode=command_mode,
                                     start=start, tolerances=tolerances)

    def tracking_figures(self, target_deg=None) -> dict[str, Any]:
        """The current move's tracking figures (seqrun/arm/tracking.py) up to now."""
        return self.streaming.tracking_figures(target_deg)

    def wait(self, seconds: float) -> None:
        """Wait while monitoring every cycle (keeps faults and watchdog in view)."""
        self.streaming.wait(seconds)

    def wait_in_position(self, tolerance_deg: float, timeout_s: float) -> float:
        """Wait until every commanded joint is within tolerance; returns the time taken."""
        return self.streaming.wait_in_position(tolerance_deg, timeout_s)

    # ------------------------------------------------------------------ halt
    def emergency_halt(self) -> bool:
        """Halt every module before reading anything, then confirm it by reading every
        module's state back; once per run (seqrun/execution/ending.py). Returns whether the
        Halt was sent; the confirmation is in :attr:`halt_result`."""
        return ending.emergency_halt(self)

    # ------------------------------------------------------------------ preflight
    def preflight(self, loaded, first_step: int = 1) -> Findings:
        """Read the arm and check the sequence (from ``first_step``) from the measured
        state (seqrun/execution/preflight.py). Returns what :attr:`sequence_check` found."""
        return preflight(self, self.sequence_check, loaded, first_step)

    @property
    def latched_at_start(self) -> list[dict[str, Any]]:
        return self.latched.at_start

    def latched_message(self) -> str:
        return self.latched.message()

    def confirm_clearing_latched(self, modules: list[int] | None) -> None:
        """Before a Reset clears a fault latched before the run: the operator's word on
        real hardware (an operator abort without it)."""
        self.latched.confirm_clearing(modules)

    # ------------------------------------------------------------------ the gripper
    def _gripper_driver(self) -> GripperDriver:
        from seqrun.drivers.base import GripperDriver
        from seqrun.errors import RunAborted

        if not isinstance(self.driver, GripperDriver):
            raise RunAborted("no_gripper", f"the arm's driver ({self.arm.driver}) does not "
                             "drive a gripper")
        return self.driver

    def gripper_current_limit(self, current_a: float) -> float:
        return self._gripper_driver().gripper_current_limit(current_a)

    def joint_currents_a(self, joints: Sequence[int]) -> list[float | None]:
        """The actual current (A) of the joints numbered ``joints`` (1-based, as an
        expression's ``current_a[J]``), None for every other joint."""
        from seqrun.drivers.base import CurrentReader
        from seqrun.errors import RunAborted

        if not isinstance(self.driver, CurrentReader):
            raise RunAborted("no_current", f"the arm's driver ({self.arm.driver}) reads no "
                             "motor currents")
        modules = [self.arm.joints[j - 1].module for j in joints]
        read = self.driver.read_currents(modules)
        currents: list[float | None] = [None] * len(self.arm.joints)
        for j, module in zip(joints, modules):
            currents[j - 1] = read[module]
        return currents

    def gripper_move(self, width_mm: float, speed_mm_s: float) -> None:
        self.beat()
        self._gripper_driver().gripper_move(width_mm, speed_mm_s)

    def gripper_read(self) -> GripperReading:
        return self._gripper_driver().gripper_read()

    # ------------------------------------------------------------------ watchdog
    def loop_alive(self, within_s: float) -> bool:
        """True while the run loop made progress within ``within_s`` (real seconds) or
        waits for the operator's answer (a question comes only between steps)."""
        return (self.waiting_for_operator
                or time.monotonic() - self._heartbeat < within_s)

    # ------------------------------------------------------------------ run
    def run(self, loaded, *, first_step: int = 1) -> RunResult:
        """Preflight, then run the steps of ``loaded`` from ``first_step`` (1-based)."""
        from seqrun.steps.registry import HANDLERS

        if not self.clock.is_virtual:
            # The garbage that earlier work left in reference cycles (a report's figures,
            # a web request) is collected now, while nothing moves: left to the collector,
            # a full collection in the loop holds the interpreter as long as it scans
            # (a report.html's figures made cycles several periods long).
            gc.collect()
        self._t0 = self.clock.now()
        self.poses = dict(getattr(loaded, "poses", {}))
        monitors_at = getattr(loaded, "monitors_at", None)
        self.monitors.start_sequence(getattr(loaded, "monitors", ()),
                                     param_types=getattr(monitors_at, "param_types", None))
        self._loaded = loaded  # (a Resume validates the rest of it again)
        steps = list(loaded.steps)
        results = [StepResult.planned(s, _label(s), _location(s)) for s in steps]
        for step, planned in zip(steps, results):
            if step.blocks:   # where the step is written: "block 1 (Try) rescue", nested " > "
                planned.detail["block"] = " > ".join(f.name for f in step.blocks)
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
                return ending.finish(self, results, "invalid", EXIT_INVALID,
                                     f"{summary}: " + "; ".join(str(e) for e in check.errors),
                                     None, errors=[e.as_dict() for e in check.errors],
                                     summary=summary)
            self.beat()
            self.driver.enable_watchdog(self.loop_alive)
        except Exception as exc:  # noqa: BLE001 - nothing moves yet, but be sure
            return ending.finish(self, results, *ending.preflight_failed(self, exc))
        # blocks (block/rescue/always): None for a sequence without any
        blocks = BlockRun(self.emit, steps) if any(s.blocks for s in steps) else None
        recheck_due = False  # a recoverable failure: the path on is checked again first
        for index, (step, result) in enumerate(zip(steps, results)):
            if step.number < first_step:
                result.status = "skipped"
                continue
            if blocks is not None and not blocks.enter(step):
                if blocks.failure is not None:
                    break
                result.status = "skipped"
                result.detail["skipped_by"] = ("rescue" if step.blocks[-1].part == "rescue"
                                               else "block")
                continue
            self.current_step = result
            try:
                if recheck_due and blocks is not None:
                    recheck_due = False
                    self._recheck(loaded, [step, *blocks.path(steps[index + 1:])], step)
                if has_flow(step.params):
                    flowed = self.flow.run(step, result, self._begin_step,
                                           partial(self._handle, HANDLERS[step.kind], step))
                    if flowed is not None:
                        self._step_passed(result, flowed)
                else:
                    self._begin_step(step, result)
                    self._step_passed(result, self._handle(HANDLERS[step.kind], step))
            except OperatorAbort as exc:
                status, code, message, fault = ending.step_aborted(self, step, result, exc)
                break
            except Exception as exc:  # noqa: BLE001 - every failure, even a bug, halts
                if (blocks is not None and step.blocks and isinstance(exc, RunAborted)
                        and recoverable(exc, self.stops)):
                    # a block's step: its rescue, its always, then the block's verdict
                    self._block_step_failed(result, exc)
                    blocks.fail(step, result, exc)
                    recheck_due = True
                    continue
                status, code, message, fault = ending.step_failed(self, step, result, exc)
                break
            except BaseException as exc:
                # Anything else leaving a step (KeyboardInterrupt, SystemExit) still halts
                # the arm before it propagates.
                ending.step_interrupted(self, step, result, results, exc)
                raise
        self.current_step = None
        untaken = self.flow.not_taken()
        if blocks is not None:
            if code == EXIT_OK:
                blocks.finish()
            if code == EXIT_OK and blocks.failure is not None:
                # no block rescued it: the run ends as that step would without a block
                failed = blocks.failure
                status, code, message, fault = ending.step_failed(self, failed.step,
                                                                  failed.result, failed.error)
            untaken += blocks.not_taken()
            self.block_outcomes = blocks.outcomes
        if self.dry_run:
            # the branches this one path did not take: validation has not seen them run
            self.not_verified.extend(b.line for b in untaken)
        if code == EXIT_OK and self.stops.halt_request is not None:
            status, code, message, fault = ending.halt_after_last_step(self)
        if code in (EXIT_OK, EXIT_OPERATOR_ABORT) and self.stops.halt_request is None:
            # After a clean end the arm keeps holding: the watchdogs are disarmed again.
            self.beat()
            self.driver.disable_watchdog()
        else:
            self.driver.stop_watchdog_keeper()
        ended = ending.finish(self, results, status, code, message, fault,
                              **({"blocks": self.block_outcomes} if self.block_outcomes
                                 else {}))
        ended.branches_not_taken = untaken
        return ended

    def _ask_before(self, step) -> None:
        """The step's questions and stop requests before it starts."""
        # A request that came before the question is acted on without asking.
        self.check_halt_request()
        if self.stops.aborts:
            raise OperatorAbort("operator abort")
        if not self.dry_run and self.stops.begin_hold():
            self._hold_paused(step)
        if self.before_step is not None and not self.ask_operator(self.before_step, step):
            raise OperatorAbort("operator declined the step")
        if getattr(step.params, "breakpoint", False):
            self._breakpoint(step)
        hazard = self.hazards.get(step.number)
        if hazard is not None:
            self._hazard_class(step, hazard)
        self.check_halt_request()
        if self.stops.aborts:
            raise OperatorAbort("operator abort")

    def _hold_paused(self, step) -> None:
        """Paused: hold before ``step``, the arm at rest and read every cycle (nothing is
        commanded), until a Resume whose check of the rest of the sequence from the measured
        pose passes (the preflight's check, as ``--from N``), an abort or a Halt."""
        self.emit("run_paused", step=step.number, label=_label(step), location=_location(step))
        stops = self.stops
        ended: str | None = "the run was stopped while paused"  # (None: resumed)
        since, refusals = self.elapsed_s(), 0
        try:
            while True:
                self.check_halt_request()
                if stops.aborts:
                    raise OperatorAbort(f"operator abort while paused before step {step.number}")
                ask = stops.next_resume()
                if ask is not None:
                    check = self.preflight(self._loaded, step.number)
                    if not check.errors:
                        ended = None
                        ask.answer(None)
                        break
                    reason = ("not valid from the arm's measured pose: "
                              + "; ".join(str(e) for e in check.errors))
                    self.emit("resume_refused", step=step.number, reason=reason)
                    refusals += 1
                    ask.answer(reason)
                    continue
                self.monitor()
                self.idle(self.cycle)
        finally:
            stops.end_hold(ended)
            if self.current_step is not None:  # (kept with the step in report.json)
                self.current_step.detail["paused_s"] = round(self.elapsed_s() - since, 3)
                if refusals:
                    self.current_step.detail["resumes_refused"] = refusals
        self.emit("run_resumed", step=step.number)

    def _breakpoint(self, step) -> None:
        """Between steps, the arm at rest: go on only when a person says so (the dry run
        passes through, and says so)."""
        title = f"step {step.number}: {_label(step)}"
        if self.dry_run:
            self.not_verified.append(f"step {step.number}: breakpoint before '{_label(step)}' "
                                     "(assumed continue)")
            return
        self.emit("breakpoint_reached", step=step.number, label=_label(step))
        attended = self.attended
        go_on = attended is not None and self.ask_operator(
            attended.breakpoint, f"Breakpoint before {title}. Continue?")
        self.emit("breakpoint_answered", step=step.number, go_on=go_on)
        if not go_on:
            raise OperatorAbort(f"operator stopped at the breakpoint before {title}"
                                if attended is not None else
                                f"breakpoint before {title}: nobody to ask")

    def pause_on_failure(self, step, result: StepResult, exc: RunAborted) -> str:
        """``on_fail: pause`` after a failure that may be retried: the operator's Retry or
        Skip (seqrun/execution/on_fail.py); an Abort raises OperatorAbort."""
        return pause_on_failure(self, self._loaded, step, result, exc,
                                f"step {step.number}: {_label(step)}")

    def _hazard_class(self, step, hazard) -> None:
        """A step of class caution or hazardous: its class in its detail (report.json,
        report.html); a hazardous one starts only after a signed confirm (the person at
        the run, never --yes; the dry run assumes it and says so)."""
        from seqrun.steps.confirm import ask_signature

        detail = self.current_step.detail if self.current_step is not None else {}
        detail.update({"hazard": hazard.hazard, "hazard_reason": hazard.reason,
                       "hazard_speed_scale": hazard.speed_scale})
        if not hazard.needs_signature:
            return
        prompt = (f"Step {step.number} ({_label(step)}) is hazardous: {hazard.reason}. "
                  "Go on?")
        signed = ask_signature(self, step.number, prompt, hazard.role)
        detail.update({k: v for k, v in signed.items() if k != "confirmed"})

    def _begin_step(self, step, result: StepResult, *, iteration: int | None = None,
                    bound: dict[str, int] | None = None, attempt: int | None = None) -> None:
        """The step's questions and event (its first start; an iteration of a repeat, a
        retry's attempt after that) and its monitors."""
        if iteration is not None and iteration > 1:
            self.check_halt_request()
            if self.stops.aborts:
                raise OperatorAbort("operator abort")
            self.emit("step_iteration", iteration=iteration, **(bound or {}))
        elif attempt is None:
            self._ask_before(step)
            result.started = self.elapsed_s()
            counted = {} if iteration is None else {"iteration": iteration, **(bound or {})}
            self.emit("step_started", kind=step.kind, label=result.label,
                      location=result.location,
                      **({"include": list(step.include_labels)}
                         if getattr(step, "include_labels", ()) else {}), **counted)
        self.streaming.tracking = None
        self.monitors.start_step(getattr(step.params, "monitors", ()), self.clock.now(),
                                 param_types=getattr(step, "param_types", None),
                                 param_values=getattr(step, "param_values", None))

    def _handle(self, handler: Callable[[Any, Any], dict | None], step) -> dict:
        """The kind's handler on ``step``; its monitors end with it."""
        try:
            return handler(step, self) or {}
        finally:
            self.monitors.stop()  # (the fault path reads the arm unwatched)
            self.setpoint_deg = None

    def _block_step_failed(self, result: StepResult, exc: RunAborted) -> None:
        """A step of a block failed in a way a rescue may follow: nothing is halted, the
        step is reported failed (the block says whether it was rescued)."""
        self.monitors.stop()
        result.status = "failed"
        result.finished = self.elapsed_s()
        result.detail.update(ending.jsonable(exc.detail or {}))
        result.detail["error"] = self.describe_error(exc)

    def _recheck(self, loaded, path: list, step) -> None:
        """After a recoverable failure, before the next step: the steps the run goes on
        with, checked from where the arm stands (the preflight's check); a refusal ends
        the run before anything moves."""
        found = recheck(self, self.sequence_check, replace(loaded, steps=tuple(path)))
        self.emit("block_recheck", first_step=step.number, steps=len(path),
                  errors=[str(e) for e in found.errors])
        if found.errors:
            raise RunAborted("block_recheck", "the steps after the failure are not valid "
                             "from where the arm stands: "
                             + "; ".join(str(e) for e in found.errors))

    def _step_passed(self, result: StepResult, detail: dict) -> None:
        result.detail.update({k: v for k, v in detail.items() if k != "planned_duration_s"})
        if "planned_duration_s" in detail:
            result.planned_duration_s = detail["planned_duration_s"]
        result.status = "passed"
        result.finished = self.elapsed_s()
        self.emit("step_finished", status="passed", duration_s=ending.round4(result.duration_s),
                  planned_duration_s=ending.round4(result.planned_duration_s),
                  **ending.jsonable(result.detail))


def _label(step) -> str:
    return getattr(step, "title", None) or step.kind


def _location(step) -> str:
    loc = step.location
    return f"{loc.file}:{loc.line}:{loc.column}" if hasattr(loc, "file") else str(loc)
