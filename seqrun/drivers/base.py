"""The arm-driver interface: what the executor asks of an arm, in joint terms.

The executor plans in user coordinates and checks in joint terms; a driver turns that into
one arm's wire protocol and back. Everything a driver reports is joint-level, typed and in
the user's units: positions in user degrees (joint order; the driver alone applies the arm
file's offsets and its drives' units), a compact per-cycle state (:class:`CycleState`) and,
when asked, the full decoded state of a joint (:class:`JointState`).

:class:`ArmDriver` lists the calls of one open arm (a run's and the session's);
:class:`DriverFamily` what the registry (:mod:`seqrun.drivers.registry`) asks of a driver
class before an arm is open. :mod:`seqrun.drivers.powercube` implements both over the
PowerCube protocol; another arm (or a ROS 2 bridge) is one more package implementing the
same calls (docs/adding-a-driver.md). No I/O here.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Literal, NamedTuple, Protocol, runtime_checkable

import numpy as np

from seqrun.arm.joint_values import GripperReading, JointLimits, JointState, LimitValues
from seqrun.arm.planner import Limits, MovePlan

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription

#: Power-session marks are 1 .. SESSION_MARK_LIMIT - 1 (:meth:`ArmDriver.write_session_mark`).
SESSION_MARK_LIMIT = 4096

#: Where a driver sends its events (the executor's ``emit``: type, then fields).
EventSink = Callable[..., None]


class CycleState(Protocol):
    """What a joint reports with every reading (PowerCube: the short state byte)."""

    @property
    def refuses_motion(self) -> bool:
        """The joint has faulted, halted or is not homed: its full state says which."""

    @property
    def moving(self) -> bool:
        """The drive reports motion."""

    def describe(self) -> str:
        """The drive's own flag names, for the operator."""

    def __int__(self) -> int:
        """A compact code for the event log (the driver documents its bits)."""



class JointReading(NamedTuple):
    """One reading of every joint."""

    #: User degrees (Totem = zeros), joint order.
    positions_deg: np.ndarray
    #: Per module id: the state the joint reported with this reading.
    states: dict[int, CycleState]
    #: When each joint answered (clock times, joint order, from the bus's own time stamps;
    #: None: not known, the reader's clock is used). Velocities come from these times,
    #: never from when a possibly stalled host got round to the answers.
    answered_at: np.ndarray | None = None
    #: Where each joint comes to rest if no command follows this cycle's (user radians,
    #: joint order; NaN: a joint this motion does not command). None: not bounded (a
    #: velocity command runs on until its watchdog). Bounds how far an arm whose host
    #: stalls can still go (seqrun/service/arm_separation.py).
    holds_at_rad: np.ndarray | None = None


@dataclass(frozen=True)
class ArmPoll:
    """One reading of the arm outside a run (status): per joint (joint order) its
    position and velocity, per module id its full state. A joint whose answers were lost
    (``tolerate_loss``) is None in all three."""

    positions_deg: list[float | None]
    velocities_deg_s: list[float | None]
    states: dict[int, JointState | None]

    @property
    def complete(self) -> bool:
        return all(s is not None for s in self.states.values())

    def missing(self) -> list[int]:
        """The modules that did not answer."""
        return [m for m, s in self.states.items() if s is None]





@dataclass(frozen=True)
class ArmIdentity:
    """Which physical arm this is: what its modules say about themselves (their serial
    numbers, by module id). Read at connect; the zero reference is keyed by it."""

    #: ``(module id, serial number as the drive states it)``, in joint order.
    serials: tuple[tuple[int, str], ...]

    @classmethod
    def of(cls, serials: Mapping[int, Any]) -> ArmIdentity:
        return cls(tuple((int(m), str(s)) for m, s in serials.items()))

    @property
    def key(self) -> str:
        """``1=41001,2=41002,...``: the same arm gives the same key, on any machine."""
        return ",".join(f"{m}={s}" for m, s in self.serials)

    def by_module(self) -> dict[int, str]:
        return dict(self.serials)

    def describe(self) -> str:
        """``serials 1:41001, 2:41002, ...`` for the operator."""
        return "serials " + ", ".join(f"{m}:{s}" for m, s in self.serials)


