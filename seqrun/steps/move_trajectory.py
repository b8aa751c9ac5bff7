"""move_trajectory: a timed joint trajectory from a CSV file, one continuous motion.

The points are interpolated as ros2_control's joint_trajectory_controller does
(:mod:`seqrun.arm.trajectory_interp`: linear, cubic with velocities, quintic with
accelerations) from where the arm stands, and streamed at the control cycle like a
``move_linear``. Validation checks the whole motion (limits, velocity, acceleration and
jerk, guards, link and tool volumes); the run interpolates again from the measured joints.
``seqrun ros`` runs its JointTrajectory messages through this step.

The file (relative to the sequence file): a header ``t`` then joint names (any of the
arm's; the others stay where they are), optionally ``<joint>_vel`` (deg/s) and
``<joint>_acc`` (deg/s²) columns; one row per point, ``t`` in seconds after the start,
angles in user degrees.

Optional tolerances, as JTC's constraints (seqrun/arm/trajectory_tolerances.py):
``path_tolerance_deg`` (per joint, the following error that stops the motion),
``goal_tolerance_deg`` and ``goal_time_s`` (per joint, within how much of its last point it
must end, and by when); each at most the arm file's ``control.max_following_error_deg``.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from pydantic import Field

from seqrun.errors import RunAborted
from seqrun.steps.kind import StepKind
from seqrun.steps.params import HazardKey, JointName, Positive, StepParams, one_key_value

if TYPE_CHECKING:
    import numpy as np

    from seqrun.arm.description import ArmDescription
    from seqrun.arm.trajectory_interp import InterpolatedTrajectory, TimedPoint
    from seqrun.arm.trajectory_tolerances import TrajectoryTolerances
    from seqrun.errors import SourceError
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep

#: A locked joint named in the file must be this close to its locked value (degrees).
LOCKED_TOLERANCE_DEG = 0.01


class MoveTrajectoryParams(StepParams):
    """Move through the points of a timed joint trajectory (a CSV file) in one continuous
    motion, as ros2_control's joint_trajectory_controller: each point reached at its time
    t, interpolated linearly (positions only), cubic (with velocities) or quintic (with
    accelerations). The whole motion is checked before anything moves."""

    kind: ClassVar[str] = "move_trajectory"
    yaml_name: ClassVar[str] = "move_trajectory"

    file: str = Field(min_length=1, description="CSV file relative to the sequence file: "
                                                "columns t (s), then joint names (degrees), "
                                                "optionally <joint>_vel (deg/s) and "
                                                "<joint>_acc (deg/s^2).")
    tolerance_deg: Positive | None = Field(
        None, description="In-position tolerance per joint at the end, degrees (default: the "
                          "arm file's control.position_tolerance_deg).")
    path_tolerance_deg: dict[JointName, Positive] | None = Field(
        None, description="Per joint, the largest following error (degrees, measured against "
                          "the interpolated setpoint) while the trajectory runs, as "
                          "joint_trajectory_controller's constraints.<joint>.trajectory: "
                          "exceeded, the motion ends in a controlled stop and the step fails "
                          "PATH_TOLERANCE_VIOLATED. At most the arm file's "
                          "control.max_following_error_deg (a looser one is refused).")
    goal_tolerance_deg: dict[JointName, Positive] | None = Field(
        None, description="Per joint, how far (degrees) from its last point the joint may "
                          "end, as constraints.<joint>.goal: not met goal_time_s after the "
                          "trajectory's end, the step fails GOAL_TOLERANCE_VIOLATED. Joints "
                          "not named use tolerance_deg. At most the arm file's "
                          "control.max_following_error_deg.")
    goal_time_s: Positive | None = Field(
        None, description="How long after the trajectory's end the goal tolerances must be "
                          "met by, seconds (constraints.goal_time; default: the arm file's "
                          "control.settle_timeout_s).")
    hazard: HazardKey = None

    def tolerances(self) -> TrajectoryTolerances:
        """The step's path and goal tolerances (seqrun/arm/trajectory_tolerances.py)."""
        from seqrun.arm.trajectory_tolerances import TrajectoryTolerances

        return TrajectoryTolerances(dict(self.path_tolerance_deg or {}),
                                    dict(self.goal_tolerance_deg or {}), self.goal_time_s)


class PointsError(ValueError):
    """The file cannot be read as trajectory points (one line)."""


