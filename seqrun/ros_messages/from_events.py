"""seqrun's events (``events.jsonl`` lines, or the session's live events) as messages.

:class:`EventTranslator` is fed one event dict at a time and returns what it means on the
ROS side, as plain records (:class:`Joints`, :class:`Frames`, :class:`Planned`,
:class:`Shapes`, :class:`EventLine`); :mod:`.ros_fields` turns them into ROS message
fields, the Foxglove face into Foxglove messages.

Time: in a run folder every event's ``t`` is seconds since the run's start, and
``run_started`` carries ``start_epoch_s`` (the trace's time base): an event's time is
``start_epoch_s + t``, a reading's stamp ``start_epoch_s + read_t`` (when the modules
answered, from the bus's own time stamps). Events logged before ``run_started`` (the zero
reference) wait for it. Live (``live=True``) the stamps are the wall clock at translation,
a reading's shifted back by how long before the event the modules answered.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from seqrun.arm.tracking import sample_time, velocity_window
from seqrun.drivers.telemetry import VelocityWindow
from seqrun.events import event_line
from seqrun.ros_messages.names import RosNames
from seqrun.ros_messages.values import (Shape, Transform, capsule_shapes, stamp_ns,
                                        static_shapes, transforms)

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription

#: The link capsules are drawn at most this often (s of the event times).
CAPSULE_PERIOD_S = 0.1
#: Events that are readings: on the joint topics and /tf, not on /seqrun/events.
READINGS = ("setpoint", "measurement")
#: Events said at warning or error level on a log channel.
ERRORS = ("fault", "internal_error", "halt_failed", "halt_unconfirmed", "latched_fault",
          "listener_failed", "measurement_failed", "watchdog_disable_failed")
WARNINGS = ("abort_requested", "halt_requested", "operator_abort", "controlled_stop",
            "session_halt", "retry", "step_retry", "frame_discarded", "log_failed")


@dataclass(frozen=True)
class Joints:
    """A ``sensor_msgs/JointState``: ``kind`` "joint_states" (measured) or
    "joint_commands" (what the executor commanded: the plan at that cycle)."""

    kind: str
    stamp_ns: int
    log_ns: int
    names: tuple[str, ...]
    positions_deg: tuple[float, ...]
    velocities_deg_s: tuple[float, ...] | None = None


@dataclass(frozen=True)
class Frames:
    """A ``tf2_msgs/TFMessage``: every link of the chain at one reading."""

    stamp_ns: int
    log_ns: int
    transforms: tuple[Transform, ...]


@dataclass(frozen=True)
class Planned:
    """A ``trajectory_msgs/JointTrajectory``: one move's plan as it was streamed, every
    cycle's plan time, planned position and velocity; stamped at the move's start."""

    stamp_ns: int
    log_ns: int
    names: tuple[str, ...]
    times_s: tuple[float, ...]
    positions_deg: tuple[tuple[float, ...], ...]
    velocities_deg_s: tuple[tuple[float, ...], ...]


@dataclass(frozen=True)
class Shapes:
    """A ``visualization_msgs/MarkerArray``: guards, obstacles and link capsules."""

    stamp_ns: int
    log_ns: int
    shapes: tuple[Shape, ...]


@dataclass(frozen=True)
class EventLine:
    """One event: its ``events.jsonl`` line (``std_msgs/String``), its type, a level
    ("info", "warning", "error") and one line for people."""

    stamp_ns: int
    log_ns: int
    kind: str
    line: str
    level: str
    text: str


Record = Joints | Frames | Planned | Shapes | EventLine


def describe(event: Mapping[str, Any]) -> str:
    """One line for people (a Foxglove log, rosout)."""
    kind = str(event.get("type"))
    step = event.get("step")
    head = f"step {step}: " if step is not None else ""
    for key in ("message", "text", "label", "error", "status"):
        value = event.get(key)
        if isinstance(value, str) and value:
            return f"{head}{kind}: {value}"
    return f"{head}{kind}"


def level_of(kind: str) -> str:
    return "error" if kind in ERRORS else "warning" if kind in WARNINGS else "info"


@dataclass
class _Move:
    stamp_ns: int
    times: list[float] = field(default_factory=list)
    positions: list[tuple[float, ...]] = field(default_factory=list)
    velocities: list[tuple[float, ...]] = field(default_factory=list)


class EventTranslator:
    """Events in, records out (see the module docstring for the time base)."""

    def __init__(self, arm: ArmDescription, names: RosNames | None = None, *,
                 live: bool = False, wall_clock: Callable[[], float] = time.time,
                 events_topic: bool = True) -> None:
        self.arm = arm
        self.names = names or RosNames.of(arm)
        self.live = live
        self._wall = wall_clock
        self._events_topic = events_topic
        self._epoch0: float | None = None
        self._pending: list[Mapping[str, Any]] = []
        self._move: _Move | None = None
        self._capsules_at = -float("inf")
        self._joint_names = tuple(arm.joint_names)
        # The measured velocity of a logged reading (events.jsonl has none): the windowed
        # estimate the live faces and the report use, over the readings' own times.
        self._velocity = VelocityWindow(velocity_window(1.0 / arm.control.cycle_hz))

    # -- time ----------------------------------------------------------------------------
    def _ns(self, event: Mapping[str, Any], t: Any = None) -> int:
        """The stamp of ``t`` (default the event's ``t``), in the event's time base."""
        at = float((event.get("t") if t is None else t) or 0.0)
        if self.live:
            shift = (at - float(event.get("t") or 0.0)) if t is not None else 0.0
            return stamp_ns(self._wall() + shift)
        assert self._epoch0 is not None
        return stamp_ns(self._epoch0 + at)

    # -- feeding -------------------------------------------------------------------------
    def translate(self, event: Mapping[str, Any]) -> list[Record]:
        """The records of one event (an ``events.jsonl`` line or a live event's dict)."""
        if not self.live and self._epoch0 is None:
            if event.get("type") != "run_started" or "start_epoch_s" not in event:
                self._pending.append(event)
                return []
            # start_epoch_s is the wall-clock time of t = 0 (run_started itself comes a
            # moment after it in real time)
            self._epoch0 = float(event["start_epoch_s"])
            out: list[Record] = []
            for early in [*self._pending, event]:
                out += self._translate(early)
            self._pending = []
            return out
        return self._translate(event)

    def finish(self) -> list[Record]:
        """What is still held: the plan of a move the log ended in."""
        if self._move is None:
            return []
        return [self._close_move()]

    # -- per event -----------------------------------------------------------------------
    def _translate(self, event: Mapping[str, Any]) -> list[Record]:
        kind = str(event.get("type"))
        out: list[Record] = []
        if kind == "setpoint":
            out += self._setpoint(event)
        elif kind == "measurement":
            out += self._measurement(event)
        else:
            if kind == "move_planned" or (self._move is not None and kind in (
                    "step_finished", "run_finished", "fault", "controlled_stop")):
                if self._move is not None:
                    out.append(self._close_move())
            if kind == "move_planned":
                self._move = _Move(self._ns(event))
            if kind in ("run_started", "step_started", "activity_started"):
                out.append(Shapes(self._ns(event), self._ns(event),
                                  tuple(static_shapes(self.arm))))
        if kind not in READINGS and self._events_topic:
            out.append(self._line(event, kind))
        return out

    def _line(self, event: Mapping[str, Any], kind: str) -> EventLine:
        ns = self._ns(event)
        data = dict(event)
        return EventLine(ns, ns, kind, event_line(data),
                         level_of(kind), describe(event))

    def _reading_ns(self, event: Mapping[str, Any]) -> int:
        read_t = event.get("read_t")
        if isinstance(read_t, Sequence) and not isinstance(read_t, str) and read_t:
            read_t = max(float(v) for v in read_t)
        return self._ns(event, read_t) if isinstance(read_t, (int, float)) else self._ns(event)

    def _joints_and_frames(self, event: Mapping[str, Any], joints_deg: Sequence[float],
                           stamp: int, velocities: Sequence[float] | None = None
                           ) -> list[Record]:
        log = self._ns(event)
        positions = tuple(float(v) for v in joints_deg)
        out: list[Record] = [
            Joints("joint_states", stamp, log, self._joint_names, positions,
                   None if velocities is None else tuple(float(v) for v in velocities)),
            Frames(stamp, log, tuple(transforms(self.arm, positions, self.names)))]
        t = float(event.get("t") or 0.0)
        if t - self._capsules_at >= CAPSULE_PERIOD_S or t < self._capsules_at:
            self._capsules_at = t
            out.append(Shapes(stamp, log, tuple(capsule_shapes(self.arm, positions))))
        return out

    def _setpoint(self, event: Mapping[str, Any]) -> list[Record]:
        out: list[Record] = []
        log = self._ns(event)
        planned = tuple(float(v) for v in event["planned_deg"])
        planned_vel = tuple(float(v) for v in event.get("planned_vel_deg_s") or ())
        out.append(Joints("joint_commands", log, log, self._joint_names, planned,
                          planned_vel or None))
        if self._move is not None:
            self._move.times.append(float(event.get("plan_t") or 0.0))
            self._move.positions.append(planned)
            self._move.velocities.append(planned_vel)
        if not self.live:   # live, the cycle's measurement event says it (with velocities)
            measured = event["measured_deg"]
            read_t = event.get("read_t")
            self._velocity.add(sample_time(read_t) if isinstance(read_t, (int, float, list))
                               else float(event.get("t") or 0.0), measured)
            out += self._joints_and_frames(event, measured, self._reading_ns(event),
                                           self._velocity.velocity())
        return out

    def _measurement(self, event: Mapping[str, Any]) -> list[Record]:
        joints = event.get("joints_deg")
        if not joints or any(v is None for v in joints):
            return []
        velocities = event.get("velocities_deg_s")
        if velocities is None and not self.live:   # a logged reading: estimated as above
            self._velocity.add(float(event.get("t") or 0.0), joints)
            velocities = self._velocity.velocity()
        return self._joints_and_frames(event, joints, self._ns(event), velocities)

    def _close_move(self) -> Planned:
        move, self._move = self._move, None
        assert move is not None
        return Planned(move.stamp_ns, move.stamp_ns, self._joint_names, tuple(move.times),
                       tuple(move.positions), tuple(move.velocities))
