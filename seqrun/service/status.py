"""The arm's status as a session knows it: the latest measurement, never read on demand.

:class:`ArmTelemetry` keeps the latest reading of every joint (position, velocity, flags,
fault), whether the arm is homed, halted or faulted and the operator's last message. It is
fed by the events of every activity (one ``measurement`` per streamed cycle) and, while
idle, by its own poll through the driver (ActPos, ActVel, state of every module, at a
modest rate, only when nothing else holds the bus). :meth:`ArmTelemetry.status` never
touches the bus. Part of the arm session (:mod:`seqrun.service.session`).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from seqrun.events import Event, EventHub, make_event

#: Version of this API (and of the console's /api/v<N>).
API_VERSION = 1

#: What the session is doing (ArmStatus.activity).
ACTIVITY_STATES = ("idle", "moving", "jogging", "running", "paused", "halted", "faulted")

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
    #: A pause: None (none), "requested" (the step under way finishes first) or "paused".
    pause: str | None = None
    #: Where the run holds: "Paused before step N (FILE:LINE:COL)" (None: it does not).
    paused_before: str | None = None
    #: The step the run started from (a run from step N: the steps before are not run).
    first_step: int = 1

    def as_dict(self) -> dict[str, Any]:
        return {"file": self.file, "step": self.step, "label": self.label,
                "steps": self.steps, "run_dir": self.run_dir, "pause": self.pause,
                "paused_before": self.paused_before, "first_step": self.first_step}


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
    #: Clock reading when the modules answered (the driver's reading time; None: not
    #: known, ``updated_at`` stands for it): what a ROS message of the reading is stamped.
    measured_at: float | None = None

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
class ArmCondition:
    """What decides whether the arm may move: a snapshot of :class:`ArmTelemetry`."""

    halted: str | None
    flags: dict[str, tuple[str, ...]]
    fault: bool
    measured: bool
    homed: bool | None
    joints: list[float | None]
    stale: bool


class ArmTelemetry:
    """The latest measurement of one arm (module docstring).

    :param session: the session's ``arm``, ``driver``, ``clock``, ``connection``, ``zero``.
    :param hub: the session's event hub (the poll publishes its readings there).
    :param t0: the session's time base (clock reading of event time 0).
    """

    def __init__(self, session: Any, hub: EventHub, t0: float) -> None:
        self._session = session
        self._hub = hub
        self._t0 = t0
        self._lock = threading.RLock()
        n = len(session.arm.joints)
        self._joints: list[float | None] = [None] * n
        self._velocities: list[float | None] = [None] * n
        self._targets: list[float | None] = [None] * n
        self._flags: dict[str, tuple[str, ...]] = {j.name: () for j in session.arm.joints}
        self._fault = False
        self._homed: bool | None = None
        #: Why the arm holds halted (the operator's STOP, a fault), None while it does not.
        self._halted: str | None = None
        #: Clock time of the last successful reset: older fault events no longer count.
        self._cleared_at = -math.inf
        self._updated_at: float | None = None
        self._measured_at: float | None = None
        self._stale = False
        self._message = ""
        self._poll_stop = threading.Event()
        self._poller: threading.Thread | None = None

    # ------------------------------------------------------------------ fed by events
    def on_event(self, event: Event) -> None:
        """Status from the events (the session's listener thread)."""
        from seqrun.events import Fault, Measurement, MovePlanned

        with self._lock:
            if isinstance(event, Measurement):
                self._take_measurement(event)
            elif isinstance(event, MovePlanned):
                for i, value in enumerate(event.target_deg):
                    self._targets[i] = float(value)
            elif isinstance(event, Fault) and (event.clock_s or 0) >= self._cleared_at:
                self._message = event.message
                if event.halt_sent:
                    self._halted = event.cause

    def _take_measurement(self, m) -> None:
        if (m.clock_s is not None and self._updated_at is not None
                and m.clock_s < self._updated_at):
            return  # older than a reading the session took itself meanwhile
        if m.states:
            homed = self._session.driver.HOMED_FLAG
            self._homed = all(homed in str(w).split("|") for w in m.states.values())
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
        self._measured_at = m.read_clock_s if m.read_clock_s is not None else m.clock_s
        self._stale = False

    # ------------------------------------------------------------------ what is known
    def status(self, activity: str | None, run: RunInfo | None) -> ArmStatus:
        """The latest measurement and ``activity`` (None: idle, or halted/faulted)."""
        from seqrun.service.kinematics import end_effector

        arm = self._session.arm
        with self._lock:
            joints = list(self._joints)
            velocities = list(self._velocities)
            targets = list(self._targets)
            flags = dict(self._flags)
            fault, updated, stale = self._fault, self._updated_at, self._stale
            measured = self._measured_at
            message = self._message
            activity = activity or self._rest_state()
        rows = tuple(JointStatus(j.name, j.module, joints[i], velocities[i], targets[i],
                                 flags.get(j.name, ()), self.flags_fault(flags.get(j.name, ())),
                                 j.locked is not None)
                     for i, j in enumerate(arm.joints))
        xyz: tuple[float, float, float] | None = None
        rpy: tuple[float, float, float] | None = None
        if all(x is not None for x in joints):
            pose = end_effector(arm, joints)  # type: ignore[arg-type]
            (x, y, z), (roll, pitch, yaw) = pose["position_mm"], pose["rpy_deg"]
            xyz, rpy = (x, y, z), (roll, pitch, yaw)
        zero = self._session.zero
        connection = self._session.connection
        return ArmStatus(rows, fault, xyz, rpy,
                         getattr(zero, "pose", None) if zero is not None
                         else getattr(arm, "zero_reference", None),
                         connection.description, bool(connection.is_simulator),
                         activity, run, updated, stale, message, measured)

    def _rest_state(self) -> str:
        if self._halted is not None or any("HALTED" in f for f in self._flags.values()):
            return "halted"
        return "faulted" if self._fault else "idle"

    def flags_fault(self, flags: tuple[str, ...]) -> bool:
        """A joint's flag names (as its driver named them) say it is at fault."""
        return any(n in self._session.driver.FAULT_FLAGS for n in flags)

    def condition(self) -> ArmCondition:
        with self._lock:
            return ArmCondition(self._halted, dict(self._flags), self._fault,
                                all(x is not None for x in self._joints), self._homed,
                                list(self._joints), self._stale)

    def joints_deg(self) -> dict[str, float]:
        """The measured joints (user degrees) by name; those not measured are left out."""
        with self._lock:
            return {j.name: float(x) for j, x in zip(self._session.arm.joints, self._joints)
                    if x is not None}

    @property
    def homed(self) -> bool | None:
        return self._homed

    # ------------------------------------------------------------------ halted, cleared
    def mark_halted(self, reason: str, *, unless_already: bool = False) -> None:
        with self._lock:
            if not (unless_already and self._halted is not None):
                self._halted = reason

    def mark_cleared(self) -> None:
        """A reset succeeded: not halted, no message, older fault events no longer count."""
        with self._lock:
            self._halted = None
            self._message = ""
            self._cleared_at = self._session.clock.now()

    def halted(self) -> str | None:
        with self._lock:
            return self._halted

    # ------------------------------------------------------------------ the idle poll
    def poll_once(self) -> None:
        """One reading of every module through the driver (the caller holds the bus)."""
        from seqrun.drivers.telemetry import joint_flags
        from seqrun.service.arm_access import read_joints

        arm = self._session.arm
        asked = self._session.clock.now()
        try:
            joints, velocities, states = read_joints(self._session.driver)
        except Exception as exc:  # noqa: BLE001 - a poll never raises: status goes stale
            self._poll_failed(str(exc))
            return
        flags, fault = joint_flags(arm.joint_names, arm.module_ids, {}, states)
        now = self._session.clock.now()
        read_at = (asked + now) / 2  # the modules answered between the two
        self._hub.publish(make_event(
            "measurement", round(now - self._t0, 6),
            {"joints_deg": joints, "state": [s.cycle_code for s in states.values()],
             "states": {str(m): s.describe() for m, s in states.items()}},
            clock_s=now, velocities_deg_s=velocities, flags=flags, fault=fault,
            source="poll", read_clock_s=read_at))
        with self._lock:  # at once, not only when the listener gets to it
            self._joints = list[float | None](joints)
            self._velocities = list[float | None](velocities)
            self._flags, self._fault = flags, fault
            self._homed = all(s.homed for s in states.values())
            self._updated_at, self._stale = now, False
            self._measured_at = read_at

    def _poll_failed(self, error: str) -> None:
        with self._lock:
            first = not self._stale
            self._stale = True
        if first:
            now = self._session.clock.now()
            self._hub.publish(make_event("status_poll_failed", round(now - self._t0, 6),
                                         {"error": error}, clock_s=now))

    def start_polling(self, hz: float, poll: Callable[[], Any],
                      idle: Callable[[], bool]) -> None:
        """Call ``poll()`` ``hz`` times a second while ``idle()`` (a thread of its own; a
        poll's own time counts in its period, so a reading that takes most of a period
        still comes ``hz`` times a second)."""
        import time

        stop = self._poll_stop = threading.Event()

        def loop(period: float) -> None:
            began = time.monotonic()
            while not stop.wait(max(0.0, period - (time.monotonic() - began))):
                began = time.monotonic()
                if idle():
                    try:
                        poll()
                    except Exception:  # noqa: BLE001 - the poll must never die
                        pass

        self._poller = threading.Thread(target=loop, args=(1.0 / hz,), daemon=True,
                                        name="seqrun-status-poll")
        self._poller.start()

    def stop_polling(self) -> None:
        self._poll_stop.set()
        if self._poller is not None:
            self._poller.join(timeout=5.0)
