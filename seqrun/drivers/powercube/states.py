"""PowerCube state words and short states, decoded into the seam's joint-level types.

The state word (CubeState, 32 bits) becomes a :class:`~seqrun.drivers.base.JointState`
(homed, halted, faulted, the most specific fault named); the short state byte of every
reading (:class:`~seqrun.powercube.protocol.ShortState`) is already a
:class:`~seqrun.drivers.base.CycleState`. Pure.
"""

from __future__ import annotations

from seqrun.arm.joint_values import JointState
from seqrun.drivers.base import CycleState
from seqrun.powercube.protocol import ShortState, StateFlag

#: Most specific first: the cause named in the report.
FAULT_CAUSES = ("TOW_ERROR", "BEYOND_HARD", "BEYOND_SOFT", "POWERFAULT", "COMM_ERROR",
                "CPU_OVERLOAD", "HALTED", "ERROR")

#: Flag names (of a state word or a short state) that mean the joint is at fault.
FAULT_FLAGS = frozenset(
    {name for name, flag in StateFlag.__members__.items() if flag & StateFlag.FAULTS}
    | {"NOT_OK"})

#: The flag name of a homed module (a state word's).
HOMED_FLAG = "HOME_OK"


def short_state(flags: StateFlag) -> ShortState:
    """The short state a module would report for this state word (table B.3)."""
    short = ShortState(0)
    if flags & (StateFlag.ERROR | StateFlag.HALTED) or not flags & StateFlag.HOME_OK:
        short |= ShortState.NOT_OK
    if flags & StateFlag.MOTION:
        short |= ShortState.MOTION
    if flags & StateFlag.RAMP_END:
        short |= ShortState.RAMP_END
    return short


def joint_state(flags: StateFlag | int) -> JointState:
    """A module's state word, decoded."""
    flags = StateFlag(flags)
    faults = StateFlag(flags & StateFlag.FAULTS)
    cause = next((name.lower() for name in FAULT_CAUSES if faults & StateFlag[name]),
                 "not_homed")
    return JointState(homed=bool(flags & StateFlag.HOME_OK),
                      halted=bool(flags & StateFlag.HALTED),
                      moving=bool(flags & StateFlag.MOTION),
                      faulted=bool(faults), cause=cause, text=flags.describe(),
                      fault_text=faults.describe() if faults else "",
                      cycle_code=int(short_state(flags)))


def cycle_state(code: int) -> CycleState:
    """A logged per-cycle state code (the short state byte) back as the state it was."""
    return ShortState(code)
