"""End-effector targets at run time, shared by ``move`` (to a tool pose) and ``move_linear``.

Both solve from the *measured* joints (a relative target is relative to where the tool
really is) and compare the result with what validation solved from the tracked joints:
further apart than the arm's ``cartesian.ik_agreement_deg`` is a fault, never a surprise
motion.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from seqrun.arm.cartesian import resolve_target, solver_for, tool_pose
from seqrun.errors import RunAborted
from seqrun.arm.ik import Unreachable
from seqrun.arm.planner import Limits

if TYPE_CHECKING:
    from seqrun.sequence.loader import ResolvedStep
    from seqrun.steps.context import StepContext
    from seqrun.steps.move import MoveParams
    from seqrun.steps.move_linear import MoveLinearParams


def tool_target(step: ResolvedStep[MoveParams | MoveLinearParams], ex: StepContext,
                measured_deg: np.ndarray) -> np.ndarray:
    """The step's tool target (4x4) from the measured joints."""
    params = step.params
    # (move_linear always has position_mm; a move comes here only when it has one)
    assert params.position_mm is not None
    current = tool_pose(solver_for(ex.arm, params.tool), measured_deg)
    return resolve_target(current, params.position_mm, params.rpy_deg,
                          relative=params.relative, frame=params.frame)


def agree(step: ResolvedStep[MoveParams | MoveLinearParams], ex: StepContext,
          joints_deg: np.ndarray) -> dict:
    """Fault if the run's solution is not the validated one."""
    validated = ex.validated_targets.get(step.number)
    detail: dict[str, Any] = {"ik_solution_deg": [round(float(v), 3) for v in joints_deg]}
    if validated is None:
        return detail
    difference = np.abs(np.asarray(joints_deg) - validated)
    worst = int(np.argmax(difference))
    bound = ex.arm.cartesian.ik_agreement_deg
    if difference[worst] > bound:
        name = ex.arm.joints[worst].name
        raise RunAborted("ik_mismatch",
                         f"the end-effector target solved from the measured joints puts {name} "
                         f"at {joints_deg[worst]:.2f}°, {difference[worst]:.2f}° from the "
                         f"validated {validated[worst]:.2f}° (allowed {bound:g}°)",
                         module=ex.arm.joints[worst].module)
    detail["ik_difference_deg"] = round(float(difference[worst]), 4)
    return detail


def run_pose(step: ResolvedStep[MoveParams], ex: StepContext) -> dict:
    """``move`` with position_mm: IK from the measured joints, then an ordinary move."""
    params = step.params
    reading = ex.read_arm()
    measured = reading.user_deg
    try:
        solution = solver_for(ex.arm, params.tool).solve(tool_target(step, ex, measured), measured)
    except Unreachable as exc:
        raise RunAborted("unreachable", f"end-effector target {exc}") from None
    detail = agree(step, ex, solution.joints_deg)
    limits = Limits.from_arm(ex.arm, velocity_scale=params.velocity_scale,
                             acceleration_scale=params.acceleration_scale, speed=ex.speed,
                             velocity_deg_s=params.velocity_deg_s)
    tolerance = params.tolerance_deg or ex.arm.control.position_tolerance_deg
    ex.emit("ik_solved", joints_deg=detail["ik_solution_deg"])
    metrics = ex.move(solution.joints_deg, list(ex.movable), limits, tolerance_deg=tolerance,
                      timeout_s=params.timeout_s, start=reading)
    return {**detail, **metrics}
