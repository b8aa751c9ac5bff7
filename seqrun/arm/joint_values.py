"""What a joint's drive reports and is given, decoded and in the user's units: the full
state of a joint, the limits it holds or is to hold, a reading of the gripper.

Plain values every layer shares: a driver (:mod:`seqrun.drivers`) makes them from its
protocol, the executor checks them, a step kind reads or writes them through the executor.
The calls that produce them are the driver's (:class:`seqrun.drivers.base.ArmDriver`).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class JointState:
    """The full state of one joint's drive, decoded by its driver."""

    homed: bool
    halted: bool
    moving: bool
    #: Any fault that stops the joint or makes it refuse motion (halted included).
    faulted: bool
    #: The most specific fault, for the report (``tow_error``, ``beyond_soft``, ...);
    #: ``not_homed`` when none is named.
    cause: str
    #: Every flag by the drive's own names (``HOME_OK|RAMP_END``), for the operator.
    text: str
    #: Only the fault flags by the drive's names ('' when there is none).
    fault_text: str = ""
    #: The code this state shows in a reading (the driver's ``CycleState``; event log).
    cycle_code: int = 0

    @property
    def ready(self) -> bool:
        """Homed and free of faults: the joint accepts motion."""
        return self.homed and not self.faulted

    def describe(self) -> str:
        return self.text


@dataclass(frozen=True)
class JointLimits:
    """The limits a joint's drive holds, in user units (deg, deg/s, deg/s^2, A)."""

    min_deg: float
    max_deg: float
    max_velocity_deg_s: float
    max_acceleration_deg_s2: float
    #: The current limit (MaxCur), A; None: a driver that does not read it.
    max_current_a: float | None = None


@dataclass(frozen=True)
class LimitValues:
    """Limits to write to one joint, user units (deg, deg/s, deg/s^2, A); None: left as
    is."""

    min_deg: float
    max_deg: float
    max_velocity_deg_s: float | None = None
    max_acceleration_deg_s2: float | None = None
    max_current_a: float | None = None


@dataclass(frozen=True)
class GripperReading:
    """One reading of the gripper, in the user's units (mm, mm/s)."""

    width_mm: float
    velocity_mm_s: float
    #: The drive reports motion (it may still push against a part at zero velocity).
    moving: bool
    #: The motor is at its current limit (CURLIMIT): it pushes against something.
    at_current_limit: bool
    #: A fault bit is set (ERROR, HALTED, a power or limit fault): the drive refuses motion.
    faulted: bool
    #: HOME_OK: a module powers on not homed (brake on) and is homed with the arm's Home;
    #: not homed is no fault, but the drive refuses motion until then.
    homed: bool
    #: Every state flag by the drive's names, for the operator.
    text: str

    @property
    def ready(self) -> bool:
        """Homed and not faulted: the drive accepts a motion."""
        return self.homed and not self.faulted
