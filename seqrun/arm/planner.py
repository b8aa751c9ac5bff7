"""Synchronized, jerk-limited joint trajectories with ruckig (pure: no I/O, no clock).

Plans are made offline (``Ruckig(dofs)`` + ``calculate``) over the *active* joints only:
locked joints and joints a step does not command are not part of the ruckig problem, so
they can never move. All active joints arrive together (``Synchronization.Time``).

Angles here are radians in user coordinates; the executor converts to module radians.
ruckig's Community build ignores position limits and computes waypoints in the cloud, so
limits are enforced by validation and every plan is a single state-to-state segment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
from ruckig import (ControlInterface, InputParameter, Result, Ruckig, RuckigError,
                    Synchronization, Trajectory)

from seqrun.arm.description import ArmDescription
from seqrun.errors import PlanningError

if TYPE_CHECKING:  # annotations only: numpy.typing is an import of its own at run time
    import numpy.typing as npt


@dataclass(frozen=True)
class Limits:
    """Per-joint kinematic limits in rad/s, rad/s², rad/s³ (one entry per arm joint)."""

    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray

    @classmethod
    def from_arm(cls, arm: ArmDescription, *, velocity_scale: float = 1.0,
                 acceleration_scale: float = 1.0, speed: float = 1.0,
                 velocity_deg_s: Mapping[str, float] | None = None,
                 reserve: float | None = None,
                 max_velocity_deg_s: Mapping[str, float] | None = None,
                 max_acceleration_deg_s2: Mapping[str, float] | None = None) -> "Limits":
        """The arm's maxima × the step's scale factors × the run's speed override.

        ``velocity_deg_s`` caps single joints (a step's per-joint velocity); it never
        raises a joint above the arm's maximum. ``reserve`` (default: the arm's
        ``control.tracking_reserve``) is the fraction of each velocity limit kept out of
        the plan for the executor to catch up a lagging joint. ``max_velocity_deg_s`` and
        ``max_acceleration_deg_s2`` replace the arm file's maxima of the joints they name
        by narrower ones (the limits in force, :mod:`seqrun.arm.limits`); never wider.
        """
        if not (0 < speed <= 1 and 0 < velocity_scale <= 1 and 0 < acceleration_scale <= 1):
            raise PlanningError("scale factors and speed must lie in (0, 1]")
        keep = 1.0 - (arm.control.tracking_reserve if reserve is None else reserve)
        vmax = {j.name: j.max_velocity_deg_s for j in arm.joints}
        amax = {j.name: j.max_acceleration_deg_s2 for j in arm.joints}
        for name, value in (max_velocity_deg_s or {}).items():
            vmax[name] = min(vmax[name], value)
        for name, value in (max_acceleration_deg_s2 or {}).items():
            amax[name] = min(amax[name], value)
        vel = np.radians([vmax[j.name] for j in arm.joints]) * min(velocity_scale * speed, keep)
        for name, cap in (velocity_deg_s or {}).items():
            i = arm.index(name)
            vel[i] = min(vel[i], math.radians(cap) * speed * keep)
        acc = np.radians([amax[j.name] for j in arm.joints]) * acceleration_scale * speed
        jerk = np.radians([j.max_jerk_deg_s3 for j in arm.joints]) * acceleration_scale * speed
        return cls(vel, acc, jerk)


@dataclass
class MovePlan:
    """One synchronized segment. ``at(t)`` is clamped to [0, duration] (ruckig's is not)."""

    active: tuple[int, ...]
    start: np.ndarray
    target: np.ndarray
    duration: float
    _trajectory: Trajectory = field(repr=False)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration of every arm joint at time ``t``."""
        # Called every control cycle: new arrays each call (callers may keep or modify
        # them), but np.zeros instead of the Python-level zeros_like, and the active
        # joints' index array made once per ``active`` tuple.
        pos = self.target.copy() if t >= self.duration else self.start.copy()
        vel = np.zeros(pos.shape, pos.dtype)
        acc = np.zeros(pos.shape, pos.dtype)
        if not self.active:
            return pos, vel, acc
        if t >= self.duration:
            # Past the end ruckig extrapolates; the plan holds its final state instead.
            return pos, vel, acc
        p, v, a = self._trajectory.at_time(max(t, 0.0))
        idx = self._index()
        pos[idx], vel[idx], acc[idx] = p, v, a
        return pos, vel, acc

    def _index(self) -> np.ndarray:
        cached = self.__dict__.get("_index_cache")
        if cached is None or cached[0] is not self.active:
            cached = self.__dict__["_index_cache"] = (
                self.active, np.array(self.active, dtype=np.intp))
        return cached[1]

    def sample(self, times: Sequence[float]) -> np.ndarray:
        """Positions at many times: shape (len(times), dof)."""
        # The positions of at(t), without its velocity and acceleration arrays.
        if not len(times):
            return np.array([])
        out = np.empty((len(times), self.start.shape[0]), self.start.dtype)
        out[:] = self.start
        active, trajectory, duration = self.active, self._trajectory, self.duration
        idx = self._index() if active else None
        for row, t in zip(out, times):
            if t >= duration:
                row[:] = self.target
            elif active:
                row[idx] = trajectory.at_time(max(t, 0.0))[0]
        return out

    def peak_velocity(self, samples: int = 200) -> np.ndarray:
        """Largest |velocity| of each joint over the plan (sampled)."""
        if self.duration <= 0 or not self.active:
            return np.zeros_like(self.start)
        ts = np.linspace(0.0, self.duration, samples)
        return np.max(np.abs(np.array([self.at(t)[1] for t in ts])), axis=0)


def _input(active: Sequence[int], limits: Limits) -> InputParameter:
    idx = list(active)
    inp = InputParameter(len(idx))
    # Whole lists only: ruckig's getters return copies, element assignment is lost.
    inp.max_velocity = [float(x) for x in limits.velocity[idx]]
    inp.max_acceleration = [float(x) for x in limits.acceleration[idx]]
    inp.max_jerk = [float(x) for x in limits.jerk[idx]]
    inp.synchronization = Synchronization.Time
    return inp


def _calculate(inp: InputParameter, dofs: int) -> Trajectory:
    trajectory = Trajectory(dofs)
    try:
        result = Ruckig(dofs).calculate(inp, trajectory)
    except RuckigError as exc:
        # ruckig's message is a multi-line dump of its input; the first line says why.
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise PlanningError(f"trajectory planner refused the move: {first}") from None
    if result not in (Result.Working, Result.Finished):
        raise PlanningError(f"trajectory planner failed: {result}")
    return trajectory


def plan_move(start: npt.ArrayLike, target: npt.ArrayLike, limits: Limits,
              active: Sequence[int], *, start_velocity: npt.ArrayLike | None = None,
              start_acceleration: npt.ArrayLike | None = None) -> MovePlan:
    """Plan from ``start`` (with optional non-zero velocity/acceleration) to rest at
    ``target``. Only ``active`` joints move; the others keep their start value."""
    start_arr = np.asarray(start, dtype=float)
    target_arr = start_arr.copy()
    tgt = np.asarray(target, dtype=float)
    active = tuple(i for i in active)
    target_arr[list(active)] = tgt[list(active)]
    if not np.all(np.isfinite(start_arr)) or not np.all(np.isfinite(target_arr)):
        raise PlanningError("start and target must be finite numbers")
    if not active:
        return MovePlan(active, start_arr, target_arr, 0.0, Trajectory(1))
    idx = list(active)
    inp = _input(active, limits)
    inp.current_position = [float(x) for x in start_arr[idx]]
    zeros = [0.0] * len(idx)
    inp.current_velocity = ([float(x) for x in np.asarray(start_velocity)[idx]]
                            if start_velocity is not None else zeros)
    inp.current_acceleration = ([float(x) for x in np.asarray(start_acceleration)[idx]]
                                if start_acceleration is not None else zeros)
    inp.target_position = [float(x) for x in target_arr[idx]]
    inp.target_velocity = zeros
    inp.target_acceleration = zeros
    trajectory = _calculate(inp, len(idx))
    return MovePlan(active, start_arr, target_arr, float(trajectory.duration), trajectory)


def plan_stop(position: npt.ArrayLike, velocity: npt.ArrayLike,
              acceleration: npt.ArrayLike, limits: Limits,
              active: Sequence[int]) -> MovePlan:
    """A controlled stop: from the current state to zero velocity as fast as the limits
    allow, each joint on its own (no synchronization needed to stop)."""
    pos = np.asarray(position, dtype=float)
    active = tuple(active)
    if not active:
        return MovePlan(active, pos.copy(), pos.copy(), 0.0, Trajectory(1))
    idx = list(active)
    inp = _input(active, limits)
    inp.control_interface = ControlInterface.Velocity
    inp.synchronization = Synchronization.No
    inp.current_position = [float(x) for x in pos[idx]]
    inp.current_velocity = [float(x) for x in np.asarray(velocity, dtype=float)[idx]]
    inp.current_acceleration = [float(x) for x in np.asarray(acceleration, dtype=float)[idx]]
    inp.target_velocity = [0.0] * len(idx)
    inp.target_acceleration = [0.0] * len(idx)
    trajectory = _calculate(inp, len(idx))
    final = pos.copy()
    final[idx] = trajectory.at_time(trajectory.duration)[0]
    return MovePlan(active, pos.copy(), final, float(trajectory.duration), trajectory)


@dataclass
class SampledPlan:
    """A precomputed joint trajectory (e.g. a straight line of the tool, solved sample by
    sample), streamed like a :class:`MovePlan`: same ``at``/``sample``/``peak_velocity``.

    Between samples the positions are cubic Hermite interpolated with the velocities of
    the samples (central differences), so position and velocity are continuous. ``at(t)``
    is clamped to [0, duration] and holds the last sample after the end.
    """

    active: tuple[int, ...]
    times: np.ndarray        # (k,) seconds, increasing, times[0] == 0
    positions: np.ndarray    # (k, dof) user rad, every joint of the arm

    def __post_init__(self) -> None:
        self.times = np.asarray(self.times, dtype=float)
        self.positions = np.asarray(self.positions, dtype=float)
        if self.times.ndim != 1 or len(self.times) < 2 or self.positions.shape[0] != len(self.times):
            raise PlanningError("a sampled plan needs at least two samples, one per time")
        if not np.all(np.diff(self.times) > 0) or not np.all(np.isfinite(self.positions)):
            raise PlanningError("a sampled plan needs increasing times and finite positions")
        self.velocities = np.gradient(self.positions, self.times, axis=0)
        self.velocities[0] = 0.0   # starts and ends at rest
        self.velocities[-1] = 0.0

    @property
    def start(self) -> np.ndarray:
        return self.positions[0]

    @property
    def target(self) -> np.ndarray:
        return self.positions[-1]

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration of every arm joint at time ``t``."""
        if t >= self.duration:
            zeros = np.zeros(self.positions.shape[1])
            return self.target.copy(), zeros, zeros.copy()
        t = max(t, 0.0)
        k = min(int(np.searchsorted(self.times, t, side="right")) - 1, len(self.times) - 2)
        h = self.times[k + 1] - self.times[k]
        u = (t - self.times[k]) / h
        p0, p1 = self.positions[k], self.positions[k + 1]
        m0, m1 = self.velocities[k] * h, self.velocities[k + 1] * h
        u2, u3 = u * u, u * u * u
        pos = ((2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * m0
               + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * m1)
        vel = ((6 * u2 - 6 * u) * p0 + (3 * u2 - 4 * u + 1) * m0
               + (-6 * u2 + 6 * u) * p1 + (3 * u2 - 2 * u) * m1) / h
        acc = ((12 * u - 6) * p0 + (6 * u - 4) * m0 + (-12 * u + 6) * p1
               + (6 * u - 2) * m1) / (h * h)
        return pos, vel, acc

    def sample(self, times: Sequence[float]) -> np.ndarray:
        return np.array([self.at(t)[0] for t in times])

    def peak_velocity(self, samples: int = 200) -> np.ndarray:
        return np.max(np.abs(self.velocities), axis=0)
