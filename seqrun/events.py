"""Typed event records and the hub that hands them to subscribers on their own queues.

Every event the executor or the arm session emits is one frozen dataclass here, a subclass of
:class:`Event`. ``Event.type`` (a class variable) is the event's name as it appears in
``events.jsonl`` (``"measurement"``, ``"step_started"``, ...); :meth:`Event.as_dict` gives that
line's dict, exactly the shape the run log and the report readers have always read.
``docs/events.md`` is generated from these classes (``python -m seqrun.events``), and a test
checks that every event type the code emits is one of them.

Fields an event has but ``events.jsonl`` does not carry (derived for the faces: a measurement's
velocities and flag names, the clock reading) are marked ``derived`` and left out of
:meth:`Event.as_dict`, so the run folder stays as it was.

Delivery (:class:`EventHub`): the control loop publishes, and publishing never waits for a
subscriber. Each subscriber has its own bounded queue; when it is full the *oldest* events are
dropped and counted (:attr:`Subscription.dropped`). A slow display, a dead browser tab or a
stuck bridge therefore cannot delay a control cycle. The one exception is the synchronous
*recorder* (the run log, and probes in tests): it is called on the loop's thread, because
the run folder must be complete on disk even when the process is killed the next instant; a
queue would lose its tail. Recorders must be fast and never block (the run log writes one
line per event and stops writing on the first disk error).
"""

from __future__ import annotations

import dataclasses
import json
import threading
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

#: The one encoder of every events.jsonl line (and of the bag's copy of it): compact,
#: anything JSON does not know as its str(). Made once: json.dumps with options builds a
#: new encoder per call, a cost per event of the control loop.
_LINE_ENCODER = json.JSONEncoder(separators=(",", ":"), default=str)


def event_line(event: Mapping[str, Any]) -> str:
    """An event's dict as its events.jsonl line (without the newline)."""
    return _LINE_ENCODER.encode(event)


#: Field metadata: not written to events.jsonl (derived for the faces).
DERIVED = {"derived": True}
#: Field metadata: left out of the dict when None (the key was absent in the old dicts).
OPTIONAL = {"optional": True}


def _derived(default: Any = None) -> Any:
    return field(default=default, metadata=DERIVED)


def _optional(default: Any = None) -> Any:
    return field(default=default, metadata=OPTIONAL)


@dataclass(frozen=True, kw_only=True)
class Event:
    """Base of every event. ``t``: seconds since the start of the run or activity that emits
    it (idle status: since the session opened); ``step``: the step number while a step runs.
    ``extra`` holds keyword fields a type does not declare (a step's result details)."""

    type: ClassVar[str] = "event"
    #: One line: when the event is emitted (docs/events.md).
    when: ClassVar[str] = ""

    t: float
    step: int | None = _optional()
    extra: Mapping[str, Any] = field(default_factory=dict)
    #: The clock's reading when the event was made (seconds; virtual time in a dry run).
    clock_s: float | None = _derived()

    def as_dict(self) -> dict[str, Any]:
        """The event as an ``events.jsonl`` line (today's dict shape)."""
        out: dict[str, Any] = {"t": self.t, "type": self.type}
        step_present = False
        for f in dataclasses.fields(self):
            if f.name in ("t", "extra") or f.metadata.get("derived"):
                continue
            value = getattr(self, f.name)
            if f.metadata.get("optional") and value is None:
                continue
            if f.name == "step":
                step_present = True
                continue
            out[f.name] = value
        out.update(self.extra)
        if step_present:
            out["step"] = self.step
        return out

    # Read-only mapping access to the events.jsonl view: recorders and tests that read
    # ``event["type"]`` or ``event.get("step")`` keep working on typed events.
    def __getitem__(self, key: str) -> Any:
        if key == "type":
            return self.type
        if key in self.extra:
            return self.extra[key]
        names = _plain_fields(type(self))
        if key in names:
            value = getattr(self, key)
            if value is None and key in _optional_fields(type(self)):
                raise KeyError(key)
            return value
        raise KeyError(key)

    def get(self, key: str, default: Any = None) -> Any:
        try:
            return self[key]
        except KeyError:
            return default

    def __contains__(self, key: object) -> bool:
        try:
            self[key]  # type: ignore[index]
            return True
        except KeyError:
            return False


_FIELDS_CACHE: dict[type, tuple[frozenset[str], frozenset[str]]] = {}


def _field_sets(cls: type) -> tuple[frozenset[str], frozenset[str]]:
    cached = _FIELDS_CACHE.get(cls)
    if cached is None:
        fields = [f for f in dataclasses.fields(cls) if not f.metadata.get("derived")
                  and f.name != "extra"]
        cached = (frozenset(f.name for f in fields),
                  frozenset(f.name for f in fields if f.metadata.get("optional")))
        _FIELDS_CACHE[cls] = cached
    return cached


def _plain_fields(cls: type) -> frozenset[str]:
    return _field_sets(cls)[0]


