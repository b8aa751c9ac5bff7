"""What the report keeps of the arm's readings: per-step summaries and decimated lines.

The readings stream by in chunks (:mod:`seqrun.report.readings`); :class:`SummaryBuilder`
folds each chunk into

- a :class:`StepSummary` per step: exact extremes of its readings (largest following
  error, lowest guard points, the peak of the windowed velocity of its streamed cycles,
  the last streamed cycle), so a step's figures can be recomputed without its samples;
- an :class:`Overview`: every plotted line as a min/max envelope of a few thousand points
  (:mod:`seqrun.report.envelope`), the exact extremes the captions state (worst following
  error per joint, lowest height per guard point), and the control loop's periods as an
  exact histogram (whole microseconds: the log's time resolution).

Memory grows with the number of steps (a few hundred bytes each), never with the number
of readings.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from seqrun.arm import kinematics
from seqrun.arm.description import ArmDescription
from seqrun.arm.tracking import VelocityStream, peak_abs
from seqrun.report.envelope import Envelope
from seqrun.report.readings import Series

#: Per-joint lines of the plots, in this order per joint.
JOINT_LINES = ("planned", "measured", "planned_vel", "measured_vel", "error")


@dataclass
class StepSummary:
    """One step's readings, reduced as they streamed by (exact, not decimated)."""

    number: int
    readings: int = 0
    streamed: int = 0                                  # setpoint cycles (a plan streamed)
    first_t: float | None = None
    last_t: float | None = None
    #: Largest |planned − measured| per joint over the streamed cycles.
    max_following_error_deg: np.ndarray | None = None
    #: Peak |windowed velocity| per joint over the streamed cycles (the step's own window).
    peak_measured_velocity_deg_s: np.ndarray | None = None
    last_planned_deg: np.ndarray | None = None         # of the last streamed cycle
    last_measured_deg: np.ndarray | None = None
    #: Lowest height (mm) per guard point over all the step's readings: {(guard, point): z}.
    lowest_mm: dict[tuple[str, str], float] = field(default_factory=dict)


