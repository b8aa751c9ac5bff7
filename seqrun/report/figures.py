"""What the report computes from a loaded run (pure: arrays in, arrays and dicts out).

The per-move figures are recomputed here with the same definitions the executor uses
(:mod:`seqrun.arm.tracking`), from the logged samples of the step: they fill in what
report.json lacks (a move ended by a fault in an older version, a killed run) and let a
test hold the two against each other.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from seqrun.arm import kinematics
from seqrun.arm.description import ArmDescription
from seqrun.report.data import RunData, Series, StepView
from seqrun.arm.tracking import peak_abs, windowed_velocity

#: Per-joint figures of a move, in the order the report shows them.
MOVE_FIGURES = ("max_following_error_deg", "final_error_deg", "peak_measured_velocity_deg_s")


def step_samples(series: Series, number: int) -> np.ndarray:
    """Indices of the streamed (setpoint) samples of step ``number``."""
    return np.flatnonzero(series.streamed & (series.step == number))


def recompute_move_figures(data: RunData, step: StepView) -> dict[str, Any]:
    """The step's tracking figures from its logged samples (empty if it streamed none)."""
    idx = step_samples(data.series, step.number)
    if idx.size == 0:
        return {}
    s = data.series
    target = (np.asarray(step.move["target_deg"], dtype=float)
              if step.move and "target_deg" in step.move else s.planned[idx[-1]])
    velocity = windowed_velocity(s.t[idx], s.measured[idx], data.velocity_window_s,
                                 None if s.t_joint is None else s.t_joint[idx])
    return {
        "max_following_error_deg": _r(np.max(np.abs(s.planned[idx] - s.measured[idx]), axis=0)),
        "final_error_deg": _r(np.abs(target - s.measured[idx[-1]])),
        "peak_measured_velocity_deg_s": _r(peak_abs(velocity)),
    }


def move_figures(data: RunData, step: StepView) -> tuple[dict[str, Any], bool]:
    """The figures the report shows for a move, and whether they come from report.json
    (True) or were recomputed from the event log (False)."""
    if all(k in step.detail for k in MOVE_FIGURES[:2]):
        return {k: step.detail.get(k) for k in MOVE_FIGURES}, True
    return recompute_move_figures(data, step), False


def guard_heights(arm: ArmDescription, measured_deg: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    """Height (z, mm) of every guarded point over the samples: ``{guard: {point: z}}``."""
    if len(measured_deg) == 0:
        return {g.name: {p: np.zeros(0) for p in g.points} for g in arm.workspace.guards}
    chain = kinematics.Chain.from_arm(arm)
    points = kinematics.point_positions(chain, np.radians(measured_deg))
    return {g.name: {p: points[p][..., 2] for p in g.points} for g in arm.workspace.guards}


def end_effector_pose(arm: ArmDescription, joints_deg: np.ndarray) -> np.ndarray:
    """x, y, z (mm), roll, pitch, yaw (deg) of the end-effector per sample: ``(n, 6)``."""
    if len(joints_deg) == 0:
        return np.zeros((0, 6))
    frames = kinematics.fk(kinematics.Chain.from_arm(arm), np.radians(joints_deg))
    rpy = np.degrees(kinematics.rpy_from_matrix(frames))
    return np.concatenate([frames[:, :3, 3], rpy], axis=1)


def loop_periods(series: Series) -> np.ndarray:
    """Control-loop periods (s): time between consecutive streamed cycles of one step."""
    if len(series) < 2:
        return np.zeros(0)
    same = (series.streamed[1:] & series.streamed[:-1]
            & (series.step[1:] == series.step[:-1]))
    return np.diff(series.t)[same]


def period_stats(periods: np.ndarray) -> dict[str, float]:
    if periods.size == 0:
        return {}
    return {"count": int(periods.size), "median_ms": float(np.median(periods) * 1e3),
            "p99_ms": float(np.percentile(periods, 99) * 1e3),
            "max_ms": float(np.max(periods) * 1e3)}


def step_spans(data: RunData) -> list[tuple[int, float, float | None]]:
    """(number, start, end) of every step that ran, in run time."""
    end_of_run = data.series.t[-1] if len(data.series) else None
    finished = next((e["t"] for e in reversed(data.events) if e.get("type") == "run_finished"),
                    end_of_run)
    spans = []
    for s in data.steps:
        if s.started_t is None:
            continue
        spans.append((s.number, s.started_t, s.finished_t if s.finished_t is not None
                      else finished))
    return spans


def decimate(t: np.ndarray, y: np.ndarray, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """At most ~``max_points`` points of a line that keep its envelope: the minimum and
    the maximum of each of ``max_points // 2`` buckets, in time order. NaN (gaps) stay."""
    n = len(t)
    if n <= max_points:
        return t, y
    buckets = max(1, max_points // 2)
    size = int(np.ceil(n / buckets))
    pad = buckets * size - n
    yy = np.concatenate([y, np.full(pad, np.nan)]).reshape(buckets, size)
    base = np.arange(buckets) * size
    all_nan = np.all(np.isnan(yy), axis=1)
    safe = np.where(np.isnan(yy), 0.0, yy)
    lo = np.where(np.isnan(yy), np.inf, safe).argmin(axis=1) + base
    hi = np.where(np.isnan(yy), -np.inf, safe).argmax(axis=1) + base
    # A bucket without data keeps one NaN point, so the line shows the gap.
    lo = np.where(all_nan, base, lo)
    hi = np.where(all_nan, base, hi)
    idx = np.unique(np.clip(np.concatenate([lo, hi]), 0, n - 1))
    return t[idx], y[idx]


def _r(a: np.ndarray, nd: int = 3) -> list[float]:
    return [round(float(x), nd) for x in a]
