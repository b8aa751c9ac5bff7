"""What a step handler may use of the executor: :class:`StepContext`.

A handler (``run(step, ex)`` of a step kind) does its bus work and safety checks through
these members only, so the executor's internals (stream, cycle, watchdog, driver) can
change behind them; ``tests/test_step_registry.py`` checks that the handlers use nothing
else and that the executor provides all of it. The executor is one implementation; a
second one (a console's single moves, a test double) implements the same members.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

if TYPE_CHECKING:
    import numpy as np

    from seqrun.arm.description import ArmDescription
    from seqrun.arm.joint_values import GripperReading, JointState, LimitValues
    from seqrun.arm.kinematics import Chain
    from seqrun.arm.trajectory_tolerances import TrajectoryTolerances
    from seqrun.arm.limits import LimitsInForce
    from seqrun.arm.planner import Limits

__all__ = ["ArmEvents", "AttendedQuestions", "JointReading", "StepContext"]

#: What an operator's question answers (yes/no, a name).
_Answer = TypeVar("_Answer")


class JointReading(Protocol):
    """One reading of the whole arm, as a handler sees it."""

    t: float
    user_deg: np.ndarray  # every joint, user degrees, arm order
    short_state: Mapping[int, Any]  # per module id: the state sent with the reading


class ArmEvents(Protocol):
    """The named events between the arms of a campaign run (signal, wait_for)."""

    def signal(self, name: str) -> None: ...

    def fired(self, name: str) -> bool: ...

    def never(self, name: str) -> str | None:
        """Why ``name`` can no longer come (the arm that would signal it has ended, the
        run is stopping), else None."""


class AttendedQuestions(Protocol):
    """The questions only a person at the run answers (never ``--yes``): a signed confirm,
    a breakpoint and a step's ``on_fail: pause``. None where nobody attends (a dry run passes through them)."""

    def sign(self, prompt: str, role: str | None) -> str | None:
        """Ask ``prompt``; the name of who answered yes (never empty), None for a no."""

    def breakpoint(self, prompt: str) -> bool:
        """Ask whether to go on; True to continue."""

    def choose(self, prompt: str, choices: tuple[str, ...]) -> str | None:
        """Ask for one of ``choices`` (a step's ``on_fail: pause``); None: no answer (the
        input ended, the question was withdrawn), taken as an abort."""


class HazardOfStep(Protocol):
    """A step's hazard class as the validation found it (what a handler reads of it)."""

    @property
    def hazard(self) -> str: ...

    @property
    def speed_scale(self) -> float: ...


class StepContext(Protocol):
    """The executor as a step handler sees it."""

    # -- what the run is about (read only for handlers)
    arm: ArmDescription
    chain: Chain                        # the arm's kinematic chain (forward kinematics)
    poses: Mapping[str, Any]            # the poses frozen with the sequence (name -> FrozenPose)
    speed: float                        # the run's speed override, (0, 1]
    movable: list[int]                  # indices of the joints that are not locked
    dry_run: bool
    #: Asked at a confirm step (None: nobody to ask, a dry run assumes yes).
    confirm: Callable[[str], bool] | None
    #: Asked at a signed confirm and a breakpoint (None: nobody attends, a dry run).
    attended: AttendedQuestions | None
    #: The sha256 of the validated inputs (a signature names what it signed; None: a
    #: dry run, nothing recorded).
    inputs_sha256: str | None
    #: Joint solutions validated from the measured start (step number -> user degrees).
    validated_targets: Mapping[int, np.ndarray]
    #: The steps of class caution or hazardous as validated from the measured start
    #: (step number -> their class: its speed cap, docs/safety.md "Hazard classes").
    @property
    def hazards(self) -> Mapping[int, HazardOfStep]: ...

    # -- state a handler reads or updates
    limits_in_force: LimitsInForce      # MaxVel/MaxAcc the modules hold (set_limits writes)
    motion_start_deg: np.ndarray | None  # measured joints where the last move started
    commanded_deg: np.ndarray | None    # what the joints were last told (None after a halt)
    not_verified: list[str]             # what a dry run could not check, for the report
    #: Records the zero reference at a power_off step (None: a dry run or the built-in
    #: simulator, nothing is recorded).
    record_zero: Callable[[str], Any] | None
    #: The events between the arms of a campaign run (None: one arm).
    sync: ArmEvents | None

    # -- the drives, in joint terms (``modules=None``: all of them at once), faults checked
    def reset_modules(self, modules: list[int] | None) -> None: ...

    def home_modules(self, modules: list[int] | None) -> None: ...

    def halt_modules(self, modules: list[int] | None) -> None: ...

    def write_limits(self, values: dict[str, LimitValues]) -> int: ...

    def read_arm(self) -> JointReading: ...

    def monitor(self) -> JointReading: ...

    def wait_for_states(self, modules: list[int] | None, ok: Callable[[JointState], bool],
                        timeout_s: float, failure: str) -> dict[int, JointState]: ...

    def refresh_measurement(self, after: str,
                            words: dict[int, JointState] | None = None) -> None: ...

    def confirm_clearing_latched(self, modules: list[int] | None) -> None: ...

    # -- motion
    # ``start``: the reading the target was found from (read_arm); the move plans from it
    # instead of reading the arm again.
    def move(self, target_deg: np.ndarray, active: list[int], limits: Limits, *,
             tolerance_deg: float, timeout_s: float | None,
             start: JointReading | None = None) -> dict[str, Any]: ...

    def follow(self, plan: Any, *, tolerance_deg: float, timeout_s: float | None,
               path_check: Callable[[Any], None] | None = None,
               command_mode: str | None = None,
               start: JointReading | None = None,
               tolerances: TrajectoryTolerances | None = None) -> dict[str, Any]: ...

    def wait(self, seconds: float) -> None: ...

    def elapsed_s(self) -> float: ...

    def wait_in_position(self, tolerance_deg: float, timeout_s: float) -> float: ...

    # -- the gripper (the arm file's ``gripper``), in mm and A
    def gripper_current_limit(self, current_a: float) -> float: ...

    def gripper_move(self, width_mm: float, speed_mm_s: float) -> None: ...

    def gripper_read(self) -> GripperReading: ...

    # -- the joints' actual motor current (A), read when asked (not in the control loop)
    def joint_currents_a(self, joints: Sequence[int]) -> list[float | None]: ...

    # -- the operator and the record
    def ask_operator(self, question: Callable[[Any], _Answer], arg: Any) -> _Answer: ...

    def emit(self, type_: str, **data: Any) -> None: ...
