"""checkpoint: forward kinematics of the measured joints against an expected pose."""

from __future__ import annotations

import math

import numpy as np

from seqrun import kinematics
from seqrun.errors import RunAborted
from seqrun.validation import format_number, resolve_checkpoint


def run(step, ex) -> dict:
    if getattr(step.params, "moved_mm", None) is not None:
        return _relative(step, ex)
    position, rotation, pos_tol, ang_tol = resolve_checkpoint(step.params, ex.arm, ex.poses)
    measured = ex.monitor()
    T = kinematics.fk(ex.chain, np.radians(measured.user_deg))
    reached = T[:3, 3]
    pos_err = float(np.linalg.norm(reached - np.asarray(position)))
    ang_err = math.degrees(float(kinematics.orientation_error(np.asarray(rotation), T[:3, :3])))
    detail = {
        "expected_position_mm": [round(float(x), 3) for x in position],
        "reached_position_mm": [round(float(x), 3) for x in reached],
        "reached_rpy_deg": [round(float(x), 3)
                            for x in np.degrees(kinematics.rpy_from_matrix(T[:3, :3]))],
        "position_error_mm": round(pos_err, 3), "angle_error_deg": round(ang_err, 4),
        "position_tolerance_mm": pos_tol, "angle_tolerance_deg": ang_tol,
    }
    ex.emit("checkpoint", **detail)
    if pos_err > pos_tol or ang_err > ang_tol:
        raise RunAborted("checkpoint",
                         f"checkpoint failed: end-effector {format_number(pos_err)} mm "
                         f"(tolerance {format_number(pos_tol)} mm) and "
                         f"{format_number(ang_err)}° (tolerance {format_number(ang_tol)}°) "
                         "from the expected pose",
                         detail=detail)
    return detail


def _relative(step, ex) -> dict:
    """'The tool moved [x, y, z] mm' since the last move started (measured joints)."""
    from seqrun.cartesian import displacement, solver_for, tool_pose

    params = step.params
    measured = ex.monitor()
    if ex.motion_start_deg is None:
        raise RunAborted("checkpoint", "relative checkpoint: no move before it in this run")
    solver = solver_for(ex.arm, params.tool)
    moved = displacement(tool_pose(solver, ex.motion_start_deg),
                         tool_pose(solver, measured.user_deg), params.frame)
    off = float(np.linalg.norm(moved - np.asarray(params.moved_mm)))
    detail = {"expected_moved_mm": [round(float(x), 3) for x in params.moved_mm],
              "moved_mm": [round(float(x), 3) for x in moved], "frame": params.frame,
              "displacement_error_mm": round(off, 3),
              "position_tolerance_mm": params.position_tolerance_mm}
    ex.emit("checkpoint", **detail)
    if off > params.position_tolerance_mm:
        raise RunAborted("checkpoint",
                         f"relative checkpoint failed: the tool moved {detail['moved_mm']} mm "
                         f"({params.frame} frame), {off:.3f} mm from the expected "
                         f"{detail['expected_moved_mm']} (tolerance "
                         f"{params.position_tolerance_mm} mm)", detail=detail)
    return detail
