"""move: one synchronized ruckig motion to a pose or to joint angles."""

from __future__ import annotations

import numpy as np

from seqrun.planner import Limits
from seqrun.validation import resolve_move_target


def run(step, ex) -> dict:
    params = step.params
    if getattr(params, "position_mm", None) is not None:  # an end-effector target
        from seqrun.steps.move_tool import run_pose

        return run_pose(step, ex)
    current = ex.read_arm()
    current_deg = {j.name: float(v) for j, v in zip(ex.arm.joints, current.user_deg)}
    # The pose as it was validated (frozen when the sequence was loaded), never the file now.
    target = resolve_move_target(params, current_deg, ex.arm, ex.poses)
    target_deg = np.array([target[j.name] for j in ex.arm.joints])
    named = set(ex.arm.joint_names) if params.pose is not None else set(params.joints or {})
    active = [i for i in ex.movable if ex.arm.joints[i].name in named]
    velocity, acceleration = ex.limits_in_force.maxima()
    limits = Limits.from_arm(ex.arm, velocity_scale=params.velocity_scale,
                             acceleration_scale=params.acceleration_scale, speed=ex.speed,
                             velocity_deg_s=params.velocity_deg_s,
                             max_velocity_deg_s=velocity, max_acceleration_deg_s2=acceleration)
    tolerance = params.tolerance_deg or ex.arm.control.position_tolerance_deg
    detail = ex.move(target_deg, active, limits, tolerance_deg=tolerance,
                     timeout_s=params.timeout_s)
    # Which limits bound the plan, and where they come from (report, dry-run table).
    narrowed = ex.limits_in_force.narrowed([ex.arm.joints[i].name for i in active])
    if narrowed:
        detail["limits_in_force"] = narrowed
    else:
        detail["limits_from"] = "arm file"
    return detail