class MotionRefused(Exception):
    """A joint refused a motion command mid-cycle (its answer said it refuses motion).

    Raised by :meth:`ArmDriver.cycle` as soon as that answer arrives, before the rest of
    the cycle is collected: the caller halts the arm at once, then asks why.
    """

    def __init__(self, module: int, state: CycleState) -> None:
        super().__init__(f"module {module}: refuses motion")
        self.module = module
        self.state = state


@dataclass
class CommandConfirmation:
    """What a confirmed stop (Halt) or Reset reached, module by module.

    ``sent``: the command left the driver at least once; ``confirmed``: every module read
    back that it took effect (Halt: HALTED; Reset: no fault left).
    """

    command: str                         # "halt" | "reset"
    modules: tuple[int, ...] = ()
    sent: bool = False
    #: Last state read from each module that answered.
    states: dict[int, JointState] = field(default_factory=dict)
    #: Modules that did not confirm -> why ("no answer", or "state ...").
    unconfirmed: dict[int, str] = field(default_factory=dict)
    attempts: int = 0
    #: Seconds from the first command on the wire to the last confirmation read.
    duration_s: float = 0.0
    error: str | None = None

    @property
    def confirmed(self) -> bool:
        return self.sent and not self.unconfirmed

    @property
    def modules_confirmed(self) -> tuple[int, ...]:
        return tuple(m for m in self.modules if m not in self.unconfirmed)

    @property
    def modules_unconfirmed(self) -> tuple[int, ...]:
        return tuple(m for m in self.modules if m in self.unconfirmed)

    def as_dict(self) -> dict[str, Any]:
        """``halt_sent``, ``halt_confirmed``, ... for a fault record."""
        return {"halt_sent": self.sent, "halt_confirmed": self.confirmed,
                "modules_not_halted": list(self.modules_unconfirmed),
                "halt_attempts": self.attempts,
                **({"halt_error": self.error} if self.error else {})}

    def describe_unconfirmed(self) -> str:
        return ", ".join(f"module {m} ({why})" for m, why in sorted(self.unconfirmed.items()))

    def describe(self, joint_names: Mapping[int, str] | None = None) -> str:
        """One line for the operator."""
        what = self.command.capitalize()
        if self.confirmed:
            return (f"{what} confirmed by every module ({len(self.modules_confirmed)}) "
                    f"after {self.attempts} attempt{'s' * (self.attempts != 1)}")
        names = joint_names or {}
        missing = ", ".join(f"{m} ({names[m]})" if m in names else str(m)
                            for m in self.modules_unconfirmed)
        if not self.sent:
            return (f"{what} could NOT be sent ({self.error}): the modules may still be "
                    "moving; use the emergency stop")
        text = f"{what} sent but NOT confirmed by module(s) {missing}"
        return text + (f" ({self.error})" if self.error else "")


#: The confirmation of an emergency Halt (the name the executor and the session use).
HaltConfirmation = CommandConfirmation

#: The commands a driver confirms by reading every module back.
ConfirmedCommand = Literal["halt", "reset", "home"]


class ForeignTraffic(Protocol):
    """A request on the bus that this process did not send: another master."""

    @property
    def is_halt(self) -> bool:
        """An emergency stop (``seqrun halt`` from another terminal), not a controller."""

    def message(self) -> str:
        """The one line the operator reads."""


