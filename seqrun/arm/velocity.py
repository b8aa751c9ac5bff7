"""A timed velocity move: per joint, ramp to a velocity, hold it, brake to rest.

The thesis GUI moved joints in velocity mode (FVEL) for as long as a button was held. Here a
velocity move is never open-ended: each joint accelerates to its velocity, holds it until
``duration_s`` after the start, then brakes to rest at the same acceleration. So where
every joint comes to rest is known before anything moves (the static checks hold it against
the step's envelope), and at any instant where a joint would stop if braked now is its
position plus its stopping distance (the per-cycle check).

:class:`VelocityPlan` has the members of :class:`~seqrun.arm.planner.MovePlan` that the
streaming reads (``active``, ``start``, ``target``, ``duration``, ``at``, ``sample``,
``peak_velocity``): the executor follows it like a sampled path. Pure: no I/O, user radians.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Union

import numpy as np

__all__ = ["VelocityPlan", "stop_position", "stopping_distance"]

#: Numbers per joint (or per sample): a sequence or a numpy array.
Numbers = Union[Sequence[float], np.ndarray]  # noqa: UP007


def stopping_distance(velocity: float, acceleration: float) -> float:
    """How far a joint at ``velocity`` travels while braking at ``acceleration`` (same
    units, e.g. deg/s and deg/s² give degrees); always >= 0."""
    return velocity * velocity / (2.0 * acceleration)


def stop_position(position: float, velocity: float, acceleration: float) -> float:
    """Where a joint at ``position`` moving at ``velocity`` comes to rest braking at
    ``acceleration`` (signed: ahead in the direction of motion)."""
    return position + float(np.sign(velocity)) * stopping_distance(velocity, acceleration)


@dataclass(frozen=True)
class _Profile:
    """One joint's trapezoid: accelerate for ``t_up``, cruise until ``t_down``, brake for
    ``t_up`` (at ``acceleration``, signed like the velocity)."""

    velocity: float       # the peak velocity reached (signed)
    acceleration: float   # signed like velocity
    t_up: float
    t_down: float

    @property
    def end(self) -> float:
        return self.t_down + self.t_up

    @property
    def distance(self) -> float:
        return self.velocity * self.t_down   # (ramp up + ramp down = one t_up at full speed)

    def at(self, t: float) -> tuple[float, float, float]:
        v, a, up, down = self.velocity, self.acceleration, self.t_up, self.t_down
        if t <= 0.0:
            return 0.0, 0.0, 0.0
        if t < up:
            return 0.5 * a * t * t, a * t, a
        ramp = 0.5 * v * up
        if t < down:
            return ramp + v * (t - up), v, 0.0
        if t < up + down:
            tau = t - down
            return ramp + v * (down - up) + v * tau - 0.5 * a * tau * tau, v - a * tau, -a
        return self.distance, 0.0, 0.0


def _profile(velocity: float, acceleration: float, duration: float) -> _Profile:
    """Accelerate towards ``velocity`` for at most ``duration``, hold it until
    ``duration``, brake. A duration shorter than the ramp gives a triangle."""
    if velocity == 0.0:
        return _Profile(0.0, 0.0, 0.0, 0.0)
    a = abs(acceleration)
    t_up = min(abs(velocity) / a, duration)
    peak = float(np.sign(velocity)) * a * t_up
    return _Profile(peak, float(np.sign(velocity)) * a, t_up, max(duration, t_up))


@dataclass(frozen=True)
class VelocityPlan:
    """Velocities held for a time, every joint at once (module docstring). User radians."""

    active: tuple[int, ...]
    start: np.ndarray
    target: np.ndarray
    duration: float
    profiles: tuple[_Profile, ...]

    @classmethod
    def plan(cls, start_rad: Numbers, velocity_rad_s: Numbers,
             acceleration_rad_s2: Numbers, duration_s: float) -> VelocityPlan:
        """``velocity_rad_s`` per joint (0: the joint does not move), each reached and
        left at its ``acceleration_rad_s2`` (> 0 where the velocity is not 0), held until
        ``duration_s`` (> 0) after the start."""
        if not duration_s > 0:
            raise ValueError(f"a velocity move needs a positive duration, got {duration_s!r}")
        start = np.asarray(start_rad, dtype=float).copy()
        profiles = []
        for v, a in zip(velocity_rad_s, acceleration_rad_s2):
            if v != 0.0 and not a > 0:
                raise ValueError(f"a joint at {v!r} rad/s needs a positive acceleration")
            profiles.append(_profile(float(v), float(a), float(duration_s)))
        active = tuple(i for i, p in enumerate(profiles) if p.velocity != 0.0)
        target = start + np.array([p.distance for p in profiles])
        end = max((p.end for p in profiles), default=0.0)
        return cls(active, start, target, end, tuple(profiles))

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration of every joint at ``t`` (held after the end)."""
        pos, vel, acc = self.start.copy(), np.zeros_like(self.start), np.zeros_like(self.start)
        for i in self.active:
            p, v, a = self.profiles[i].at(t)
            pos[i] += p
            vel[i], acc[i] = v, a
        return pos, vel, acc

    def sample(self, times: Numbers) -> np.ndarray:
        """Positions at many times: shape (len(times), dof)."""
        if not len(times):
            return np.array([])
        return np.array([self.at(float(t))[0] for t in times])

    def peak_velocity(self, samples: int = 200) -> np.ndarray:
        """Largest |velocity| of each joint (exact: the profiles' peaks)."""
        return np.array([abs(p.velocity) for p in self.profiles])
