"""A trajectory's tolerances, as ros2_control's joint_trajectory_controller (JTC) has them.

- ``path_deg``: per joint, the largest following error (measured against the interpolated
  setpoint) allowed while the trajectory runs. Exceeded: the motion is stopped
  (a controlled stop, then the run's Halt) and the failure is ``PATH_TOLERANCE_VIOLATED``
  naming the joint, the error and the time.
- ``goal_deg``: per joint, how far from its last point a joint may end. Checked from the
  trajectory's end until ``goal_time_s`` after it; not met by then: the failure is
  ``GOAL_TOLERANCE_VIOLATED`` naming the joint and its error. Joints without one use the
  step's in-position tolerance (the arm file's ``control.position_tolerance_deg``).
- ``goal_time_s``: JTC's ``goal_time_tolerance``. None (JTC's 0) means the arm file's
  ``control.settle_timeout_s`` (what every move allows itself to settle).

The arm file's own bound (``control.max_following_error_deg``) always applies: a tolerance
may only be tighter, and one looser than that bound is refused (:func:`problems`), not
capped, so that nobody believes a bound is in force that is not.

Pure: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from seqrun.arm.description import ArmDescription

__all__ = ["PATH_TOLERANCE_VIOLATED", "GOAL_TOLERANCE_VIOLATED", "TrajectoryTolerances",
           "override", "problems", "from_parameters", "from_goal", "step_keys",
           "PARAMETER_PREFIX", "PARAMETERS", "parameter_names"]

#: The failures' names (control_msgs/FollowJointTrajectory's result codes).
PATH_TOLERANCE_VIOLATED = "PATH_TOLERANCE_VIOLATED"
GOAL_TOLERANCE_VIOLATED = "GOAL_TOLERANCE_VIOLATED"
#: JTC's parameter namespace: ``constraints.<joint>.trajectory``, ``constraints.<joint>.goal``
#: (radians), ``constraints.goal_time`` (s).
PARAMETER_PREFIX = "constraints."
#: JTC's constraint parameters as ``seqrun ros`` declares them (``<joint>``: every joint
#: not locked in the arm file): name -> what it is (docs/ros2-node.md lists them).
PARAMETERS = {
    "constraints.<joint>.trajectory": "path tolerance, rad: the largest following error "
                                      "of the joint while a trajectory runs (0: none beyond "
                                      "the arm file's control.max_following_error_deg)",
    "constraints.<joint>.goal": "goal tolerance, rad: how far from its last point the joint "
                                "may end (0: the arm file's control.position_tolerance_deg)",
    "constraints.goal_time": "how long after a trajectory's end the goal tolerances must be "
                             "met by, s (0: the arm file's control.settle_timeout_s)",
    "constraints.stopped_velocity_tolerance": "0 only (not supported: the arm is at rest "
                                              "when its joints are in their goal tolerance)",
}


@dataclass(frozen=True)
class TrajectoryTolerances:
    """Per-joint tolerances in degrees (joints not named: none beyond the arm file's)."""

    path_deg: Mapping[str, float] = field(default_factory=dict)
    goal_deg: Mapping[str, float] = field(default_factory=dict)
    goal_time_s: float | None = None

    @property
    def empty(self) -> bool:
        return not self.path_deg and not self.goal_deg and self.goal_time_s is None

    def path_array(self, names: Iterable[str]) -> np.ndarray:
        """Per joint (``names``' order): the path tolerance, inf where none."""
        import numpy as np

        return np.array([self.path_deg.get(n, math.inf) for n in names], dtype=float)

    def goal_array(self, names: Iterable[str], default_deg: float) -> np.ndarray:
        """Per joint: the goal tolerance, ``default_deg`` where none."""
        import numpy as np

        return np.array([self.goal_deg.get(n, default_deg) for n in names], dtype=float)


def override(base: TrajectoryTolerances, given: TrajectoryTolerances) -> TrajectoryTolerances:
    """JTC's rule: what a goal gives overrides the defaults, joint by joint (a joint the
    goal does not name keeps the default); a goal_time given overrides too."""
    return TrajectoryTolerances(
        path_deg={**base.path_deg, **given.path_deg},
        goal_deg={**base.goal_deg, **given.goal_deg},
        goal_time_s=given.goal_time_s if given.goal_time_s is not None else base.goal_time_s)


def problems(tolerances: TrajectoryTolerances,
             arm: ArmDescription) -> list[tuple[str, str, str]]:
    """What is wrong with ``tolerances`` for ``arm``: (which key, which joint or "", one
    line). Unknown or locked joints, and tolerances looser than the arm file's
    ``control.max_following_error_deg`` (refused, never capped)."""
    bound = float(arm.control.max_following_error_deg)
    joints = {j.name: j for j in arm.joints}
    found: list[tuple[str, str, str]] = []
    for key, values in (("path_tolerance_deg", tolerances.path_deg),
                        ("goal_tolerance_deg", tolerances.goal_deg)):
        for name, value in values.items():
            if name not in joints:
                found.append((key, name, f"{key}: unknown joint {name!r} (joints: "
                                         f"{', '.join(joints)})"))
            elif joints[name].locked is not None:
                found.append((key, name, f"{key}: {name} is locked in the arm file"))
            elif value > bound:
                found.append((key, name, f"{key}: {name} {value:g}° is looser than the arm "
                                         f"file's control.max_following_error_deg {bound:g}° "
                                         f"(a tolerance may only be tighter)"))
    return found


def parameter_names(joint_names: Iterable[str]) -> dict[str, str]:
    """Every constraint parameter for these joints: name -> its :data:`PARAMETERS` key."""
    names: dict[str, str] = {}
    for joint in joint_names:
        for what in ("trajectory", "goal"):
            names[f"{PARAMETER_PREFIX}{joint}.{what}"] = f"{PARAMETER_PREFIX}<joint>.{what}"
    for key in ("goal_time", "stopped_velocity_tolerance"):
        names[f"{PARAMETER_PREFIX}{key}"] = f"{PARAMETER_PREFIX}{key}"
    return names


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value < 0:
        raise ValueError(f"parameter {name} must be a number >= 0, got {value!r}")
    return float(value)


def from_parameters(values: Mapping[str, Any], joint_names: Iterable[str]) -> TrajectoryTolerances:
    """JTC's ``constraints.*`` parameters (radians, seconds; 0: not set, as JTC) as
    tolerances in degrees. ValueError in one line for a value that is not a number >= 0
    or a parameter under ``constraints.`` that is none of these."""
    names = list(joint_names)
    known = set(parameter_names(names))
    path: dict[str, float] = {}
    goal: dict[str, float] = {}
    goal_time: float | None = None
    for key, value in values.items():
        if not key.startswith(PARAMETER_PREFIX):
            continue
        if key not in known:
            raise ValueError(f"parameter {key}: not one of constraints.goal_time, "
                             f"constraints.<joint>.trajectory, constraints.<joint>.goal "
                             f"(joints: {', '.join(names)})")
        x = _number(key, value)
        if x == 0:
            continue
        if key.endswith("stopped_velocity_tolerance"):
            # the readings carry no velocity at the goal: refused, not silently ignored
            raise ValueError(f"parameter {key}: not supported (0 or unset only): the arm "
                             f"is at rest when every joint is in its goal tolerance")
        rest = key[len(PARAMETER_PREFIX):]
        if rest == "goal_time":
            goal_time = x
        elif rest.endswith(".trajectory"):
            path[rest.removesuffix(".trajectory")] = math.degrees(x)
        elif rest.endswith(".goal"):
            goal[rest.removesuffix(".goal")] = math.degrees(x)
    return TrajectoryTolerances(path, goal, goal_time)


def from_goal(base: TrajectoryTolerances, path: Iterable[tuple[str, float, float, float]],
              goal: Iterable[tuple[str, float, float, float]],
              goal_time_s: float) -> TrajectoryTolerances:
    """A FollowJointTrajectory goal's ``path_tolerance`` and ``goal_tolerance`` (per joint:
    name, position (rad), velocity, acceleration) and ``goal_time_tolerance`` (s) over
    ``base`` (the node's parameters), as JTC reads them: a position > 0 overrides the
    joint's default, 0 keeps it, < 0 removes it (the arm file's own bound only); the same
    for the goal time. ValueError in one line: a velocity or acceleration tolerance (the
    readings carry no velocity to hold it against), a value that is not a finite number."""
    merged: list[dict[str, float]] = []
    for field_name, given, default in (("path_tolerance", path, base.path_deg),
                                       ("goal_tolerance", goal, base.goal_deg)):
        values = dict(default)
        for name, position, velocity, acceleration in given:
            for what, x in (("position", position), ("velocity", velocity),
                            ("acceleration", acceleration)):
                if not math.isfinite(x):
                    raise ValueError(f"{field_name} of {name}: {what} {x!r} is not a "
                                     f"finite number")
            if velocity != 0 or acceleration != 0:
                raise ValueError(f"{field_name} of {name}: only position tolerances are "
                                 f"supported (velocity and acceleration must be 0)")
            if position > 0:
                values[name] = math.degrees(position)
            elif position < 0:
                values.pop(name, None)
        merged.append(values)
    if not math.isfinite(goal_time_s):
        raise ValueError(f"goal_time_tolerance {goal_time_s!r} is not a finite number")
    goal_time = base.goal_time_s if goal_time_s == 0 else (None if goal_time_s < 0
                                                            else goal_time_s)
    return TrajectoryTolerances(merged[0], merged[1], goal_time)


def step_keys(tolerances: TrajectoryTolerances) -> str:
    """``tolerances`` as the keys of a ``move_trajectory`` step (flow-style YAML, "" when
    there are none): the ROS face runs its trajectories through that step."""
    import json

    keys = []
    if tolerances.path_deg:
        keys.append(f"path_tolerance_deg: {json.dumps(dict(tolerances.path_deg))}")
    if tolerances.goal_deg:
        keys.append(f"goal_tolerance_deg: {json.dumps(dict(tolerances.goal_deg))}")
    if tolerances.goal_time_s is not None:
        keys.append(f"goal_time_s: {json.dumps(tolerances.goal_time_s)}")
    return "".join(f", {k}" for k in keys)