@runtime_checkable
class ArmDriver(Protocol):
    """One arm behind its protocol. Modules are named by their ids (``modules``, joint
    order); ``None`` for a set of modules means every module (one broadcast where the
    protocol has one). Calls come from the executor's thread, except
    :meth:`halt_and_confirm`, which may come from any thread."""

    #: Module ids in joint order.
    modules: list[int]
    #: Flag names (of :meth:`CycleState.describe` and :attr:`JointState.text`) that mean a
    #: fault, and the one that means homed: what a face may read in a logged state text.
    FAULT_FLAGS: ClassVar[frozenset[str]]
    HOMED_FLAG: ClassVar[str]

    def use_arm(self, arm: ArmDescription) -> None:
        """From now on convert with ``arm`` (the same arm with the zero reference decided
        after connecting: the modules are asked first)."""

    def configure(self, *, cycle_s: float, run_limits: Limits, command_mode: str,
                  emit: EventSink) -> None:
        """Set the run's control period, its (speed-scaled) limits, its setpoint law and
        where driver events go; raises ValueError for an unknown ``command_mode``."""

    # -- reading
    def read(self) -> JointReading:
        """Position (user degrees) and cycle state of every joint (a lost read retried)."""

    def read_states(self, modules: Sequence[int] | None = None) -> dict[int, JointState]:
        """The full state of ``modules`` (None: all)."""

    def read_state(self, module: int) -> JointState:
        """The full state of one module."""

    # -- motion
    def start_motion(self, moving: list[int], limits: Limits, *,
                     command_mode: str | None = None) -> None:
        """A motion of the joints ``moving`` (indices) starts, planned within ``limits``:
        choose its setpoint law (``command_mode``, or the run's) and send what it needs
        once. Ends with :meth:`end_motion`."""

    def cycle(self, plan: MovePlan, t: float, moving: list[int],
              measured_deg: np.ndarray) -> JointReading:
        """One control cycle: setpoints of ``plan`` (user radians) at plan time ``t`` for
        ``moving``, and a reading of every joint. Raises :class:`MotionRefused` at the first answer
        that refuses motion; a lost answer to a motion command is a fault."""

    def end_motion(self) -> None:
        """The motion is over (or failed): back to the run's setpoint law."""

    # -- commands
    def reset(self, modules: Sequence[int] | None) -> None:
        """Clear the modules' error state."""

    def home(self, modules: Sequence[int] | None) -> None:
        """Home the modules (enable the motors)."""

    def halt(self, modules: Sequence[int] | None) -> None:
        """A deliberate stop (the sequence's ``halt`` step): modules refuse motion after."""

    def halt_and_confirm(self) -> CommandConfirmation:
        """The emergency stop: Halt every module before anything else, then read back
        that each one halted. Never raises; a failure is in the result. Any thread."""

    def halt_now(self, *, wait: bool = True) -> None:
        """The Halt broadcast at once, before anything queued is read; ``wait=False``: even
        while another thread's exchange holds the bus (an operator's STOP). Confirm it with
        :meth:`halt_and_confirm`. Raises :class:`~seqrun.errors.BusError`."""

    def confirm(self, command: ConfirmedCommand,
                modules: Sequence[int] | None = None) -> CommandConfirmation:
        """``seqrun halt|reset|home``: send ``command`` and confirm it on every module
        (None: all) by reading its state back. Halt and Reset are broadcast and repeated
        for the modules that did not confirm; Home is refused (nothing sent, ``error``
        says why) while a module is halted or in error, sent once (broadcast for the
        whole arm, else addressed) and confirmed when every module reports homed and at
        rest (a module may travel to its home switch first). Never raises for the bus."""

    # -- the arm outside a run (status, the zero decision)
    def identity(self) -> ArmIdentity:
        """What the modules say about themselves (serial numbers): which physical arm
        this is. Reads only, nothing moves; a lost answer asked again."""

    def poll(self, *, tolerate_loss: bool = False) -> ArmPoll:
        """Position, velocity and full state of every joint (reads only). A lost answer
        raises :class:`~seqrun.errors.BusError`, or with ``tolerate_loss`` leaves its
        joint None."""

    def homed(self) -> bool:
        """Every module reports homed (no power-on since the last start-up); reads only,
        a lost answer asked again."""

    def session_mark(self) -> int | None:
        """The power-session mark the drives hold (written by :meth:`write_session_mark`
        since they last powered on), None when they hold none, differ, or one cannot be
        told from a value that outlives a power cycle; reads only."""

    def write_session_mark(self, mark: int) -> bool:
        """Leave ``mark`` (1 .. SESSION_MARK_LIMIT - 1) in the drives' volatile memory,
        where a power cycle erases it, and read it back: False when the drives do not hold
        it (the caller treats every command as the first after a power-on)."""

    def watch_foreign(self, on_foreign: Callable[[ForeignTraffic], None]) -> None:
        """Call ``on_foreign`` for every request on the bus this process did not send."""

    def add_frame_listener(self, listener: Callable[[Any], None]) -> None:
        """``listener(frame)`` for every frame sent and received (the run log's trace)."""

    def remove_frame_listener(self, listener: Callable[[Any], None]) -> None: ...

    def describe_error(self, exc: BaseException) -> str:
        """``exc`` in the operator's words (a request that got no answer in user units)."""

    # -- limits held by the drives
    def read_limits(self) -> list[JointLimits]:
        """What every joint's drive holds (joint order, user units)."""

    def write_limits(self, values: Mapping[str, LimitValues]) -> int:
        """Write limits per joint name and read them back; raises RunAborted
        (``limits_not_written``) for a value that reads back different. Returns the
        number of values written."""

    # -- watchdog (a drive that stops by itself when its master goes silent)
    def enable_watchdog(self, alive: Callable[[float], bool]) -> None:
        """Arm the drives' watchdogs (if the arm file asks) and keep them fed while
        ``alive(within_s)`` says the control loop made progress within ``within_s``."""

    def stop_watchdog_keeper(self) -> None:
        """Stop feeding the watchdogs (after a fault: they stay armed)."""

    def disable_watchdog(self) -> None:
        """After a clean end: disarm the watchdogs; the arm keeps holding."""

    @property
    def closed(self) -> bool: ...

    def close(self) -> None:
        """Stop using the bus (the connection stays open: its owner closes it)."""