def _optional_fields(cls: type) -> frozenset[str]:
    return _field_sets(cls)[1]


# ====================================================================== run lifecycle
@dataclass(frozen=True, kw_only=True)
class RunStarted(Event):
    type: ClassVar[str] = "run_started"
    when: ClassVar[str] = "first event of a run, before the preflight reads the arm"
    steps: int
    first_step: int = 1
    speed: float = 1.0
    command_mode: str = "ramp"
    dry_run: bool = False
    #: The run clock's reading at t = 0 (puts events and trace frames on one time base).
    clock_s: float | None = None
    virtual_time: bool = False
    cycle_s: float = 0.01
    velocity_window_s: float = 0.1
    #: The arm description as in the arm file.
    arm: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class Preflight(Event):
    type: ClassVar[str] = "preflight"
    when: ClassVar[str] = ("after the preflight read the arm and re-validated the sequence "
                           "from the measured state (before the first motion)")
    start_deg: Sequence[float]
    homed: bool
    limits_written: bool
    module_limits: Mapping[str, Sequence[float]] = field(default_factory=dict)
    states: Mapping[str, str] = field(default_factory=dict)
    errors: Sequence[str] = ()
    notes: Sequence[str] = ()


@dataclass(frozen=True, kw_only=True)
class StepStarted(Event):
    type: ClassVar[str] = "step_started"
    when: ClassVar[str] = "a step begins (after its before-step question, if any)"
    kind: str
    label: str
    location: str
    #: Labels of the include files the step came through.
    include: Sequence[str] | None = _optional()
    #: A repeated step: this is its first iteration of ``iterations`` (repeat's count)
    #: or of at most ``max_iterations`` (repeat's max, with while).
    iteration: int | None = _optional()
    iterations: int | None = _optional()
    max_iterations: int | None = _optional()


@dataclass(frozen=True, kw_only=True)
class StepIteration(Event):
    type: ClassVar[str] = "step_iteration"
    when: ClassVar[str] = ("a repeated step begins its next iteration (``repeat``: the "
                           "first is its step_started); ``iterations``: repeat's count, "
                           "``max_iterations``: its max with while")
    iteration: int
    iterations: int | None = _optional()
    max_iterations: int | None = _optional()


@dataclass(frozen=True, kw_only=True)
class StepSkipped(Event):
    type: ClassVar[str] = "step_skipped"
    when: ClassVar[str] = ("a step did not run: its ``if`` was false, its ``skip_if`` true, "
                           "or its ``repeat``'s while false at the start (no step_started "
                           "or step_finished follows)")
    kind: str
    label: str
    location: str
    key: str
    condition: str
    value: bool
    values: Mapping[str, Any]


@dataclass(frozen=True, kw_only=True)
class StepRetry(Event):
    type: ClassVar[str] = "step_retry"
    when: ClassVar[str] = ("a step with ``retry`` failed in a way that may be retried and "
                           "runs again after ``delay_s``")
    attempt: int
    times: int
    cause: str
    message: str
    delay_s: float


@dataclass(frozen=True, kw_only=True)
class OperatorChoice(Event):
    type: ClassVar[str] = "operator_choice"
    when: ClassVar[str] = ("a step with ``on_fail: pause`` failed in a way that may be "
                           "retried (its own retries spent) and the operator chose, the arm "
                           "at rest: ``choice`` retry (the step runs again), skip (the step "
                           "stays failed, the run goes on once the rest is checked from the "
                           "measured arm) or abort (an operator abort); ``by`` says who "
                           "answered where (terminal, console), ``cause`` and ``message`` "
                           "the failure")
    choice: str
    by: str
    cause: str
    message: str


@dataclass(frozen=True, kw_only=True)
class SkipRecheck(Event):
    type: ClassVar[str] = "skip_recheck"
    when: ClassVar[str] = ("the operator skipped a failed step (``on_fail: pause``): the "
                           "``steps`` steps after it checked from the measured arm as the "
                           "preflight does; any ``errors`` end the run before anything moves")
    first_step: int
    steps: int
    errors: Sequence[str]


@dataclass(frozen=True, kw_only=True)
class StepFinished(Event):
    type: ClassVar[str] = "step_finished"
    when: ClassVar[str] = ("a step passed; ``extra`` carries its result details (a move's "
                           "tracking figures, a checkpoint's errors)")
    status: str
    duration_s: float | None = None
    planned_duration_s: float | None = None


@dataclass(frozen=True, kw_only=True)
class BlockStepFailed(Event):
    type: ClassVar[str] = "block_step_failed"
    when: ClassVar[str] = ("a step written in a block failed in a way a rescue may follow "
                           "(a check, a wait_until timing out, a checkpoint or check_gripper "
                           "out of tolerance): nothing is halted; ``part``: the block's list "
                           "it is in (steps, rescue, always); ``rescue``: the block's rescue "
                           "runs next")
    block: int
    part: str
    location: str
    cause: str
    message: str
    rescue: bool


