"""End-effector targets at run time, shared by ``move`` (to a tool pose) and ``move_linear``.

Both solve from the *measured* joints (a relative target is relative to where the tool
really is) and compare the result with what validation solved from the tracked joints:
further apart than the arm's ``cartesian.ik_agreement_deg`` is a fault, never a surprise
motion. The parameters are read through :class:`~seqrun.steps.params.ToolTargetParams`,
what both kinds' models have in common.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from seqrun.arm.cartesian import resolve_target, solver_for, tool_pose
from seqrun.errors import RunAborted

if TYPE_CHECKING:
    from seqrun.steps.context import StepContext
    from seqrun.steps.params import ToolTargetParams
    from seqrun.steps.resolved import ResolvedStep


def tool_target(params: ToolTargetParams, ex: StepContext,
                measured_deg: np.ndarray) -> np.ndarray:
    """The step's tool target (4x4) from the measured joints."""
    # (move_linear always has position_mm; a move comes here only when it has one)
    assert params.position_mm is not None
    current = tool_pose(solver_for(ex.arm, params.tool), measured_deg)
    return resolve_target(current, params.position_mm, params.rpy_deg,
                          relative=params.relative, frame=params.frame)


def agree(step: ResolvedStep, ex: StepContext, joints_deg: np.ndarray) -> dict:
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

