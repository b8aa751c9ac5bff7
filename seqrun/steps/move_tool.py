"""End-effector targets at run time: ``move`` to a tool pose and ``move_linear``.

Both solve from the *measured* joints (a relative target is relative to where the tool
really is) and compare the result with what validation solved from the tracked joints:
further apart than the arm's ``cartesian.ik_agreement_deg`` is a fault, never a surprise
motion.
"""

from __future__ import annotations

import numpy as np

from seqrun.cartesian import PathError, plan_linear, resolve_target, solver_for, tool_pose
from seqrun.errors import RunAborted
from seqrun.ik import Unreachable
from seqrun.planner import Limits


def _target(step, ex, measured_deg: np.ndarray) -> np.ndarray:
    params = step.params
    current = tool_pose(solver_for(ex.arm, params.tool), measured_deg)
    return resolve_target(current, params.position_mm, params.rpy_deg,
                          relative=params.relative, frame=params.frame)


def _agree(step, ex, joints_deg: np.ndarray) -> dict:
    """Fault if the run's solution is not the validated one."""
    validated = ex.validated_targets.get(step.number)
    detail: dict[str, object] = {"ik_solution_deg": [round(float(v), 3) for v in joints_deg]}
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


def run_pose(step, ex) -> dict:
    """``move`` with position_mm: IK from the measured joints, then an ordinary move."""
    params = step.params
    measured = ex.read_arm().user_deg
    try:
        solution = solver_for(ex.arm, params.tool).solve(_target(step, ex, measured), measured)
    except Unreachable as exc:
        raise RunAborted("unreachable", f"end-effector target {exc}") from None
    detail = _agree(step, ex, solution.joints_deg)
    limits = Limits.from_arm(ex.arm, velocity_scale=params.velocity_scale,
                             acceleration_scale=params.acceleration_scale, speed=ex.speed,
                             velocity_deg_s=params.velocity_deg_s)
    tolerance = params.tolerance_deg or ex.arm.control.position_tolerance_deg
    ex.emit("ik_solved", joints_deg=detail["ik_solution_deg"])
    metrics = ex.move(solution.joints_deg, list(ex.movable), limits, tolerance_deg=tolerance,
                      timeout_s=params.timeout_s)
    return {**detail, **metrics}


def run_linear(step, ex) -> dict:
    """``move_linear``: the line solved from the measured joints, streamed sample by
    sample; the tool's distance from the line is checked every cycle."""
    params = step.params
    measured = ex.read_arm().user_deg
    keep = 1 - ex.arm.control.tracking_reserve
    max_velocity = np.array([j.max_velocity_deg_s for j in ex.arm.joints]) * keep * ex.speed
    try:
        linear = plan_linear(ex.arm, params.tool, measured, _target(step, ex, measured),
                             speed_mm_s=params.speed_mm_s * ex.speed,
                             rotation_speed_deg_s=params.rotation_speed_deg_s * ex.speed,
                             acceleration_mm_s2=params.acceleration_mm_s2 * ex.speed,
                             jerk_mm_s3=params.jerk_mm_s3 * ex.speed,
                             max_velocity_deg_s=max_velocity)
    except PathError as exc:
        raise RunAborted("linear_path", f"straight line: {exc}") from None
    detail = _agree(step, ex, linear.joints_deg[-1])
    solver = solver_for(ex.arm, params.tool)
    path, limit = linear.path, params.max_deviation_mm
    worst = {"mm": 0.0}

    def deviation(m) -> None:
        off = float(path.deviation_mm(tool_pose(solver, m.user_deg)[:3, 3]))
        worst["mm"] = max(worst["mm"], off)
        if off > limit:
            raise RunAborted("path_deviation",
                             f"the tool is {off:.2f} mm off the straight line (allowed "
                             f"{limit:g} mm)", detail={"max_deviation_mm": round(off, 3)})

    tolerance = params.tolerance_deg or ex.arm.control.position_tolerance_deg
    ex.emit("ik_solved", joints_deg=detail["ik_solution_deg"], samples=len(linear.plan.times),
            length_mm=round(path.length_mm, 3))
    metrics = ex.follow(linear.plan, tolerance_deg=tolerance, timeout_s=params.timeout_s,
                        path_check=deviation, command_mode=ex.arm.cartesian.linear_command_mode)
    return {**detail, **metrics, "length_mm": round(path.length_mm, 3),
            "max_deviation_mm": round(worst["mm"], 4),
            "min_manipulability": round(linear.min_manipulability, 4)}