@dataclass(frozen=True, kw_only=True)
class BlockRecheck(Event):
    type: ClassVar[str] = "block_recheck"
    when: ClassVar[str] = ("after a block's step failed, before the next step: the "
                           "``steps`` steps the run goes on with (the rescue, the always, "
                           "what follows) checked from the measured arm as the preflight "
                           "does; any ``errors`` end the run before anything moves")
    first_step: int
    steps: int
    errors: Sequence[str]


@dataclass(frozen=True, kw_only=True)
class BlockFinished(Event):
    type: ClassVar[str] = "block_finished"
    when: ClassVar[str] = ("the run left a block: ``status`` passed, rescued (a step "
                           "failed and the rescue passed), failed (the failure goes on to "
                           "the block around it, else ends the run) or not run")
    block: int
    label: str
    location: str
    status: str
    failed_step: int | None = None


@dataclass(frozen=True, kw_only=True)
class RunFinished(Event):
    type: ClassVar[str] = "run_finished"
    when: ClassVar[str] = ("last event of a run, whatever ended it; ``extra`` may carry "
                           "``errors`` and ``summary`` (a run not valid from the measured "
                           "state) and ``blocks`` (how each block ended)")
    status: str
    exit_code: int
    message: str
    duration_s: float | None = None
    planned_duration_s: float | None = None


@dataclass(frozen=True, kw_only=True)
class ZeroReference(Event):
    type: ClassVar[str] = "zero_reference"
    when: ClassVar[str] = "before the run starts: the zero reference (power-off pose) in force"
    pose: str | None = None
    text: str = ""
    source: str = ""
    after_power_on: bool = False
    record: Mapping[str, Any] | None = None


@dataclass(frozen=True, kw_only=True)
class ZeroRecorded(Event):
    type: ClassVar[str] = "zero_recorded"
    when: ClassVar[str] = "a power_off step recorded the pose the arm is powered off in"
    pose: str
    text: str


# ====================================================================== motion and telemetry
@dataclass(frozen=True, kw_only=True)
class MovePlanned(Event):
    type: ClassVar[str] = "move_planned"
    when: ClassVar[str] = "a move (joint, end-effector or straight-line) was planned"
    duration_s: float | None
    start_deg: Sequence[float]
    target_deg: Sequence[float]
    #: Names of the joints that move.
    joints: Sequence[str]
    velocity_limit_deg_s: Sequence[float] | None = _optional()
    #: True for a precomputed (sampled) plan, e.g. a straight line.
    sampled: bool | None = _optional()


@dataclass(frozen=True, kw_only=True)
class Setpoint(Event):
    type: ClassVar[str] = "setpoint"
    when: ClassVar[str] = ("every control cycle of a move: what was commanded and what was "
                           "measured (one per cycle, 100 Hz on the arm)")
    plan_t: float
    planned_deg: Sequence[float]
    measured_deg: Sequence[float]
    planned_vel_deg_s: Sequence[float]
    #: Short state byte of every joint's module.
    state: Sequence[int]
    #: When the joints answered (s since the run start, from the bus's own time stamps):
    #: the time of ``measured_deg`` (one per joint when they answered over 2 ms apart);
    #: ``t`` is when the loop logged it, later after a host stall.
    read_t: float | Sequence[float] | None = _optional()


@dataclass(frozen=True, kw_only=True)
class Measurement(Event):
    """A reading of the whole arm. In events.jsonl: ``joints_deg``, ``state`` and, after
    home/reset/halt, ``after`` and ``states``. Subscribers also get one per streamed cycle
    of a move (``source="cycle"``, not written to the log: the ``setpoint`` event holds it),
    the preflight's reading (``source="preflight"``, likewise) and the session's idle polls
    (``source="poll"``)."""

    type: ClassVar[str] = "measurement"
    when: ClassVar[str] = ("every monitoring cycle (waits, checkpoints, pause), after home/"
                           "reset/halt steps and a fault's Halt; subscribers also get one per "
                           "cycle of a move and the session's idle status polls")
    #: Every joint, user degrees.
    joints_deg: Sequence[float]
    #: Short state byte of every joint's module.
    state: Sequence[int]
    #: What the reading follows (home, reset, halt).
    after: str | None = _optional()
    #: State words by module id (names), where read.
    states: Mapping[str, str] | None = _optional()
    #: Joint velocities, deg/s (windowed estimate or the modules' ActVel), when known.
    velocities_deg_s: Sequence[float] | None = _derived()
    #: State flag names per joint (joint name -> names), from the state word or short state.
    flags: Mapping[str, Sequence[str]] | None = _derived()
    #: Any joint's module reports a fault (ERROR, HALTED, TOW_ERROR, ...).
    fault: bool = _derived(False)
    #: Where the reading came from: "monitor", "cycle", "preflight", "poll", "step".
    source: str = _derived("monitor")
    #: The clock's reading when the modules answered (the driver's reading time, earlier
    #: than ``clock_s`` by the exchange and what came after it), where known.
    read_clock_s: float | None = _derived()


