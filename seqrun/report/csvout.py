"""CSV export of a run's time series (``seqrun report RUN_DIR --csv DIR``).

``timeseries.csv``, one row per reading of the arm (every control cycle of a move, every
monitoring cycle of a wait or checkpoint), full resolution:

==========================  ================================================================
``t_s``                     seconds since the run start, when the joints answered (read_t)
``step``                    step number
``streamed``                1 when a plan was being streamed (a move), else 0
``<j>_planned_deg``         planned position (empty when nothing was streamed)
``<j>_measured_deg``        measured position
``<j>_planned_vel_deg_s``   planned velocity (empty when nothing was streamed)
``<j>_measured_vel_deg_s``  windowed estimate (seqrun/arm/tracking.py; empty for the first
                            samples of the run)
``<j>_state``               the module's state in its driver's words (``MOTION|RAMP_END``,
                            ``OK``, ...)
``ee_x_mm`` … ``ee_yaw_deg``  end-effector pose by forward kinematics of the measured joints
==========================  ================================================================

``steps.csv``: one row per step with planned and executed duration and, for moves, the
per-joint tracking figures (``<j>_max_following_error_deg`` ...).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

from seqrun.drivers.registry import cycle_state
from seqrun.report.data import RunData
from seqrun.report.figures import end_effector_pose, move_figures

_POSE = ("ee_x_mm", "ee_y_mm", "ee_z_mm", "ee_roll_deg", "ee_pitch_deg", "ee_yaw_deg")
_STEP_FIGURES = ("max_following_error_deg", "final_error_deg", "peak_measured_velocity_deg_s")


def export_csv(data: RunData, out_dir: str | Path) -> list[Path]:
    """Write timeseries.csv and steps.csv into ``out_dir`` (created); returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [_timeseries(data, out / "timeseries.csv"), _steps(data, out / "steps.csv")]


def _timeseries(data: RunData, path: Path) -> Path:
    """One row per reading, written a chunk of readings at a time (events.jsonl streamed
    once more, never held whole)."""
    names = data.joint_names
    header = ["t_s", "step", "streamed"]
    for kind in ("planned_deg", "measured_deg", "planned_vel_deg_s", "measured_vel_deg_s",
                 "state"):
        header += [f"{n}_{kind}" for n in names]
    if data.arm is not None:
        header += list(_POSE)
    states: dict[int, str] = {}
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(header)
        for s in data.readings():
            pose = end_effector_pose(data.arm, s.measured) if data.arm is not None else None
            for k in range(len(s)):
                row = [f"{s.t[k]:.6f}", int(s.step[k]), int(s.streamed[k])]
                row += [_f(x, 3) for x in s.planned[k]]
                row += [_f(x, 3) for x in s.measured[k]]
                row += [_f(x, 2) for x in s.planned_vel[k]]
                row += [_f(x, 3) for x in s.measured_vel[k]]
                for code in s.state[k]:
                    code = int(code)
                    if code not in states:
                        states[code] = "" if code < 0 else cycle_state(data.arm, code).describe()
                    row.append(states[code])
                if pose is not None:
                    row += [_f(x, 3) for x in pose[k]]
                w.writerow(row)
    return path


def _steps(data: RunData, path: Path) -> Path:
    names = data.joint_names
    header = ["step", "kind", "label", "status", "planned_duration_s", "executed_duration_s"]
    for key in _STEP_FIGURES:
        header += [f"{n}_{key}" for n in names]
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(header)
        for step in data.steps:
            figures = move_figures(data, step)[0] if step.kind == "move" else {}
            executed = step.detail.get("executed_duration_s", step.duration_s)
            row = [step.number, step.kind, step.label, step.status,
                   _f(step.planned_duration_s, 4), _f(executed, 4)]
            for key in _STEP_FIGURES:
                values = figures.get(key) or [None] * len(names)
                row += [_f(v, 3) for v in values]
            w.writerow(row)
    return path


def _f(x, nd: int) -> str:
    if x is None:
        return ""
    x = float(x)
    if math.isnan(x):
        return ""
    text = f"{x:.{nd}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text


__all__ = ["export_csv"]