@dataclass
class Overview:
    """The run's readings as the plots draw them."""

    readings: int = 0
    t_first: float | None = None
    t_last: float | None = None
    #: name -> (t, y): ``planned.0`` ... ``error.6`` (per joint index), ``guard.desk.wrist``.
    lines: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: Exact largest |planned − measured| per joint (NaN: never streamed).
    worst_error_deg: np.ndarray | None = None
    #: Exact lowest height per guard point: {(guard, point): z mm}.
    lowest_mm: dict[tuple[str, str], float] = field(default_factory=dict)
    #: Control-loop periods (µs) -> how many: time between consecutive streamed cycles
    #: of one step.
    periods_us: dict[int, int] = field(default_factory=dict)

    def line(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        return self.lines.get(name, (np.zeros(0), np.zeros(0)))


class SummaryBuilder:
    """Fold chunks of readings into step summaries and an overview (bounded memory)."""

    def __init__(self, arm: ArmDescription | None, dof: int, window_s: float,
                 max_points: int) -> None:
        self.dof = dof
        self.window_s = window_s
        self.guards = [(g.name, p) for g in arm.workspace.guards for p in g.points] \
            if arm is not None and arm.dof == dof else []
        self.chain = kinematics.Chain.from_arm(arm) if self.guards and arm else None
        self.names = [f"{q}.{i}" for i in range(dof) for q in JOINT_LINES] \
            + [f"guard.{g}.{p}" for g, p in self.guards]
        self.envelope = Envelope(len(self.names), max_points)
        self.overview = Overview(worst_error_deg=np.full(dof, np.nan))
        self.steps: dict[int, StepSummary] = {}
        self._step_velocity: tuple[int, VelocityStream] | None = None
        self._last: tuple[float, int, bool] | None = None      # (t, step, streamed)
        self._periods: dict[int, int] = {}

    def add(self, s: Series) -> None:
        if len(s) == 0:
            return
        ov = self.overview
        ov.readings += len(s)
        ov.t_first = float(s.t[0]) if ov.t_first is None else ov.t_first
        ov.t_last = float(s.t[-1])
        error = s.planned - s.measured
        heights = self._heights(s.measured)
        columns = []
        for i in range(self.dof):
            columns += [s.planned[:, i], s.measured[:, i], s.planned_vel[:, i],
                        s.measured_vel[:, i], error[:, i]]
        columns += [heights[key] for key in self.guards]
        self.envelope.add(s.t, np.column_stack(columns))
        assert ov.worst_error_deg is not None  # (set when the summary was made)
        ov.worst_error_deg = np.fmax(ov.worst_error_deg, _nanmax(np.abs(error), self.dof))
        for key in self.guards:
            ov.lowest_mm[key] = _fmin(ov.lowest_mm.get(key), heights[key])
        self._loop_periods(s)
        # Per step: readings of one step are consecutive.
        cuts = np.flatnonzero(np.diff(s.step)) + 1
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(s)]):
            self._step(s, int(s.step[a]), slice(a, b), error, heights)

    def _heights(self, measured: np.ndarray) -> dict[tuple[str, str], np.ndarray]:
        if self.chain is None:
            return {}
        points = kinematics.point_positions(self.chain, np.radians(measured))
        return {(g, p): points[p][..., 2] for g, p in self.guards}

    def _step(self, s: Series, number: int, rows: slice, error: np.ndarray,
              heights: dict) -> None:
        summary = self.steps.get(number)
        if summary is None:
            summary = self.steps[number] = StepSummary(number)
        summary.readings += rows.stop - rows.start
        summary.first_t = float(s.t[rows.start]) if summary.first_t is None else summary.first_t
        summary.last_t = float(s.t[rows.stop - 1])
        for key in self.guards:
            summary.lowest_mm[key] = _fmin(summary.lowest_mm.get(key), heights[key][rows])
        idx = np.flatnonzero(s.streamed[rows]) + rows.start
        if idx.size == 0:
            return
        summary.streamed += idx.size
        worst = _nanmax(np.abs(error[idx]), self.dof)
        summary.max_following_error_deg = worst if summary.max_following_error_deg is None \
            else np.fmax(summary.max_following_error_deg, worst)
        if self._step_velocity is None or self._step_velocity[0] != number:
            self._step_velocity = (number, VelocityStream(self.window_s))
        peak = peak_abs(self._step_velocity[1].feed(s.t[idx], s.measured[idx],
                                                    s.t_joint[idx]))
        summary.peak_measured_velocity_deg_s = peak if summary.peak_measured_velocity_deg_s \
            is None else np.maximum(summary.peak_measured_velocity_deg_s, peak)
        summary.last_planned_deg = s.planned[idx[-1]].copy()
        summary.last_measured_deg = s.measured[idx[-1]].copy()

    def _loop_periods(self, s: Series) -> None:
        t, step, streamed = s.t, s.step, s.streamed
        if self._last is not None:
            t = np.r_[self._last[0], t]
            step = np.r_[self._last[1], step]
            streamed = np.r_[self._last[2], streamed]
        self._last = (float(s.t[-1]), int(s.step[-1]), bool(s.streamed[-1]))
        same = streamed[1:] & streamed[:-1] & (step[1:] == step[:-1])
        periods = np.rint(np.diff(t)[same] * 1e6).astype(np.int64)
        for value, count in zip(*np.unique(periods, return_counts=True)):
            self._periods[int(value)] = self._periods.get(int(value), 0) + int(count)

    def finish(self) -> tuple[Overview, dict[int, StepSummary]]:
        lines = self.envelope.finish()
        self.overview.lines = dict(zip(self.names, lines))
        self.overview.periods_us = dict(sorted(self._periods.items()))
        return self.overview, self.steps


def _nanmax(a: np.ndarray, n: int) -> np.ndarray:
    """Largest value per column ignoring NaN (NaN where a column has none)."""
    return np.fmax.reduce(a, axis=0) if len(a) else np.full(n, np.nan)


def _fmin(current: float | None, values: np.ndarray) -> float:
    values = values[~np.isnan(values)]
    lowest = float(values.min()) if values.size else np.nan
    return lowest if current is None or np.isnan(current) else float(np.fmin(current, lowest))