@dataclass(frozen=True, kw_only=True)
class MeasurementFailed(Event):
    type: ClassVar[str] = "measurement_failed"
    when: ClassVar[str] = ("the state reading after home/reset/halt failed (the Halt path "
                           "reports a module that does not answer)")
    after: str
    error: str


@dataclass(frozen=True, kw_only=True)
class Checkpoint(Event):
    type: ClassVar[str] = "checkpoint"
    when: ClassVar[str] = ("a checkpoint step measured the end-effector; ``extra`` holds "
                           "expected/reached position and rpy, the errors and tolerances")


@dataclass(frozen=True, kw_only=True)
class Check(Event):
    type: ClassVar[str] = "check"
    when: ClassVar[str] = ("a check step evaluated its condition; ``extra`` holds the values "
                           "it read and the requirements it verifies")
    condition: str
    passed: bool


@dataclass(frozen=True, kw_only=True)
class WaitTimedOut(Event):
    type: ClassVar[str] = "wait_timed_out"
    when: ClassVar[str] = ("a wait_until's condition did not hold within its timeout_s "
                           "(on_timeout: fail ends the run, continue goes on)")
    condition: str
    timeout_s: float
    on_timeout: str


@dataclass(frozen=True, kw_only=True)
class MonitorTripped(Event):
    type: ClassVar[str] = "monitor_tripped"
    when: ClassVar[str] = ("a step's or the sequence's monitor did not hold for "
                           "persist_cycles readings in a row (action halt: the fault follows; "
                           "stop: a controlled stop, then the fault; warn: once until it "
                           "holds again)")
    condition: str
    action: str
    cycles: int
    values: Mapping[str, Any]
    message: str | None = _optional()
    #: "sequence" for a monitor of the whole sequence (its top-level ``monitors:``).
    scope: str | None = _optional()


@dataclass(frozen=True, kw_only=True)
class IkSolved(Event):
    type: ClassVar[str] = "ik_solved"
    when: ClassVar[str] = "an end-effector target (move_tool, move_linear) was solved from the measured joints"
    joints_deg: Sequence[float]
    samples: int | None = _optional()
    length_mm: float | None = _optional()


@dataclass(frozen=True, kw_only=True)
class Retry(Event):
    type: ClassVar[str] = "retry"
    when: ClassVar[str] = "a lost acknowledge of a read was retried (reads only)"
    what: str
    module: int | None = _optional()
    modules: Sequence[int] | None = _optional()


@dataclass(frozen=True, kw_only=True)
class HostStall(Event):
    type: ClassVar[str] = "host_stall"
    when: ClassVar[str] = ("the control loop was not run for more than two cycles (this "
                           "computer did not schedule it): the plan resumes where the arm "
                           "went meanwhile instead of running ahead of it")
    seconds: float
    held_s: float
    plan_t: float


@dataclass(frozen=True, kw_only=True)
class FrameDiscarded(Event):
    type: ClassVar[str] = "frame_discarded"
    when: ClassVar[str] = "a received frame was not used as an answer (stale, foreign, malformed)"
    can_id: str
    data: str
    reason: str


@dataclass(frozen=True, kw_only=True)
class WatchdogEnabled(Event):
    type: ClassVar[str] = "watchdog_enabled"
    when: ClassVar[str] = "the modules' watchdogs were armed (after the preflight)"
    refresh_period_s: float


@dataclass(frozen=True, kw_only=True)
class WatchdogDisabled(Event):
    type: ClassVar[str] = "watchdog_disabled"
    when: ClassVar[str] = "after a clean end (or operator abort): the watchdogs were disarmed"


@dataclass(frozen=True, kw_only=True)
class WatchdogDisableFailed(Event):
    type: ClassVar[str] = "watchdog_disable_failed"
    when: ClassVar[str] = "disarming the watchdogs failed (the modules will stop on their own)"
    error: str


@dataclass(frozen=True, kw_only=True)
class VelocityZeroFailed(Event):
    type: ClassVar[str] = "velocity_zero_failed"
    when: ClassVar[str] = ("FVEL 0 at the end of a velocity motion got no answer (a failing "
                           "motion: the Halt follows; the watchdog stays armed)")
    error: str


@dataclass(frozen=True, kw_only=True)
class VelocityMovePlanned(Event):
    type: ClassVar[str] = "velocity_move_planned"
    when: ClassVar[str] = ("a move_velocity step starts: its planned duration, each joint's "
                           "velocity and the envelope every cycle is checked against")
    duration_s: float
    velocity_deg_s: dict[str, float]
    envelope_deg: dict[str, list[float]]


@dataclass(frozen=True, kw_only=True)
class GripperCommand(Event):
    type: ClassVar[str] = "gripper_command"
    when: ClassVar[str] = ("a grip or release starts: the jaws' target width and speed (a grip "
                           "closes fully: the part stops the jaws), its force as current limit")
    command: str
    target_mm: float
    speed_mm_s: float
    force_n: float | None = None
    current_a: float | None = None


