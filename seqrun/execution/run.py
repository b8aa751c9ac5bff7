"""The run as its parts see it: :class:`Run` (the executor's members the preflight, the
stream and the endings use), :class:`Measurement` (one reading of the arm) and how the
event log rounds numbers.

The parts name this protocol, not the executor, so the executor imports its parts and
nothing imports it back; ``tests/test_architecture.py`` holds the parts to its public
members.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.arm.limits import LimitsInForce
    from seqrun.arm.planner import Limits
    from seqrun.clock import Clock
    from seqrun.arm.joint_values import JointState
    from seqrun.drivers.base import ArmDriver, CycleState, HaltConfirmation
    from seqrun.events import EventHub
    from seqrun.execution.checks import ReadingChecks
    from seqrun.execution.latched import LatchedFaults
    from seqrun.execution.stops import StopControl
    from seqrun.results import RunResult, StepResult


def rounded(a, nd: int = 3) -> list[float]:
    """Floats of ``a`` rounded for the event log (a numpy array via tolist(): iterating it
    would make a numpy scalar per element, several times a cycle)."""
    return [round(float(x), nd) for x in (a.tolist() if isinstance(a, np.ndarray) else a)]


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
    #: Where each joint comes to rest if no command follows (the driver's
    #: ``JointReading.holds_at_rad``); None: not known or not bounded.
    holds_at_rad: np.ndarray | None = None

    @property
    def at(self) -> float:
        """The reading's time: when the joints answered (their mean) where known."""
        return self.t if self.answered_at is None else float(self.answered_at.mean())


class Run(Protocol):
    """The executor as its parts see it (seqrun/executor.py implements it)."""

    # -- what the run is about
    arm: ArmDescription
    modules: list[int]
    movable: list[int]
    cycle: float
    command_mode: str
    limits: Limits
    speed: float
    clock: Clock
    driver: ArmDriver
    events: EventHub
    # -- its state
    last: Measurement | None
    commanded_deg: np.ndarray | None
    #: The plan's position at this cycle while a plan streams (None: none streams).
    setpoint_deg: np.ndarray | None
    motion_start_deg: np.ndarray | None
    current_step: StepResult | None
    halt_result: HaltConfirmation | None
    interrupted_result: RunResult | None
    not_verified: list[str]
    bus_retries: int
    validated_targets: dict[int, np.ndarray]
    planned_paths: dict[int, Any] | None
    hazards: dict[int, Any]
    limits_in_force: LimitsInForce
    # -- its other parts
    latched: LatchedFaults
    stops: StopControl
    checks: ReadingChecks

    def emit(self, type_: str, **data: Any) -> None: ...

    def beat(self) -> None: ...

    def idle(self, seconds: float) -> None: ...

    def since_start(self, t: float) -> float: ...

    def idle_until(self, t: float) -> None: ...

    def elapsed_s(self) -> float: ...

    def read_arm(self) -> Measurement: ...

    def take_reading(self, reading: Any) -> Measurement: ...

    def read_state_words(self, modules: list[int] | None = None) -> dict[int, JointState]: ...

    def check_states(self, m: Measurement, *, require_homed: bool = True) -> None: ...

    def check_guards(self, m: Measurement) -> None: ...

    def check_halt_request(self) -> None: ...

    def monitor(self) -> Measurement: ...

    def states_of(self, m: Measurement) -> list[int]: ...

    def emergency_halt(self) -> bool: ...

    def refresh_measurement(self, after: str,
                            words: dict[int, JointState] | None = None) -> None: ...

    def describe_error(self, exc: BaseException) -> str: ...

    def tracking_figures(self, target_deg: Any = None) -> dict[str, Any]: ...

    def ask_operator(self, question: Callable[[Any], bool], arg: Any) -> bool: ...