def read_points(path: Path, arm: ArmDescription,
                start_deg: np.ndarray) -> list[TimedPoint]:
    """The file's rows as points of every arm joint (rad), joints it does not name at
    ``start_deg``. PointsError: unreadable, unknown or locked joints, not numbers."""
    from seqrun.arm.trajectory_interp import TimedPoint

    try:
        with open(path, newline="", encoding="utf-8") as handle:
            rows = [r for r in csv.reader(handle) if r and any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError) as exc:
        raise PointsError(f"cannot read {path}: {exc}") from None
    if not rows:
        raise PointsError(f"{path}: empty (a header t,<joint>... and one row per point)")
    header = [c.strip() for c in rows[0]]
    if not header or header[0] != "t":
        raise PointsError(f"{path}:1: the first column must be t (seconds)")
    names = arm.joint_names
    columns: dict[tuple[str, str], int] = {}
    for index, title in enumerate(header[1:], start=1):
        joint, _, what = title.partition("_")
        what = what or "pos"
        if joint not in names or what not in ("pos", "vel", "acc") or (joint, what) in columns:
            raise PointsError(f"{path}:1: column {title!r} is not a joint of the arm, "
                              f"<joint>_vel or <joint>_acc, or is repeated")
        columns[(joint, what)] = index
    given = [n for n in names if (n, "pos") in columns]
    if not given:
        raise PointsError(f"{path}:1: no joint column")
    has_vel = all((n, "vel") in columns for n in given)
    has_acc = has_vel and all((n, "acc") in columns for n in given)
    points = []
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise PointsError(f"{path}:{line}: {len(row)} values for {len(header)} columns")
        try:
            values = [float(c) for c in row]
        except ValueError:
            raise PointsError(f"{path}:{line}: a value is not a number") from None
        if not all(math.isfinite(v) for v in values):
            raise PointsError(f"{path}:{line}: a value is not a finite number")
        pos = [float(math.radians(d)) for d in start_deg]
        vel = [0.0] * len(names)
        acc = [0.0] * len(names)
        for name in given:
            i = names.index(name)
            degrees = values[columns[(name, "pos")]]
            locked = arm.joints[i].locked
            if locked is not None and abs(degrees - locked) > LOCKED_TOLERANCE_DEG:
                raise PointsError(f"{path}:{line}: {name} is locked at {locked:g}° in the "
                                  f"arm file; the trajectory asks {degrees:.3f}°")
            if locked is None:
                pos[i] = math.radians(degrees)
            if has_vel:
                vel[i] = math.radians(values[columns[(name, "vel")]])
            if has_acc:
                acc[i] = math.radians(values[columns[(name, "acc")]])
        points.append(TimedPoint(values[0], tuple(pos), tuple(vel) if has_vel else None,
                                 tuple(acc) if has_acc else None))
    if not points:
        raise PointsError(f"{path}: no points (one row per point after the header)")
    return points


def plan_trajectory(arm: ArmDescription, path: Path, start_deg: np.ndarray, speed: float,
                    lower_deg: np.ndarray, upper_deg: np.ndarray, velocity_deg_s: np.ndarray,
                    acceleration_deg_s2: np.ndarray) -> InterpolatedTrajectory:
    """The file's points from ``start_deg`` as a checked sampled plan (times stretched by
    1/speed). PointsError with one line for the first problem."""
    import numpy as np

    from seqrun.arm.trajectory_interp import (TimedPoint, TrajectoryError, first_violation,
                                              interpolate)

    points = read_points(path, arm, start_deg)
    if speed != 1.0:  # a slower run: the same path, later (velocities scaled alike)
        points = [TimedPoint(p.time_s / speed, p.positions,
                             tuple(v * speed for v in p.velocities) if p.velocities else None,
                             tuple(a * speed * speed for a in p.accelerations)
                             if p.accelerations else None) for p in points]
    active = [i for i, j in enumerate(arm.joints) if j.locked is None]
    try:
        # a first point at 0 s from a client's reading of joint_states: the current state
        # within the in-position tolerance (the motion starts from the measured joints)
        trajectory = interpolate(
            np.radians(start_deg), points, 1.0 / arm.control.cycle_hz, active,
            start_tolerance_rad=math.radians(arm.control.position_tolerance_deg))
    except TrajectoryError as exc:
        raise PointsError(f"trajectory {exc}") from None
    jerk = np.radians([j.max_jerk_deg_s3 for j in arm.joints])
    found = first_violation(trajectory, arm.joint_names, np.radians(lower_deg),
                            np.radians(upper_deg), np.radians(velocity_deg_s),
                            np.radians(acceleration_deg_s2), jerk, active)
    if found:
        raise PointsError(f"trajectory {found}")
    return trajectory