# ====================================================================== operator control
@dataclass(frozen=True, kw_only=True)
class AbortRequested(Event):
    type: ClassVar[str] = "abort_requested"
    when: ClassVar[str] = "the loop took an abort request (first: controlled stop; second: Halt)"
    reason: str
    count: int


@dataclass(frozen=True, kw_only=True)
class HaltRequested(Event):
    type: ClassVar[str] = "halt_requested"
    when: ClassVar[str] = "the loop took a Halt request (STOP, second Ctrl-C, SIGTERM, ...)"
    reason: str
    cause: str


@dataclass(frozen=True, kw_only=True)
class PauseRequested(Event):
    type: ClassVar[str] = "pause_requested"
    when: ClassVar[str] = ("Pause was asked for (any thread): the step under way finishes, then "
                           "the run holds before the next one")


@dataclass(frozen=True, kw_only=True)
class RunPaused(Event):
    type: ClassVar[str] = "run_paused"
    when: ClassVar[str] = ("the run holds before ``step`` (the arm at rest, read every cycle, "
                           "nothing commanded) until Resume, abort or STOP")
    label: str
    location: str


@dataclass(frozen=True, kw_only=True)
class ResumeRefused(Event):
    type: ClassVar[str] = "resume_refused"
    when: ClassVar[str] = ("Resume was asked for, but the rest of the sequence (from ``step``) "
                           "is not valid from the arm's measured pose: the run stays paused")
    reason: str


@dataclass(frozen=True, kw_only=True)
class RunResumed(Event):
    type: ClassVar[str] = "run_resumed"
    when: ClassVar[str] = ("the rest of the sequence was validated again from the arm's "
                           "measured pose and the run goes on with ``step``")


@dataclass(frozen=True, kw_only=True)
class ControlledStop(Event):
    type: ClassVar[str] = "controlled_stop"
    when: ClassVar[str] = "a controlled stop (ruckig to zero velocity) starts: abort, jog release"
    duration_s: float | None


@dataclass(frozen=True, kw_only=True)
class Holding(Event):
    type: ClassVar[str] = "holding"
    when: ClassVar[str] = "after a controlled stop: the arm holds where it stopped"
    joints_deg: Sequence[float] | None


@dataclass(frozen=True, kw_only=True)
class OperatorAbortEvent(Event):
    type: ClassVar[str] = "operator_abort"
    when: ClassVar[str] = "the run ended by the operator (abort, a declined question)"
    message: str


@dataclass(frozen=True, kw_only=True)
class ConfirmRequested(Event):
    type: ClassVar[str] = "confirm_requested"
    when: ClassVar[str] = ("a session run asks the operator (a confirm step, a before-step "
                           "question, clearing a latched fault, a signed confirm, a "
                           "breakpoint, a step's on_fail: pause); answer with "
                           "ArmSession.answer(question_id, yes, name, choice) (name: a signed "
                           "question's yes; choice: one of ``choices``)")
    question_id: str
    text: str
    #: Who started the activity that asks (a face's client name; None: not said).
    started_by: str | None = _optional()
    #: A signed question: a yes needs the name of who answers (and ``role``: as what).
    sign: bool | None = _optional()
    role: str | None = _optional()
    #: A question with choices (a step's ``on_fail: pause``: retry, skip, abort): a yes
    #: names one of them (``ArmSession.answer(question_id, True, choice=...)``).
    choices: Sequence[str] | None = _optional()


@dataclass(frozen=True, kw_only=True)
class ConfirmAnswered(Event):
    type: ClassVar[str] = "confirm_answered"
    when: ClassVar[str] = "a question was answered (or withdrawn: the run stopped meanwhile)"
    question_id: str
    yes: bool
    #: Who answered a signed question yes.
    name: str | None = _optional()
    #: What a yes to a question with choices chose.
    choice: str | None = _optional()


@dataclass(frozen=True, kw_only=True)
class ConfirmSigned(Event):
    type: ClassVar[str] = "confirm_signed"
    when: ClassVar[str] = ("a signed confirm was answered yes: who (``signed_by``), as what "
                           "(``signed_role``), when (UTC) and the sha256 of the validated "
                           "inputs they signed")
    text: str
    signed_by: str
    signed_role: str | None = _optional()
    signed_at_utc: str
    inputs_sha256: str | None = _optional()


@dataclass(frozen=True, kw_only=True)
class BreakpointReached(Event):
    type: ClassVar[str] = "breakpoint_reached"
    when: ClassVar[str] = ("the run stopped before a step with ``breakpoint: true`` (the arm "
                           "at rest) and asks the operator to continue")
    label: str


@dataclass(frozen=True, kw_only=True)
class BreakpointAnswered(Event):
    type: ClassVar[str] = "breakpoint_answered"
    when: ClassVar[str] = ("the operator answered a breakpoint: ``go_on`` true continues, "
                           "false ends the run as an operator abort")
    go_on: bool


