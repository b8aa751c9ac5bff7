"""A timed joint trajectory as one continuous motion, as ros2_control's
joint_trajectory_controller interpolates it (pure: no I/O, no clock).

The first segment starts from the arm's state at t = 0 (its measured position, at rest);
between points the positions are interpolated linearly when the points give positions only,
by a cubic Hermite polynomial when they give velocities too, by a quintic when they also
give accelerations (JTC's spline interpolation). The result is sampled at the control cycle
(and at every point's time, so that the streamed plan passes through the points) into the
:class:`~seqrun.arm.planner.SampledPlan` the executor streams for ``move_linear``.

:func:`first_violation` checks the interpolated motion before anything moves: the joint
limits, and each joint's velocity, acceleration and jerk against the bounds given; it
names the first point (index and time) whose segment violates one. Angles are radians.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from seqrun.arm.planner import SampledPlan

__all__ = ["InterpolatedTrajectory", "TimedPoint", "TrajectoryError", "first_violation",
           "interpolate", "interpolation_kind"]

#: A first point at t = 0 must be this close to the current state (rad) by default.
START_TOLERANCE_RAD = 1e-4


@dataclass(frozen=True)
class TimedPoint:
    """One point of every arm joint (rad, rad/s, rad/s²) due ``time_s`` after the start."""

    time_s: float
    positions: tuple[float, ...]
    velocities: tuple[float, ...] | None = None
    accelerations: tuple[float, ...] | None = None


@dataclass(frozen=True)
class InterpolatedTrajectory:
    """The sampled plan and, per sample, the interpolant's own velocity, acceleration and
    jerk (what the checks read); ``segment[i]`` is the index of the point sample ``i``
    moves towards (0 = the first point)."""

    plan: SampledPlan
    velocities: np.ndarray
    accelerations: np.ndarray
    jerks: np.ndarray
    segment: np.ndarray
    point_times: np.ndarray
    kind: str


class TrajectoryError(ValueError):
    """The points cannot make a trajectory (one line, naming the point)."""


def interpolation_kind(points: Sequence[TimedPoint]) -> str:
    """``linear``, ``cubic`` or ``quintic``: what every point gives (JTC's choice)."""
    if points and all(p.velocities is not None for p in points):
        if all(p.accelerations is not None for p in points):
            return "quintic"
        return "cubic"
    return "linear"


def _coefficients(p0, v0, a0, p1, v1, a1, h: float, kind: str) -> np.ndarray:
    """Polynomial coefficients c[0..5] (in powers of s = t - t0) per joint: shape (6, dof)."""
    c = np.zeros((6, len(p0)))
    c[0] = p0
    if kind == "linear":
        c[1] = (p1 - p0) / h
    elif kind == "cubic":
        c[1] = v0
        c[2] = (3 * (p1 - p0) / h - 2 * v0 - v1) / h
        c[3] = (2 * (p0 - p1) / h + v0 + v1) / (h * h)
    else:
        c[1], c[2] = v0, a0 / 2
        h2, h3 = h * h, h * h * h
        c[3] = (20 * (p1 - p0) - (8 * v1 + 12 * v0) * h - (3 * a0 - a1) * h2) / (2 * h3)
        c[4] = (30 * (p0 - p1) + (14 * v1 + 16 * v0) * h + (3 * a0 - 2 * a1) * h2) / (2 * h3 * h)
        c[5] = (12 * (p1 - p0) - 6 * (v1 + v0) * h + (a1 - a0) * h2) / (2 * h3 * h2)
    return c


def _evaluate(c: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, ...]:
    """Position, velocity, acceleration, jerk at offsets ``s`` (k,) -> each (k, dof)."""
    powers = np.vstack([s ** k for k in range(6)]).T  # (k, 6)
    zero = np.zeros_like(s)
    one = np.ones_like(s)
    d1 = np.vstack([zero, one, 2 * s, 3 * s**2, 4 * s**3, 5 * s**4]).T
    d2 = np.vstack([zero, zero, 2 * one, 6 * s, 12 * s**2, 20 * s**3]).T
    d3 = np.vstack([zero, zero, zero, 6 * one, 24 * s, 60 * s**2]).T
    return powers @ c, d1 @ c, d2 @ c, d3 @ c


def interpolate(start: Sequence[float], points: Sequence[TimedPoint], cycle_s: float,
                active: Sequence[int], *,
                start_tolerance_rad: float = START_TOLERANCE_RAD) -> InterpolatedTrajectory:
    """The points from ``start`` (every arm joint, rad, at rest at t = 0) as a sampled plan
    at ``cycle_s``; joints not ``active`` stay at ``start``. A first point at t = 0 is the
    current state (within ``start_tolerance_rad``): the motion starts from ``start`` itself.
    TrajectoryError: no point, times not increasing, a first point at t = 0 away from the
    start, lengths that do not match."""
    begin = np.asarray(start, dtype=float)
    dof, total = len(begin), len(points)
    if not points:
        raise TrajectoryError("no points")
    kind = interpolation_kind(points)
    before = 0.0
    for number, point in enumerate(points, start=1):
        where = f"point {number}/{total} (t={point.time_s:g} s)"
        for what, values in (("positions", point.positions), ("velocities", point.velocities),
                             ("accelerations", point.accelerations)):
            if values is not None and len(values) != dof:
                raise TrajectoryError(f"{where}: {len(values)} {what} for {dof} joints")
        if number == 1 and point.time_s == 0:
            off = np.abs(np.asarray(point.positions) - begin)
            if np.max(off) > start_tolerance_rad:
                raise TrajectoryError(
                    f"{where}: time_from_start 0 but {np.degrees(np.max(off)):.3f}° away "
                    "from where the arm stands (a first point at 0 s must be the current "
                    "state)")
        elif point.time_s <= before:
            raise TrajectoryError(
                f"{where}: time_from_start must be after "
                + (f"the previous point's {before:g} s" if number > 1 else "0 s"))
        before = point.time_s
    # the knots: the current state, then every point (a first point at 0 s is the state)
    knots = [TimedPoint(0.0, tuple(begin), (0.0,) * dof, (0.0,) * dof)]
    numbers = [0]
    for index, point in enumerate(points):
        if point.time_s == 0:
            continue
        knots.append(point)
        numbers.append(index)
    if len(knots) < 2:
        raise TrajectoryError("point 1/1 (t=0 s): nothing to move through")
    t_all, p_all, v_all, a_all, j_all, seg = [], [], [], [], [], []
    for k in range(1, len(knots)):
        a, b = knots[k - 1], knots[k]
        h = b.time_s - a.time_s
        zeros = np.zeros(dof)
        c = _coefficients(np.asarray(a.positions, float),
                          np.asarray(a.velocities, float) if a.velocities is not None else zeros,
                          np.asarray(a.accelerations, float)
                          if a.accelerations is not None else zeros,
                          np.asarray(b.positions, float),
                          np.asarray(b.velocities, float) if b.velocities is not None else zeros,
                          np.asarray(b.accelerations, float)
                          if b.accelerations is not None else zeros, h, kind)
        # the cycle's grid inside the segment, and the segment's end (the point itself)
        first = np.ceil(a.time_s / cycle_s - 1e-9) * cycle_s + 0.0
        grid = np.arange(first, b.time_s - 1e-9, cycle_s)
        grid = grid[grid > a.time_s + 1e-9] if k > 1 else grid
        times = np.append(grid, b.time_s)
        p, v, acc, jerk = _evaluate(c, times - a.time_s)
        t_all.append(times)
        p_all.append(p)
        v_all.append(v)
        a_all.append(acc)
        j_all.append(jerk)
        seg.append(np.full(len(times), numbers[k]))
    times = np.concatenate(t_all)  # the first segment's grid starts at 0
    positions = np.vstack(p_all)
    still = [i for i in range(dof) if i not in set(active)]
    positions[:, still] = begin[still]
    plan = SampledPlan(tuple(active), times, positions)
    return InterpolatedTrajectory(plan, np.vstack(v_all), np.vstack(a_all), np.vstack(j_all),
                                  np.concatenate(seg).astype(int),
                                  np.array([p.time_s for p in points]), kind)


def first_violation(trajectory: InterpolatedTrajectory, names: Sequence[str],
                    lower: np.ndarray, upper: np.ndarray, velocity: np.ndarray,
                    acceleration: np.ndarray, jerk: np.ndarray | None,
                    active: Sequence[int]) -> str | None:
    """The first sample (in time) outside the joint limits ``lower``/``upper`` (rad) or
    faster than ``velocity``/``acceleration``/``jerk`` (rad/s, rad/s², rad/s³; jerk None:
    not checked) for an ``active`` joint, as one line naming the point, or None."""
    plan = trajectory.plan
    idx = list(active)
    checks = [("position", plan.positions, lower, upper, "°", "outside its limits"),
              ("velocity", trajectory.velocities, -velocity, velocity, "°/s", "above its limit"),
              ("acceleration", trajectory.accelerations, -acceleration, acceleration, "°/s²",
               "above its limit")]
    if jerk is not None:
        checks.append(("jerk", trajectory.jerks, -jerk, jerk, "°/s³", "above its limit"))
    tolerance = 1e-9
    worst: tuple[int, int, str] | None = None
    for what, values, lo, hi, unit, _ in checks:
        bad = (values[:, idx] < lo[idx] - tolerance) | (values[:, idx] > hi[idx] + tolerance)
        rows = np.flatnonzero(bad.any(axis=1))
        if rows.size and (worst is None or rows[0] < worst[0]):
            joint = idx[int(np.flatnonzero(bad[rows[0]])[0])]
            worst = (int(rows[0]), joint, what)
    if worst is None:
        return None
    row, joint, what = worst
    point = int(trajectory.segment[row])
    due = float(trajectory.point_times[point])
    total = len(trajectory.point_times)
    t = float(plan.times[row])
    _, values, lo, hi, unit, words = next(c for c in checks if c[0] == what)
    value = float(np.degrees(values[row, joint]))
    where = f"point {point + 1}/{total} (t={due:g} s): {names[joint]}"
    if what == "position":
        return (f"{where} at {value:.3f}° at t={t:.3f} s, {words} "
                f"{np.degrees(lo[joint]):g}°..{np.degrees(hi[joint]):g}°")
    return (f"{where} {what} {abs(value):.3f} {unit} at t={t:.3f} s, {words} of "
            f"{np.degrees(hi[joint]):g} {unit}")