@runtime_checkable
class GripperDriver(Protocol):
    """A driver that also drives the arm file's gripper (optional: the executor refuses
    the gripper steps on a driver without these)."""

    def gripper_current_limit(self, current_a: float) -> float:
        """Write the gripper's current limit (its grip force) and read it back; returns
        what it reads. RunAborted (``limits_not_written``) when it differs, or without a
        gripper."""

    def gripper_move(self, width_mm: float, speed_mm_s: float) -> None:
        """Start the jaws towards ``width_mm`` at ``speed_mm_s``; RunAborted when the
        module refuses."""

    def gripper_read(self) -> GripperReading:
        """Width, velocity and state of the gripper."""


@runtime_checkable
class CurrentReader(Protocol):
    """A driver that reads its modules' actual motor current (optional: an expression that
    reads ``current_a`` is refused on a driver without it)."""

    def read_currents(self, modules: Sequence[int]) -> dict[int, float]:
        """The actual current of each module in ``modules``, in A (reads only)."""


class DriverFamily(Protocol):
    """What :mod:`seqrun.drivers.registry` asks of a driver class (no arm open yet)."""

    @classmethod
    def open(cls, arm: ArmDescription, connection: Any, *,
             response_timeout_s: float | None = None) -> ArmDriver:
        """The driver of ``arm`` on an open connection (:class:`seqrun.service.connection.
        Connection`: its ``bus``, ``clock``, ``echoes_own``)."""

    @staticmethod
    def cycle_state(code: int) -> CycleState:
        """A logged per-cycle state code (``int(CycleState)``) back as its state: what a
        report says of a run folder's ``state`` columns."""

    @classmethod
    def simulator_positions(cls, arm: ArmDescription,
                            joints_deg: Mapping[str, float]) -> dict[int, float]:
        """What the family's simulated drives read (by module id, in their units) while
        the arm stands at ``joints_deg``: where a dry run starts them."""