# ====================================================================== faults and Halt
@dataclass(frozen=True, kw_only=True)
class Fault(Event):
    type: ClassVar[str] = "fault"
    when: ClassVar[str] = "a fault ended the run (after the Halt was sent and confirmed or not)"
    cause: str
    module: int | None
    message: str
    #: The step the fault happened in (None: preflight or after the last step).
    step: int | None = None
    halt_sent: bool = False
    halt_confirmed: bool = False
    modules_not_halted: Sequence[int] | None = _optional()
    halt_attempts: int | None = _optional()
    halt_error: str | None = _optional()


@dataclass(frozen=True, kw_only=True)
class InternalError(Event):
    type: ClassVar[str] = "internal_error"
    when: ClassVar[str] = "a bug raised inside a step (the arm was halted); the traceback"
    traceback: str


@dataclass(frozen=True, kw_only=True)
class HaltConfirmed(Event):
    type: ClassVar[str] = "halt_confirmed"
    when: ClassVar[str] = "the emergency Halt was read back HALTED from every module"
    modules: Sequence[int]
    attempts: int
    duration_s: float | None


@dataclass(frozen=True, kw_only=True)
class HaltUnconfirmed(Event):
    type: ClassVar[str] = "halt_unconfirmed"
    when: ClassVar[str] = "the emergency Halt was sent but some modules did not read back HALTED"
    modules: Sequence[int]
    attempts: int
    duration_s: float | None
    states: Mapping[str, str]
    message: str


@dataclass(frozen=True, kw_only=True)
class HaltFailed(Event):
    type: ClassVar[str] = "halt_failed"
    when: ClassVar[str] = "the emergency Halt could not be sent (use the emergency stop)"
    error: str | None
    message: str


@dataclass(frozen=True, kw_only=True)
class LatchedFault(Event):
    type: ClassVar[str] = "latched_fault"
    when: ClassVar[str] = "the preflight found modules reporting a fault before the run sent anything"
    modules: Sequence[Mapping[str, Any]]
    message: str


@dataclass(frozen=True, kw_only=True)
class LatchedFaultCleared(Event):
    type: ClassVar[str] = "latched_fault_cleared"
    when: ClassVar[str] = "a Reset step may clear a fault latched before the run (who said so)"
    modules: Sequence[int]
    confirmed_by: str


@dataclass(frozen=True, kw_only=True)
class ListenerFailed(Event):
    type: ClassVar[str] = "listener_failed"
    when: ClassVar[str] = "a recorder or idle hook raised; it was removed, the run goes on"
    error: str


# ====================================================================== session
@dataclass(frozen=True, kw_only=True)
class ActivityStarted(Event):
    type: ClassVar[str] = "activity_started"
    when: ClassVar[str] = "the session started an activity (move, jog, run, reset, home, arm_up)"
    kind: str
    detail: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class ActivityFinished(Event):
    type: ClassVar[str] = "activity_finished"
    when: ClassVar[str] = "a session activity ended (status, exit code, one-line message)"
    kind: str
    status: str
    exit_code: int
    message: str


@dataclass(frozen=True, kw_only=True)
class SessionHalt(Event):
    type: ClassVar[str] = "session_halt"
    when: ClassVar[str] = "ArmSession.halt() sent the Halt broadcast and read the modules back"
    reason: str
    halt_sent: bool
    halt_confirmed: bool
    modules_not_halted: Sequence[int] = ()
    message: str = ""


@dataclass(frozen=True, kw_only=True)
class JogStarted(Event):
    type: ClassVar[str] = "jog_started"
    when: ClassVar[str] = "a jog starts streaming (joint, direction, velocity, where it would end)"
    joint: str
    direction: int
    velocity_deg_s: float
    end_deg: float
    end_reason: str
    #: "position" (FRAMP) or "velocity" (FVEL).
    mode: str = "position"


@dataclass(frozen=True, kw_only=True)
class JogStopped(Event):
    type: ClassVar[str] = "jog_stopped"
    when: ClassVar[str] = "a jog ended without a fault (released, stopped, end of its range)"
    joint: str
    reason: str
    joints_deg: Sequence[float] | None = None


@dataclass(frozen=True, kw_only=True)
class ClientJoined(Event):
    type: ClassVar[str] = "client_joined"
    when: ClassVar[str] = ("a client (a console page, an API client) joined the session "
                           "(seqrun/service/control.py); holder and clients as after it")
    client: Mapping[str, Any]
    holder: Mapping[str, Any] | None = None
    clients: Sequence[Mapping[str, Any]] = ()


@dataclass(frozen=True, kw_only=True)
class ClientLeft(Event):
    type: ClassVar[str] = "client_left"
    when: ClassVar[str] = "a client left the session (its connection closed)"
    client: Mapping[str, Any]
    holder: Mapping[str, Any] | None = None
    clients: Sequence[Mapping[str, Any]] = ()


