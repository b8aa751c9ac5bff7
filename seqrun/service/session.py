"""The arm session: the one object that owns one arm's bus (the service layer).

Every face (``seqrun run`` and the arm commands, the web console, a future ROS 2 bridge) goes
through an :class:`ArmSession` and its typed results and events (:mod:`seqrun.events`), never
through the executor or the arm's driver.

What it guarantees:

- **One activity at a time** (a move, a jog, a sequence run, reset/home/arm-up). A second one
  is refused (:class:`~seqrun.errors.Refused`, one line); so are bad inputs (unknown joint or
  pose, a target outside the limits, NaN) and a motion while the arm is halted or faulted.
  A refused command sends nothing.
- **Every motion goes through the sequence machinery**: a console move is a one-step sequence
  built in memory, validated by the same validator and run by the same executor (the same
  per-cycle checks, the same Halt on any fault).
- :meth:`ArmSession.halt` **never waits behind anything**: it sends the Halt broadcast from
  the caller's thread (the driver's ``halt_now`` path takes no lock a run holds), posts a Halt
  request to a running activity's stop-request inbox, and then confirms by reading every
  module back.
- **Status without touching the bus**: :meth:`ArmSession.status` returns the latest
  measurement. While idle a background thread polls the arm at a modest rate (paused while an
  activity owns the bus); during an activity the executor's measurements feed it.
- Nothing restarts motion by itself: after a halt or a fault only an explicit reset (or
  arm-up) makes the arm movable again.

The session owns the connection's driver and the event hub and composes small services,
one concept each, as a CANopen node composes its SDO, NMT and PDO services:

========================  ==========================================================
``session.activities``    one activity at a time, its executor (:mod:`.activities`)
``session.telemetry``     the latest measurement, the idle poll (:mod:`.status`)
``session.stopping``      STOP (a confirmed Halt) and abort (:mod:`.stopping`)
``session.motion``        reset/home/arm-up, moves, velocities, jog (:mod:`.motion`)
``session.runs``          sequence runs, pause/resume (:mod:`.runs`)
``session.questions``     questions as events, answers (:mod:`.questions`)
========================  ==========================================================

The methods below are the session's API (``API_VERSION``); each hands on to its service.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from seqrun.drivers.base import HaltConfirmation
from seqrun.errors import Refused
from seqrun.events import Event, EventHub, Subscription, make_event
from seqrun.service.activities import (EXIT_FAULT_CODE, Activities, Activity,
                                       ActivityResult)
from seqrun.service.control import ControlDesk
from seqrun.service.gripper import GripperControl
from seqrun.service.motion import DEFAULT_MOVE_SHARE, JOG_DEADMAN_S, Motion
from seqrun.service.questions import Questions
from seqrun.service.runs import Runs
from seqrun.service.status import (ACTIVITY_STATES, API_VERSION, STATUS_POLL_HZ, ArmStatus,
                                   ArmTelemetry, JointStatus, RunInfo)
from seqrun.service.stopping import HALT_CONFIRM_WAIT_S, ControlHandler, Stopping


class ArmSession:
    """The one owner of one arm's bus. Thread-safe; see the module docstring.

    :param arm: the arm description, with the zero reference in force applied
        (:meth:`~seqrun.arm.description.ArmDescription.with_zero_reference`).
    :param connection: an open :class:`~seqrun.service.connection.Connection` (the session closes it
        in :meth:`close` when ``own_connection``).
    :param project: the campaign (:class:`~seqrun.sequence.project.Project`): poses, run folders.
    :param log_root: where run folders go (default: the project's runs dir, else ``runs/``).
    :param poses_dir: pose search path for named poses (default: the project's, then the
        shipped poses).
    :param zero: the zero reference in force (:class:`~seqrun.service.zero.ZeroInForce`), for status
        and the run records.
    :param status_hz: idle status poll rate; 0 disables polling (tests poll by hand with
        :meth:`poll_status`).
    :param arm_path: the arm file ``arm`` was read from, named in the run records
        (record.json, inputs/); default: the sequence's own arm file.
    :param loop_priority: run each activity's thread (the 100 Hz loop) at ``SCHED_FIFO``
        with this priority (1-99; that thread and the threads it starts:
        :mod:`seqrun.service.realtime`).
    """

    def __init__(self, arm, connection, *, project=None, log_root: Path | None = None,
                 poses_dir=None, zero=None, status_hz: float = STATUS_POLL_HZ,
                 response_timeout_s: float | None = None, own_connection: bool = True,
                 jog_deadman_s: float = JOG_DEADMAN_S,
                 loop_priority: int | None = None, arm_path: Path | None = None,
                 arm_id: str | None = None) -> None:
        from seqrun.drivers.registry import open_driver
        from seqrun.service.connection import response_timeout_s as default_timeout
        from seqrun.shipped import shipped_dir

        self.arm = arm
        self.arm_path = Path(arm_path) if arm_path is not None else None
        #: In a campaign with several arms ([arms.ID]): which arm this is (its runs say so).
        self.arm_id = arm_id
        self.connection = connection
        self.clock = connection.clock
        self.project = project
        self.zero = zero
        self.own_connection = own_connection
        if poses_dir is None:
            poses_dir = (tuple(project.pose_path) if project is not None
                         else (Path("poses"), shipped_dir("poses")))
        self.poses_dir = poses_dir
        self.log_root = Path(log_root) if log_root is not None else (
            project.runs_dir if project is not None else Path("runs"))
        #: The arm's driver: every word to the modules goes through it.
        self.driver = open_driver(arm, connection, response_timeout_s=(
            response_timeout_s if response_timeout_s is not None else default_timeout(arm)))
        self._hub = EventHub()
        self._t0 = self.clock.now()
        self._closed = False
        self._closing = threading.Lock()
        # The services, each one concept (module docstring).
        self.questions = Questions(self.publish, lambda: self.activities.stop_pending(),
                                   self._started_by)
        self.activities = Activities(self, self.publish, self._activity_ended,
                                     loop_priority=loop_priority)
        self.telemetry = ArmTelemetry(self, self._hub, self._t0)
        self.stopping = Stopping(self)
        self.motion = Motion(self, jog_deadman_s=jog_deadman_s)
        self.gripper = GripperControl(self)
        self.runs = Runs(self)
        #: Who holds control and who watches (every face of this session shares it).
        self.control = ControlDesk(publish=self.publish, clock=self.clock.now,
                                   stop_motion=self.stop_motion_of)
        #: This arm against the other arms of a campaign served in this process
        #: (:class:`seqrun.service.arm_separation.SessionSeparation`; None: one arm).
        self.separation: Any = None
        self._status_listener = self._hub.add_listener(self._on_event, "session status",
                                                       maxsize=10_000)
        self._status_hz = 0.0
        self.set_status_rate(status_hz)

    # ------------------------------------------------------------------ lifetime
    def __enter__(self) -> ArmSession:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Stop any motion (controlled stop; a Halt if that does not end it), stop the
        status poll, close the driver and (``own_connection``) the bus."""
        with self._closing:
            if self._closed:
                return
            self._closed = True
            activity = self.activities.current
        if activity is not None and not activity.done:
            self.abort("session closed")
            try:
                activity.wait(timeout=10.0)
            except TimeoutError:
                self.halt("session closed: the activity did not stop")
        self.telemetry.stop_polling()
        self._status_listener.close(timeout=1.0)
        self.driver.close()
        if self.own_connection:
            self.connection.close()

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def client(self) -> Any:
        """The driver's bus client, where it has one (tests look at its frames)."""
        return getattr(self.driver, "client", None)

    @property
    def jog_deadman_s(self) -> float:
        """A jog not renewed within this time (s) ends with a controlled stop."""
        return self.motion.jog_deadman_s

    @jog_deadman_s.setter
    def jog_deadman_s(self, seconds: float) -> None:
        self.motion.jog_deadman_s = seconds

    def _started_by(self) -> str | None:
        activity = self.activities.current
        return activity.started_by if activity is not None else None

    @property
    def activity(self) -> Activity | None:
        """The activity under way, or None."""
        return self.activities.current

    # ------------------------------------------------------------------ events
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
        self.activities.add_idle_hook(hook)

    def remove_idle_hook(self, hook: Callable[[float], None]) -> None:
        self.activities.remove_idle_hook(hook)

    def publish(self, type_: str, **data: Any) -> None:
        """A session event (its own time base) on the hub."""
        now = self.clock.now()
        self._hub.publish(make_event(type_, round(now - self._t0, 6), data, clock_s=now))

    def _on_event(self, event: Event) -> None:
        """Status from the events (its own listener thread)."""
        self.telemetry.on_event(event)
        self.activities.on_event(event)

    def _activity_ended(self, result: ActivityResult) -> None:
        if result.exit_code == EXIT_FAULT_CODE:
            self.telemetry.mark_halted("fault", unless_already=True)
        self.questions.withdraw()

    # ------------------------------------------------------------------ status
    def status(self) -> ArmStatus:
        """The latest measurement and what the session does; never touches the bus."""
        return self.telemetry.status(self.activities.state(), self.activities.run_info)

    def status_dict(self) -> dict[str, Any]:
        """:meth:`status` as a JSON-ready dict (the control socket's ``status`` op)."""
        return self.status().as_dict()

    def set_status_rate(self, hz: float) -> float:
        """Read the arm ``hz`` times a second while idle (0: not at all; the ROS node reads
        it at its joint_states rate); returns the rate before."""
        before = self._status_hz
        self.telemetry.stop_polling()
        self._status_hz = float(hz)
        if hz > 0:
            self.telemetry.start_polling(hz, self.poll_status,
                                         lambda: self.activities.current is None)
        return before

    def poll_status(self) -> ArmStatus:
        """Read the arm once now (idle only; during an activity the executor feeds status)
        and return the new status. The background poll calls this."""
        bus = self.activities.bus
        if bus.acquire(blocking=False):
            try:
                if self.activities.current is None and not self.driver.closed:
                    self.telemetry.poll_once()
            finally:
                bus.release()
        return self.status()

    # ------------------------------------------------------------------ stopping
    def halt(self, reason: str = "STOP") -> HaltConfirmation:
        """Halt broadcast now from this thread, stop any activity, confirm by reading every
        module back (:meth:`Stopping.halt`)."""
        return self.stopping.halt(reason)

    def halt_dict(self, reason: str = "STOP") -> dict[str, Any]:
        """:meth:`halt` as a JSON-ready dict (the control socket's ``halt`` op)."""
        return self.stopping.halt_dict(reason)

    def abort(self, reason: str = "operator abort") -> None:
        """Controlled stop of whatever moves (:meth:`Stopping.abort`)."""
        self.stopping.abort(reason)

    def stop_motion_of(self, client: Any) -> str | None:
        """End the motion a control desk's ``client`` started (its ``name`` is the activity's
        ``started_by``), if one is under way, with a controlled stop, and wait for it (a Halt
        if it does not end); what was done (None: nothing of its was under way). The desk
        calls it when that client releases control, leaves, or is taken over."""
        activity = self.activities.current
        if activity is None or activity.done or activity.started_by != client.name:
            return None
        if activity.kind == "jog":
            self.jog_stop()
            return "jog stopped (controlled stop)"
        self.abort(f"{client.name} no longer holds control")
        try:
            activity.wait(timeout=30.0)
        except TimeoutError:
            self.halt(f"{client.name} no longer holds control: the {activity.kind} did not stop")
            return f"{activity.kind} halted"
        return f"{activity.kind} stopped (controlled stop)"

    def control_handler(self) -> Any:
        """The object a control socket serves: ``status_dict()`` and ``halt(reason) -> dict``."""
        return ControlHandler(self)

    # ------------------------------------------------------------------ commands and moves
    def reset(self) -> ActivityResult:
        return self.motion.reset()

    def home(self) -> ActivityResult:
        return self.motion.home()

    def arm_up(self) -> ActivityResult:
        return self.motion.arm_up()

    def set_move_velocities(self, velocities_deg_s: Mapping[str, float]) -> dict[str, float]:
        return self.motion.set_move_velocities(velocities_deg_s)

    def move_velocities(self) -> dict[str, float]:
        return self.motion.move_velocities()

    def move_to_pose(self, name: str, *, velocity_scale: float | None = None,
                     by: str | None = None) -> Activity:
        return self.motion.move_to_pose(name, velocity_scale=velocity_scale, by=by)

    def move_to_joints(self, joints_deg: Mapping[str, float], *,
                       velocity_scale: float | None = None, by: str | None = None) -> Activity:
        return self.motion.move_to_joints(joints_deg, velocity_scale=velocity_scale, by=by)

    def jog(self, joint: str, speed_scale: float, *, by: str | None = None,
            mode: str = "position") -> Activity:
        return self.motion.jog(joint, speed_scale, by=by, mode=mode)

    def jog_stop(self) -> ActivityResult | None:
        return self.motion.jog_stop()

    def grip(self, part_width_mm: float, force_n: float, *,
             by: str | None = None) -> Activity:
        return self.gripper.grip(part_width_mm, force_n, by=by)

    def release(self, width_mm: float, *, by: str | None = None) -> Activity:
        return self.gripper.release(width_mm, by=by)

    def gripper_state(self) -> dict[str, Any] | None:
        return self.gripper.state()

    # ------------------------------------------------------------------ sequences
    def run_sequence(self, file: str | Path, *, speed: float = 1.0, step_mode: bool = False,
                     first_step: int = 1, command_mode: str | None = None,
                     log_dir: Path | None = None, html_report: bool = True,
                     loaded=None, assume_yes: bool = False, by: str | None = None) -> Activity:
        """Validate and run ``file`` in a worker, questions as events
        (:meth:`Runs.run_sequence`); ``by``: who started it (a face's client)."""
        return self.runs.run_sequence(file, speed=speed, step_mode=step_mode,
                                      first_step=first_step, command_mode=command_mode,
                                      log_dir=log_dir, html_report=html_report,
                                      loaded=loaded, assume_yes=assume_yes, by=by)

    def run_loaded(self, loaded, *, log_dir: Path | None, speed: float = 1.0,
                   first_step: int = 1, command_mode: str | None = None,
                   confirm: Callable[[str], bool] | None = None,
                   before_step: Callable | None = None,
                   confirm_clear_latched: Callable[[str], bool] | None = None,
                   on_executor: Callable | None = None, run_control=None, requests=None,
                   warn: Callable[[str], None] | None = None, meta: dict | None = None,
                   html_report: bool = True, file: str | None = None,
                   bus_held: bool = False, cycle_hz: float | None = None,
                   record_zero: Callable[[str], Any] | None = None, part: Any = None,
                   attended: Any = None):
        """Run a loaded, checked sequence on this thread, the caller's prompts and signals
        (:meth:`Runs.run_loaded`)."""
        return self.runs.run_loaded(
            loaded, log_dir=log_dir, speed=speed, first_step=first_step,
            command_mode=command_mode, confirm=confirm, before_step=before_step,
            confirm_clear_latched=confirm_clear_latched, on_executor=on_executor,
            run_control=run_control, requests=requests, warn=warn, meta=meta,
            html_report=html_report, file=file, bus_held=bus_held, cycle_hz=cycle_hz,
            record_zero=record_zero, part=part, attended=attended)

    def pause(self) -> None:
        self.runs.pause()

    def resume(self) -> None:
        self.runs.resume()

    # ------------------------------------------------------------------ questions
    def step(self) -> None:
        self.questions.step()

    def answer(self, question_id: str, yes: bool, name: str | None = None,
               choice: str | None = None) -> None:
        self.questions.answer(question_id, yes, name, choice)

    def pending_questions(self) -> dict[str, str]:
        return self.questions.pending()

    # ------------------------------------------------------------------ poses
    def pose_names(self) -> list[str]:
        """Every pose the session can move to (the project's and the shipped ones)."""
        from seqrun.service.poses import pose_names

        return pose_names(self.poses_dir)

    def save_pose(self, name: str, *, overwrite: bool = False, description: str = "") -> Path:
        """Write a pose file from the measured joints (the project's poses folder)."""
        from seqrun.service.poses import save_session_pose

        return save_session_pose(self, name, overwrite=overwrite, description=description)


__all__ = ["API_VERSION", "ACTIVITY_STATES", "DEFAULT_MOVE_SHARE", "HALT_CONFIRM_WAIT_S",
           "JOG_DEADMAN_S", "Activity", "ActivityResult", "ArmSession", "ArmStatus",
           "JointStatus", "RunInfo", "Refused", "Event"]
