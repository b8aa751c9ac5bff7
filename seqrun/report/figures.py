"""What the report computes from a loaded run (pure: arrays in, arrays and dicts out).

The per-move figures are recomputed here with the same definitions the executor uses
(:mod:`seqrun.arm.tracking`), from the step's summary of its logged samples (exact
extremes gathered as events.jsonl streamed by, :mod:`seqrun.report.summary`): they fill
in what report.json lacks (a move ended by a fault in an older version, a killed run)
and let a test hold the two against each other.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from seqrun.arm import kinematics
from seqrun.arm.description import ArmDescription
from seqrun.report.data import RunData, StepView
from seqrun.report.envelope import Envelope

#: Per-joint figures of a move, in the order the report shows them.
MOVE_FIGURES = ("max_following_error_deg", "final_error_deg", "peak_measured_velocity_deg_s")


def recompute_move_figures(data: RunData, step: StepView) -> dict[str, Any]:
    """The step's tracking figures from its logged samples (empty if it streamed none)."""
    summary = data.step_summaries.get(step.number)
    if summary is None or summary.streamed == 0:
        return {}
    # (a step that streamed readings has every one of these)
    assert summary.last_measured_deg is not None and summary.last_planned_deg is not None
    assert summary.max_following_error_deg is not None
    assert summary.peak_measured_velocity_deg_s is not None
    target = (np.asarray(step.move["target_deg"], dtype=float)
              if step.move and "target_deg" in step.move else summary.last_planned_deg)
    return {
        "max_following_error_deg": _r(summary.max_following_error_deg),
        "final_error_deg": _r(np.abs(target - summary.last_measured_deg)),
        "peak_measured_velocity_deg_s": _r(summary.peak_measured_velocity_deg_s),
    }


def move_figures(data: RunData, step: StepView) -> tuple[dict[str, Any], bool]:
    """The figures the report shows for a move, and whether they come from report.json
    (True) or were recomputed from the event log (False)."""
    if all(k in step.detail for k in MOVE_FIGURES[:2]):
        return {k: step.detail.get(k) for k in MOVE_FIGURES}, True
    return recompute_move_figures(data, step), False


def end_effector_pose(arm: ArmDescription, joints_deg: np.ndarray) -> np.ndarray:
    """x, y, z (mm), roll, pitch, yaw (deg) of the end-effector per sample: ``(n, 6)``."""
    if len(joints_deg) == 0:
        return np.zeros((0, 6))
    frames = kinematics.fk(kinematics.Chain.from_arm(arm), np.radians(joints_deg))
    rpy = np.degrees(kinematics.rpy_from_matrix(frames))
    return np.concatenate([frames[:, :3, 3], rpy], axis=1)


def loop_periods(data: RunData) -> tuple[np.ndarray, np.ndarray]:
    """Control-loop periods (ms) and how often each occurred: time between consecutive
    streamed cycles of one step (exact, to the log's microsecond)."""
    periods = data.overview.periods_us
    return (np.array(list(periods), dtype=float) / 1e3,
            np.array(list(periods.values()), dtype=int))


def period_stats(data: RunData) -> dict[str, float]:
    """count, median, p99 and max (ms) of the control-loop periods, exactly as
    ``np.median`` / ``np.percentile`` (linear) of the periods themselves."""
    values, counts = loop_periods(data)
    total = int(counts.sum())
    if total == 0:
        return {}
    cumulative = np.cumsum(counts)

    def order(k: int) -> float:   # the k-th smallest period (0-based)
        return float(values[np.searchsorted(cumulative, k, side="right")])

    def percentile(p: float) -> float:
        position = p / 100 * (total - 1)
        lo = int(np.floor(position))
        hi = min(lo + 1, total - 1)
        return order(lo) + (position - lo) * (order(hi) - order(lo))

    return {"count": total, "median_ms": percentile(50), "p99_ms": percentile(99),
            "max_ms": float(values[-1])}


def step_spans(data: RunData) -> list[tuple[int, float, float | None]]:
    """(number, start, end) of every step that ran, in run time."""
    end_of_run = data.overview.t_last
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
    """At most ``max_points`` points of a line that keep its envelope: the minimum and the
    maximum of each bucket of samples, in time order (:mod:`seqrun.report.envelope`).
    NaN (gaps) stay."""
    envelope = Envelope(1, max_points)
    envelope.add(t, np.asarray(y, dtype=float)[:, None])
    return envelope.finish()[0]


def _r(a: np.ndarray, nd: int = 3) -> list[float]:
    return [round(float(x), nd) for x in a]