@dataclass(frozen=True, kw_only=True)
class ControlTaken(Event):
    type: ClassVar[str] = "control_taken"
    when: ClassVar[str] = ("a client took control of the arm (holder), from nobody or, "
                           "taking over, from the previous holder (previous), who sees it; "
                           "stopped: what of the previous holder's motion was stopped first")
    holder: Mapping[str, Any] | None
    previous: Mapping[str, Any] | None = None
    stopped: str | None = None
    clients: Sequence[Mapping[str, Any]] = ()


@dataclass(frozen=True, kw_only=True)
class ControlReleased(Event):
    type: ClassVar[str] = "control_released"
    when: ClassVar[str] = ("the holder gave control up, or left (left); nobody holds it "
                           "until a client takes it")
    previous: Mapping[str, Any]
    left: bool = False
    holder: Mapping[str, Any] | None = None
    clients: Sequence[Mapping[str, Any]] = ()


@dataclass(frozen=True, kw_only=True)
class StatusPollFailed(Event):
    type: ClassVar[str] = "status_poll_failed"
    when: ClassVar[str] = "the session's idle status poll got no answer (shown as stale)"
    error: str


@dataclass(frozen=True, kw_only=True)
class Unregistered(Event):
    """An emitted type with no record here (a test forbids it; this keeps a run alive)."""

    type: ClassVar[str] = "unregistered"
    when: ClassVar[str] = "never (a test checks every emitted type has a record)"
    name: str = ""

    def as_dict(self) -> dict[str, Any]:
        out = super().as_dict()
        out.pop("name", None)
        out["type"] = self.name
        return out


def _all_event_classes() -> list[type[Event]]:
    out, todo = [], list(Event.__subclasses__())
    while todo:
        cls = todo.pop(0)
        out.append(cls)
        todo.extend(cls.__subclasses__())
    return out


#: Every event type by its name.
EVENT_TYPES: dict[str, type[Event]] = {
    cls.type: cls for cls in _all_event_classes() if cls is not Unregistered}


def make_event(type_: str, t: float, data: Mapping[str, Any], *,
               clock_s: float | None = None, **derived: Any) -> Event:
    """The typed record for an ``emit(type_, **data)`` call: declared fields by name, the
    rest in ``extra``. Never raises for unknown keys (a run must not fail on an event)."""
    cls = EVENT_TYPES.get(type_)
    if cls is None:
        return Unregistered(t=t, name=type_, extra=dict(data), clock_s=clock_s)
    names = _plain_fields(cls)
    known = {k: v for k, v in data.items() if k in names and k != "t"}
    extra = {k: v for k, v in data.items() if k not in names}
    if "t" in data:  # a setpoint carries its own t (the cycle's)
        t = data["t"]
    if cls is RunStarted:
        # run_started's clock_s is its own field (written); the derived reading is the same.
        return cls(t=t, extra=extra, **known)
    try:
        return cls(t=t, extra=extra, clock_s=clock_s, **known, **derived)
    except TypeError:
        # A call site without a declared field: keep everything, typed where possible.
        return Unregistered(t=t, name=type_, extra=dict(data), clock_s=clock_s)


# ====================================================================== delivery
class Subscription:
    """One subscriber's bounded queue. When full, the oldest events go (counted in
    :attr:`dropped`): the publisher never waits."""

    def __init__(self, hub: "EventHub", maxsize: int, name: str) -> None:
        if maxsize < 1:
            raise ValueError("maxsize must be at least 1")
        self.name = name
        self.maxsize = maxsize
        self.dropped = 0
        self._hub = hub
        self._queue: deque[Event] = deque()
        self._cond = threading.Condition(threading.Lock())
        self._closed = False
        #: Events handed out by get() whose handling is not finished (see wait_idle).
        self._busy = 0

    def _put(self, event: Event) -> None:
        with self._cond:
            if self._closed:
                return
            if len(self._queue) >= self.maxsize:
                self._queue.popleft()
                self.dropped += 1
            self._queue.append(event)
            self._cond.notify()

    def get(self, timeout: float | None = None) -> Event | None:
        """The next event, waiting up to ``timeout`` seconds (None: until one comes or the
        subscription is closed); None when none came or the subscription is closed."""
        with self._cond:
            if not self._queue and not self._closed:
                self._cond.wait(timeout)
            if not self._queue:
                return None
            self._busy = 1
            return self._queue.popleft()

    def task_done(self) -> None:
        """The event last taken by get() is handled (see Listener.flush)."""
        with self._cond:
            self._busy = 0

    @property
    def idle(self) -> bool:
        """Nothing queued and nothing taken but not yet handled."""
        with self._cond:
            return not self._queue and not self._busy

    def get_nowait(self) -> Event | None:
        with self._cond:
            return self._queue.popleft() if self._queue else None

    def drain(self) -> list[Event]:
        """Every queued event, oldest first, without waiting."""
        with self._cond:
            out = list(self._queue)
            self._queue.clear()
            return out

    def __iter__(self) -> Iterator[Event]:
        while True:
            event = self.get()
            if event is None:
                if self._closed:
                    return
                continue
            yield event

    def __len__(self) -> int:
        return len(self._queue)

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._hub._remove(self)


