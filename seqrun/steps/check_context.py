"""What a step kind's static check may use of the validator: :class:`CheckContext`.

A kind's ``check(checker, step, params)`` reads and updates the state the checks share
while the validator walks the steps (the tracked joints and modules, the limits in force,
the findings) and calls the checks more than one kind needs, through these members only.
:class:`seqrun.sequence.validation.Checker` is the implementation; the kinds never import
it, so the validator may import the kinds. ``tests/test_step_registry.py`` checks that the
checks use nothing else and that the Checker provides all of it (as
:class:`~seqrun.steps.context.StepContext` is the executor for a handler).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    import numpy as np

    from seqrun.arm.description import ArmDescription, Joint
    from seqrun.arm.ik import IkSolver
    from seqrun.arm.limits import LimitsInForce
    from seqrun.errors import SourceError
    from seqrun.steps.params import ToolParams, ToolTargetParams
    from seqrun.steps.resolved import FrozenPose, ResolvedStep

__all__ = ["CheckContext", "PlannedMoveParams", "TrackedJoint"]


@dataclass
class TrackedJoint:
    """What the checks know of one joint after the steps so far."""

    joint: Joint
    position: float
    reset: bool = False
    homed: bool = False
    halted: bool = False
    limits: tuple[float, float] | None = None  # written MinPos/MaxPos
    at_start: bool = True  # still at its start position (for the wording of notes)

    @property
    def locked(self) -> bool:
        return self.joint.locked is not None


class PlannedMoveParams(Protocol):
    """What planning a move along its guards reads of the move's parameters."""

    @property
    def velocity_scale(self) -> float: ...

    @property
    def acceleration_scale(self) -> float: ...

    @property
    def velocity_deg_s(self) -> Mapping[str, float]: ...


class CheckContext(Protocol):
    """The validator as a step kind's check sees it."""

    # -- what is checked against (read only for checks)
    arm: ArmDescription
    poses: Mapping[str, FrozenPose]     # the poses frozen with the sequence
    speed: float                        # the run's speed override: the plans are checked at it
    #: A step left out before (it failed on its own) may have changed the modules'
    #: start-up state: the start-up order (reset, home, limits, halt) is not checked.
    incomplete: bool
    #: A step left out before may have moved the arm: what depends on where the joints are
    #: is not checked until a move to absolute targets of every joint says it again.
    position_unknown: bool
    # -- the state the steps so far leave (a check reads it and updates it)
    joints: dict[str, TrackedJoint]     # by joint name, arm order
    file_limits: LimitsInForce          # the limits the files set (exceeding them: an error)
    limits: LimitsInForce               # ... and what the modules hold (moves planned within)
    motion_start_deg: np.ndarray | None  # where the last move started (user degrees)
    #: The step after which where the arm stands is not known (its target unreachable,
    #: outside the limits): a check comparing with the tracked joints says nothing.
    lost_at: ResolvedStep | None
    powered_off: ResolvedStep | None    # the power_off step, once there is one
    #: The arm's id in a campaign with several arms (None: the one arm; signal and
    #: wait_for have nobody to talk to).
    arm_id: str | None
    #: Per pose: the joints outside the arm's limits and the finding at the pose file's line.
    pose_limit_findings: dict[str, dict[str, SourceError]]
    # -- the findings, each at the file:line:col of the value it is about
    errors: list[SourceError]
    notes: list[SourceError]

    # -- the checks more than one kind needs
    def hazard_speed_scale(self, step: ResolvedStep) -> float:
        """The speed cap of the step's hazard class (given, or derived from its planned
        clearance so far); 1.0: none."""
        ...

    def pose(self, step: ResolvedStep, name: str, *,
             target: bool) -> dict[str, float] | None: ...

    def names(self, step: ResolvedStep, names: list[str] | Mapping[str, Any], path: tuple,
              *, as_keys: bool, what: str) -> list[str]: ...

    def modules(self, step: ResolvedStep, joints: str | list[str]) -> list[TrackedJoint]: ...

    def which(self, names: list[str], of: list[str] | None = None) -> str: ...

    def after_halt(self, step: ResolvedStep, what: str) -> None: ...

    def motion_allowed(self, step: ResolvedStep, names: list[str]) -> None: ...

    def guards_along_plan(self, step: ResolvedStep, params: PlannedMoveParams,
                          target: dict[str, float]) -> None: ...

    def check_path_guards(self, step: ResolvedStep, times: np.ndarray, path_rad: np.ndarray,
                          *, what: str) -> None: ...

    def tool_target(self, step: ResolvedStep, params: ToolTargetParams) -> np.ndarray | None: ...

    def tool_solver(self, step: ResolvedStep, params: ToolParams) -> IkSolver | None: ...

    def tracked(self) -> np.ndarray: ...

    def unlocked_names(self) -> list[str]: ...

    def outside_limits(self, step: ResolvedStep, joints_deg: np.ndarray, what: str) -> bool: ...

    def arrive(self, step: ResolvedStep, joints_deg: np.ndarray) -> None: ...

    def solution_note(self, step: ResolvedStep, joints_deg: np.ndarray,
                      extra: str = "") -> None: ...
