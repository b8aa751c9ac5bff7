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

import math
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from seqrun.errors import Refused
from seqrun.events import Event, EventHub, Subscription
from seqrun.halt import HaltConfirmation

#: Version of this API (and of the console's /api/v<N>).
API_VERSION = 1

#: What the session is doing (ArmStatus.activity).
ACTIVITY_STATES = ("idle", "moving", "jogging", "running", "paused", "halted", "faulted")

#: A jog that is not renewed within this time ends with a controlled stop (deadman).
JOG_DEADMAN_S = 0.2

#: Idle status poll rate (Hz): modest, the bus is shared with nothing else while idle.
STATUS_POLL_HZ = 5.0


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

    def __init__(self, kind: str, activity_id: int) -> None:
        self.kind = kind
        self.id = activity_id
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
    :param poses_dir: pose search path for named poses (default: the project's).
    :param zero: the zero reference in force (:class:`~seqrun.zero.ZeroInForce`), for status
        and the run records.
    :param status_hz: idle status poll rate; 0 disables polling (tests poll by hand with
        :meth:`poll_status`).
    """

    def __init__(self, arm, connection, *, project=None, log_root: Path | None = None,
                 poses_dir=None, zero=None, status_hz: float = STATUS_POLL_HZ,
                 response_timeout_s: float | None = None, own_connection: bool = True,
                 jog_deadman_s: float = JOG_DEADMAN_S) -> None:
        raise NotImplementedError

    # ------------------------------------------------------------------ lifetime
    def __enter__(self) -> "ArmSession":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Stop any motion (controlled stop; a Halt if that does not end it), stop the
        status poll, close the client and (``own_connection``) the bus."""
        raise NotImplementedError

    # ------------------------------------------------------------------ events and status
    @property
    def events(self) -> EventHub:
        """The session's event hub (every run's, move's and poll's typed events)."""
        raise NotImplementedError

    def subscribe(self, *, maxsize: int = 1000, name: str = "") -> Subscription:
        """Typed events on a queue of their own (see :class:`seqrun.events.EventHub`)."""
        raise NotImplementedError

    def status(self) -> ArmStatus:
        """The latest measurement and what the session does; never touches the bus."""
        raise NotImplementedError

    def status_dict(self) -> dict[str, Any]:
        """:meth:`status` as JSON-ready dict (the control socket's ``status`` op)."""
        return self.status().as_dict()

    def poll_status(self) -> ArmStatus:
        """Read the arm once now (idle only; during an activity the executor feeds status)
        and return the new status. The background poll calls this."""
        raise NotImplementedError

    @property
    def activity(self) -> Activity | None:
        """The activity under way, or None."""
        raise NotImplementedError

    # ------------------------------------------------------------------ stopping
    def halt(self, reason: str = "STOP") -> HaltConfirmation:
        """Halt broadcast now from this thread, stop any activity, confirm by reading every
        module back. Never waits behind a lock, a run or a queue before the broadcast."""
        raise NotImplementedError

    def halt_dict(self, reason: str = "STOP") -> dict[str, Any]:
        """:meth:`halt` as a JSON-ready dict (the control socket's ``halt`` op)."""
        result = self.halt(reason)
        return {"v": API_VERSION, **result.as_dict(), "message": result.describe()}

    def control_handler(self) -> Any:
        """The object a control socket serves: ``status_dict()`` and ``halt(reason) -> dict``."""
        return _ControlHandler(self)

    # ------------------------------------------------------------------ blocking commands
    def reset(self) -> ActivityResult:
        """Reset every module (clears faults and Halt), confirmed by reading back."""
        raise NotImplementedError

    def home(self) -> ActivityResult:
        """Home every module (the arm file's homing), confirmed (HOME_OK)."""
        raise NotImplementedError

    def arm_up(self) -> ActivityResult:
        """"ARM" of the thesis console: reset, then write the arm file's limits."""
        raise NotImplementedError

    # ------------------------------------------------------------------ moves
    def set_move_velocities(self, velocities_deg_s: Mapping[str, float]) -> dict[str, float]:
        """Per-joint velocity (deg/s) of the session's moves (the thesis ALLVEL); joints not
        named keep theirs. Returns the velocities in force. Refused: unknown joint, NaN, not
        positive, above the joint's limit."""
        raise NotImplementedError

    def move_velocities(self) -> dict[str, float]:
        raise NotImplementedError

    def move_to_pose(self, name: str, *, velocity_scale: float | None = None) -> Activity:
        """Move to a named pose (a pose file), as a one-step sequence: validated, executed
        by the executor. Non-blocking."""
        raise NotImplementedError

    def move_to_joints(self, joints_deg: Mapping[str, float], *,
                       velocity_scale: float | None = None) -> Activity:
        """Move the named joints to user-degree targets (others stay). Non-blocking."""
        raise NotImplementedError

    # ------------------------------------------------------------------ jog
    def jog(self, joint: str, speed_scale: float) -> Activity:
        """Jog one joint at ``speed_scale`` (-1..1) of its jog velocity. Call again at least
        every :data:`JOG_DEADMAN_S` (same joint: renews, new scale applies) or the jog ends
        with a controlled stop. Refused near a limit (moving towards it) or outside the
        workspace guards, like a move."""
        raise NotImplementedError

    def jog_stop(self) -> ActivityResult | None:
        """End the jog with a controlled stop (waits for it); None if no jog ran."""
        raise NotImplementedError

    # ------------------------------------------------------------------ sequences
    def run_sequence(self, file: str | Path, *, speed: float = 1.0, step_mode: bool = False,
                     first_step: int = 1, command_mode: str | None = None,
                     log_dir: Path | None = None, html_report: bool = True,
                     loaded=None, assume_yes: bool = False) -> Activity:
        """Validate ``file`` (refused with its first error line when invalid), then run it in
        a worker thread with a run folder like ``seqrun run``. Questions (confirm steps,
        ``step_mode``'s before-step question, clearing a latched fault) are published as
        ``confirm_requested`` events; answer them with :meth:`answer`."""
        raise NotImplementedError

    def pause(self) -> None:
        """Pause the run (controlled stop, hold); :meth:`resume` goes on."""
        raise NotImplementedError

    def resume(self) -> None:
        raise NotImplementedError

    def step(self) -> None:
        """In step mode: let the next step start (answers its before-step question yes)."""
        raise NotImplementedError

    def abort(self, reason: str = "operator abort") -> None:
        """Controlled stop of whatever moves (run, move, jog); the activity ends (130)."""
        raise NotImplementedError

    def answer(self, question_id: str, yes: bool) -> None:
        """Answer a ``confirm_requested`` question (any thread). Refused: unknown or
        already answered question."""
        raise NotImplementedError

    def pending_questions(self) -> dict[str, str]:
        """Questions waiting for an answer: id -> text."""
        raise NotImplementedError

    # ------------------------------------------------------------------ poses
    def pose_names(self) -> list[str]:
        """Every pose the session can move to (the project's and the shipped ones)."""
        raise NotImplementedError

    def save_pose(self, name: str, *, overwrite: bool = False, description: str = "") -> Path:
        """Write a pose file from the measured joints (the project's poses folder)."""
        raise NotImplementedError


class _ControlHandler:
    """What a control socket (seqrun.service.control_socket) serves for a session."""

    def __init__(self, session: ArmSession) -> None:
        self._session = session

    def status_dict(self) -> dict[str, Any]:
        return self._session.status_dict()

    def halt(self, reason: str) -> dict[str, Any]:
        return self._session.halt_dict(reason)


def _finite(value: Any, what: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise Refused(f"{what}: {value!r} is not a number") from None
    if not math.isfinite(x):
        raise Refused(f"{what}: {value!r} is not a finite number")
    return x


__all__ = ["API_VERSION", "ACTIVITY_STATES", "JOG_DEADMAN_S", "Activity", "ActivityResult",
           "ArmSession", "ArmStatus", "JointStatus", "RunInfo", "Refused", "Event"]