class Listener:
    """A subscription drained by its own daemon thread calling ``callback(event)``. A
    callback that raises is logged once (``error``) and the listener stops."""

    def __init__(self, subscription: Subscription, callback: Callable[[Event], None]) -> None:
        self.subscription = subscription
        self.callback = callback
        self.error: BaseException | None = None
        self._idle = threading.Condition()
        self._pending = 0
        self._thread = threading.Thread(target=self._run, daemon=True,
                                        name=f"seqrun-listener-{subscription.name or id(self)}")
        self._thread.start()

    def _run(self) -> None:
        sub = self.subscription
        while True:
            event = sub.get()
            if event is None:
                if sub.closed:
                    break
                continue
            try:
                self.callback(event)
            except (Exception, SystemExit) as exc:  # noqa: BLE001 - a face never stops a run
                self.error = exc
                sub.close()
                break
            finally:
                sub.task_done()
                with self._idle:
                    self._idle.notify_all()
        with self._idle:
            self._idle.notify_all()

    def flush(self, timeout: float = 1.0) -> bool:
        """Wait (up to ``timeout`` s) until every event queued so far was handled; for a
        face that must print its lines before a question or the final summary."""
        import time

        deadline = time.monotonic() + timeout
        with self._idle:
            while not self.subscription.idle and self._thread.is_alive():
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._idle.wait(min(left, 0.05))
        return True

    def close(self, timeout: float = 1.0) -> None:
        """Handle what is queued (up to ``timeout`` s), then stop the thread."""
        self.flush(timeout)
        self.subscription.close()
        self._thread.join(timeout)

    @property
    def dropped(self) -> int:
        return self.subscription.dropped


class EventHub:
    """Publish typed events to any number of subscribers, each on its own queue, and to the
    synchronous recorders (see the module docstring for why those exist)."""

    def __init__(self) -> None:
        self._subs: tuple[Subscription, ...] = ()
        self._recorders: tuple[Callable[[Event], None], ...] = ()
        self._lock = threading.Lock()

    def publish(self, event: Event) -> None:
        """Hand ``event`` to every subscriber. Never blocks on a subscriber, never raises."""
        for sub in self._subs:  # a tuple swapped whole on (un)subscribe: no lock here
            try:
                sub._put(event)
            except Exception:  # noqa: BLE001 - delivery must never fail the publisher
                pass

    def subscribe(self, *, maxsize: int = 1000, name: str = "") -> Subscription:
        sub = Subscription(self, maxsize, name)
        with self._lock:
            self._subs = self._subs + (sub,)
        return sub

    def add_listener(self, callback: Callable[[Event], None], name: str = "", *,
                     maxsize: int = 1000) -> Listener:
        """``callback(event)`` on a daemon thread of its own, fed by its own queue."""
        return Listener(self.subscribe(maxsize=maxsize, name=name), callback)

    def _remove(self, sub: Subscription) -> None:
        with self._lock:
            self._subs = tuple(s for s in self._subs if s is not sub)

    @property
    def subscribers(self) -> int:
        return len(self._subs)


# ====================================================================== documentation
def _type_name(tp: Any) -> str:
    text = tp if isinstance(tp, str) else getattr(tp, "__name__", repr(tp))
    return text.replace("typing.", "").replace("collections.abc.", "")


def events_markdown() -> str:
    """docs/events.md, generated from the records above."""
    lines = ["# Events", "",
             "Generated from `seqrun/events.py` by `python -m seqrun.events > docs/events.md`; "
             "a test checks it is current and that every emitted type is listed.", "",
             "Every event has `t` (seconds since the start of the run or activity), `type`, "
             "and `step` while a step runs. `events.jsonl.gz` (gzip; older runs: "
             "`events.jsonl`) holds one event per line in the "
             "shape of `Event.as_dict()`; fields marked *derived* are given to subscribers "
             "only (they are recomputed from the log). Fields not listed for a type (a step's "
             "result details, a checkpoint's figures) arrive in `extra` and in the line.", "",
             "Delivery: `EventHub.subscribe()` gives each subscriber its own bounded queue "
             "(oldest dropped and counted when full): a slow subscriber never delays the "
             "100 Hz loop. The run log is the one synchronous recorder: it must be complete "
             "on disk when a run is killed.", ""]
    for name, cls in sorted(EVENT_TYPES.items()):
        lines += [f"## `{name}`", "", cls.when[:1].upper() + cls.when[1:] + ".", ""]
        fields = [f for f in dataclasses.fields(cls) if f.name not in ("t", "step", "extra")]
        fields = [f for f in fields if not (f.name == "clock_s" and f.metadata.get("derived"))]
        if fields:
            lines += ["| field | type | |", "|---|---|---|"]
            for f in fields:
                note = ("derived" if f.metadata.get("derived")
                        else "optional" if f.metadata.get("optional") else "")
                lines.append(f"| `{f.name}` | `{_type_name(f.type)}` | {note} |")
            lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    print(events_markdown())
