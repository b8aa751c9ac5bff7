"""checkpoint: forward kinematics of the measured joints against an expected pose."""

from __future__ import annotations

import math

import numpy as np

from seqrun import kinematics
from seqrun.errors import RunAborted
from seqrun.validation import format_number, resolve_checkpoint


def run(step, ex) -> dict:
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