def describe(params: MoveTrajectoryParams) -> str:
    return f"move through the trajectory in {params.file}"


def _file(step: ResolvedStep, params: MoveTrajectoryParams) -> Path:
    return Path(step.location.file).parent / params.file


def check(checker: CheckContext, step: ResolvedStep[MoveTrajectoryParams],
          params: MoveTrajectoryParams) -> None:
    """The whole motion from the tracked joints: the points, the limits in force, the
    velocities (less the tracking reserve), accelerations and jerks, the guards and the
    link and tool volumes along the samples."""
    import numpy as np

    from seqrun.arm.trajectory_tolerances import problems

    arm = checker.arm
    checker.motion_allowed(step, checker.unlocked_names())
    for key, joint, message in problems(params.tolerances(), arm):
        unknown = joint not in arm.joint_names
        checker.errors.append(step.error(message, key, joint, key=unknown))
    names = arm.joint_names
    keep = 1 - arm.control.tracking_reserve
    limits = [checker.joints[n].limits or checker.joints[n].joint.limits_deg for n in names]
    if checker.position_unknown or checker.lost_at is not None:
        # where the first segment starts is not known: the file only (no second error
        # about a motion from a place the arm is not)
        try:
            read_points(_file(step, params), arm, checker.tracked())
        except PointsError as exc:
            checker.errors.append(step.error(str(exc), "file"))
        return
    try:
        trajectory = plan_trajectory(
            arm, _file(step, params), checker.tracked(), checker.speed,
            np.array([lo for lo, _ in limits]), np.array([hi for _, hi in limits]),
            np.array([checker.limits.velocity(n).value * keep for n in names]),
            np.array([checker.limits.acceleration(n).value for n in names]))
    except PointsError as exc:
        checker.errors.append(step.error(str(exc), "file"))
        checker.lost_at = step
        return
    plan = trajectory.plan
    before = len(checker.errors)
    checker.check_path_guards(step, plan.times, plan.positions, what="trajectory")
    checker.errors[before:] = [_at_point(e, trajectory.point_times)
                               for e in checker.errors[before:]]
    checker.arrive(step, np.degrees(plan.target))


def _at_point(error: SourceError, point_times: np.ndarray) -> SourceError:
    """A finding along the path ("... at 2.08 s of 5.00 s ...") named by the point whose
    segment it is in, as the trajectory's own findings are."""
    import dataclasses
    import re

    import numpy as np

    found = re.search(r"at (\d+(?:\.\d+)?) s of ", error.message)
    if found is None:
        return error
    t = float(found.group(1))
    k = min(int(np.searchsorted(point_times, t - 1e-9)), len(point_times) - 1)
    return dataclasses.replace(error, message=f"trajectory point {k + 1}/{len(point_times)} "
                                              f"(t={point_times[k]:g} s): {error.message}")


def run(step: ResolvedStep[MoveTrajectoryParams], ex: StepContext) -> dict[str, Any]:
    """The points interpolated again from the measured joints, checked against the arm
    file, and streamed sample by sample."""
    import numpy as np

    params = step.params
    reading = ex.read_arm()
    arm = ex.arm
    keep = 1 - arm.control.tracking_reserve
    try:
        trajectory = plan_trajectory(
            arm, _file(step, params), reading.user_deg, ex.speed,
            np.array([j.limits_deg[0] for j in arm.joints]),
            np.array([j.limits_deg[1] for j in arm.joints]),
            np.array([j.max_velocity_deg_s * keep for j in arm.joints]),
            np.array([j.max_acceleration_deg_s2 for j in arm.joints]))
    except PointsError as exc:
        raise RunAborted("trajectory", str(exc)) from None
    tolerance = params.tolerance_deg or arm.control.position_tolerance_deg
    tolerances = params.tolerances()
    metrics = ex.follow(trajectory.plan, tolerance_deg=tolerance, timeout_s=None,
                        start=reading, tolerances=None if tolerances.empty else tolerances)
    return {**metrics, "points": len(trajectory.point_times),
            "interpolation": trajectory.kind}


KIND = StepKind(
    name="move_trajectory", params=MoveTrajectoryParams, describe=describe, check=check,
    run=run, value=one_key_value("move_trajectory", MoveTrajectoryParams),
    example="move_trajectory: {file: wave.csv}", motion=True,
    data_files=lambda params: (params.file,))
