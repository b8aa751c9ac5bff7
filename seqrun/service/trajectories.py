"""A joint trajectory from another system (a ROS 2 ``JointTrajectory``), run as a sequence.

A trajectory is one continuous motion through its points, as ros2_control's
joint_trajectory_controller runs it: it is written as a sequence of one ``move_trajectory``
step (:mod:`seqrun.steps.move_trajectory`) whose CSV file holds the points, checked by
:func:`seqrun.service.checking.check_sequence` from where the arm stands (the whole
interpolated motion against the limits of the arm file, the velocity, acceleration and jerk
bounds, the locked joint, the workspace guards and the link and tool volumes) and then run
by the arm session like any sequence (:meth:`~seqrun.service.session.ArmSession.run_sequence`:
checked again from the measured joints, a run folder, the same per-cycle checks and Halt on
any fault). Anything wrong is :class:`~seqrun.errors.Refused` with one line naming the first
violating point and time, before anything is sent. A trajectory arriving while one runs is
refused (joint_trajectory_controller would replace it; seqrun does not).

What a point means here:

- ``positions`` are radians in seqrun's user coordinates (those of ``/<arm>/joint_states``:
  Totem = 0, the zero reference in force applied by the arm's driver); ``velocities`` (rad/s)
  and ``accelerations`` (rad/s²), when every point gives them, make the interpolation cubic
  or quintic (positions only: linear), as JTC;
- ``time_from_start`` is when the point is reached: strictly increasing, the first after 0
  (or at 0 only if it is where the arm stands); the motion starts from the measured joints
  at rest;
- joints the trajectory does not name stay where they are; a locked joint may be named only
  at its locked value.

Tolerances (:class:`~seqrun.arm.trajectory_tolerances.TrajectoryTolerances`: JTC's path and
goal tolerances and goal time) become the step's ``path_tolerance_deg``,
``goal_tolerance_deg`` and ``goal_time_s``: the same checks and the same execution as a
sequence's ``move_trajectory``.
"""

from __future__ import annotations

import itertools
import json
import math
import numbers
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from seqrun.arm import trajectory_tolerances as tolerance_rules
from seqrun.arm.trajectory_tolerances import (GOAL_TOLERANCE_VIOLATED, PATH_TOLERANCE_VIOLATED,
                                              TrajectoryTolerances, step_keys)
from seqrun.errors import Refused

__all__ = ["GOAL_TOLERANCE_VIOLATED", "MAX_POINTS", "PATH_TOLERANCE_VIOLATED",
           "JointTrajectory", "TrajectoryPoint", "TrajectoryTolerances", "check_trajectory",
           "constraint_parameters", "in_trajectory_terms", "run_trajectory",
           "tolerances_from_goal", "tolerances_from_parameters", "trajectory_csv"]

#: More points than this is refused (a dense trajectory is one motion: 10,000 points is
#: 100 s at the control cycle).
MAX_POINTS = 10_000
#: A locked joint named in a trajectory must be this close to its locked value (degrees).
LOCKED_TOLERANCE_DEG = 0.01


@dataclass(frozen=True)
class TrajectoryPoint:
    """One point: every named joint's position (radians), when it is due (seconds after
    the trajectory starts) and, optionally, its velocity (rad/s) and acceleration (rad/s²)."""

    positions_rad: tuple[float, ...]
    time_from_start_s: float = 0.0
    velocities_rad_s: tuple[float, ...] = ()
    accelerations_rad_s2: tuple[float, ...] = ()


@dataclass(frozen=True)
class JointTrajectory:
    """What ``trajectory_msgs/JointTrajectory`` carries that seqrun uses."""

    joint_names: tuple[str, ...]
    points: tuple[TrajectoryPoint, ...]


def constraint_parameters(arm: Any) -> dict[str, str]:
    """JTC's ``constraints.*`` parameters for ``arm`` (its joints not locked): name -> what
    it is, for a face to declare (0.0 each: not set)."""
    joints = [j.name for j in arm.joints if j.locked is None]
    return {name: tolerance_rules.PARAMETERS[what]
            for name, what in tolerance_rules.parameter_names(joints).items()}


def tolerances_from_parameters(arm: Any, values: dict[str, Any]) -> TrajectoryTolerances:
    """The tolerances the ``constraints.*`` parameters ``values`` give (radians, seconds),
    checked against the arm file. Refused in one line: not a number >= 0, unknown, looser
    than ``control.max_following_error_deg``."""
    joints = [j.name for j in arm.joints if j.locked is None]
    try:
        tolerances = tolerance_rules.from_parameters(values, joints)
    except ValueError as exc:
        raise Refused(str(exc)) from None
    found = tolerance_rules.problems(tolerances, arm)
    if found:
        raise Refused(f"parameter constraints: {found[0][2]}")
    return tolerances


def tolerances_from_goal(base: TrajectoryTolerances, path: Any, goal: Any,
                         goal_time_s: float) -> TrajectoryTolerances:
    """A FollowJointTrajectory goal's tolerances over ``base``
    (:func:`seqrun.arm.trajectory_tolerances.from_goal`: the goal's override, joint by
    joint). Refused in one line (velocity or acceleration tolerances, not a number)."""
    try:
        return tolerance_rules.from_goal(base, path, goal, goal_time_s)
    except ValueError as exc:
        raise Refused(f"trajectory: {exc}") from None


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise Refused(f"{what}: {value!r} is not a number")
    x = float(value)
    if not math.isfinite(x):
        raise Refused(f"{what}: {value!r} is not a finite number")
    return x


def trajectory_csv(arm: Any, trajectory: JointTrajectory) -> str:
    """``trajectory`` as the CSV file of a ``move_trajectory`` step (t in seconds, then the
    named joints in user degrees, their velocities and accelerations where every point gives
    them). Refused: no point, too many, an unknown, repeated or locked joint, a point of the
    wrong length, a value that is not a finite number, times that do not increase."""
    names = list(trajectory.joint_names)
    if not names:
        raise Refused("trajectory: no joint names")
    if not trajectory.points:
        raise Refused("trajectory: no points")
    if len(trajectory.points) > MAX_POINTS:
        raise Refused(f"trajectory: {len(trajectory.points)} points, at most {MAX_POINTS}")
    joints = {j.name: j for j in arm.joints}
    for name in names:
        if not isinstance(name, str) or name not in joints:
            raise Refused(f"trajectory: unknown joint {name!r} (joints: "
                          f"{', '.join(joints)})")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise Refused(f"trajectory: joint {repeated[0]} is named twice")
    points = trajectory.points
    with_velocities = all(len(p.velocities_rad_s) for p in points)
    with_accelerations = with_velocities and all(len(p.accelerations_rad_s2) for p in points)
    header = ["t", *names]
    if with_velocities:
        header += [f"{n}_vel" for n in names]
    if with_accelerations:
        header += [f"{n}_acc" for n in names]
    rows = [",".join(header)]
    before_s = 0.0
    total = len(points)
    for number, point in enumerate(points, start=1):
        where = f"trajectory point {number}/{total}"
        due_s = _number(point.time_from_start_s, f"{where}: time_from_start")
        where = f"{where} (t={due_s:g} s)"
        if due_s < 0 or (number > 1 and due_s <= before_s):
            raise Refused(f"{where}: time_from_start must be after "
                          + (f"the previous point's {before_s:g} s" if number > 1 else "0 s"))
        columns = [("positions", point.positions_rad)]
        if with_velocities:
            columns.append(("velocities", point.velocities_rad_s))
        if with_accelerations:
            columns.append(("accelerations", point.accelerations_rad_s2))
        values = [repr(due_s)]
        for what, given in columns:
            if len(given) != len(names):
                raise Refused(f"{where}: {len(given)} {what} for {len(names)} joints")
            for name, value in zip(names, given):
                values.append(repr(math.degrees(_number(value, f"{where}: {name}"))))
        for name, value in zip(names, point.positions_rad):
            locked = joints[name].locked
            if locked is not None and abs(math.degrees(value) - locked) > LOCKED_TOLERANCE_DEG:
                raise Refused(f"{where}: {name} is locked at {locked:g}° in the arm file; "
                              f"the trajectory asks {math.degrees(value):.3f}°")
        rows.append(",".join(values))
        before_s = due_s
    return "\n".join(rows) + "\n"


_numbers = itertools.count(1)
_folder: list[Path] = []


def _private_folder() -> Path:
    """One folder per process for the trajectories' sequence files (a run's records copy
    the file when it starts; a refused one is removed at once)."""
    if not _folder:
        _folder.append(Path(tempfile.mkdtemp(prefix="seqrun-trajectories-")))
    return _folder[0]


def _sequence_text(points_file: str, points: int,
                   tolerances: TrajectoryTolerances | None = None) -> str:
    label = json.dumps(f"ROS trajectory ({points} points)")
    keys = step_keys(tolerances) if tolerances is not None else ""
    return ("name: ros_trajectory\n"
            "description: a joint trajectory received over ROS 2 (seqrun ros)\n"
            "steps:\n"
            f"  - move_trajectory: {{file: {json.dumps(points_file)}, label: {label}{keys}}}\n")


def in_trajectory_terms(text: str) -> str:
    """A run's message about a trajectory's sequence file (the executor's checks from the
    measured arm) with the private file named as the trajectory."""
    import re

    return re.sub(r"\S*seqrun-trajectories-[^/\s]*/ros_trajectory_\d+\.yaml(:\d+:\d+)?",
                  "trajectory", text)


def _same_file(named: Any, file: Path) -> bool:
    try:
        return Path(str(named)).resolve() == file.resolve()
    except OSError:
        return False


def _in_operator_terms(error: Any, file: Path) -> str:
    """A finding about the generated files as the trajectory's (a finding about another
    file, the arm's or a pose's, keeps its ``file:line:col``)."""
    points = file.with_suffix(".csv")
    if isinstance(error, str):
        return (error.replace(f"{file}:", "trajectory:").replace(str(file), "the trajectory")
                .replace(str(points), "the trajectory"))
    message = str(error.message).replace(str(points), "the trajectory")
    if _same_file(error.file, file):
        # the step's own findings name the point (and time) they are about
        return message if message.startswith("trajectory") else f"trajectory: {message}"
    return f"{error.file}:{error.line}:{error.column}: {message}"


def check_trajectory(session: Any, trajectory: JointTrajectory, folder: Path | None = None,
                     tolerances: TrajectoryTolerances | None = None):
    """Write ``trajectory`` as a sequence of one ``move_trajectory`` step (and its CSV file;
    ``tolerances``: its path and goal tolerances, the step's keys) and check it from where the arm stands (the one validate call,
    :func:`~seqrun.service.checking.check_sequence`, without the dry run: what ``seqrun run``
    checks before the bus). Returns the check (valid) and the sequence file; Refused with
    the first finding, naming the point and time where it has one."""
    from seqrun.service.checking import check_sequence

    s = session
    s.motion.check_movable("trajectory")
    if s.activity is not None and not s.activity.done:
        raise Refused("trajectory: another motion is running (a new trajectory does not "
                      "replace it; stop it first)")
    start = s.telemetry.joints_deg()
    text = trajectory_csv(s.arm, trajectory)
    folder = Path(folder) if folder is not None else _private_folder()
    file = folder / f"ros_trajectory_{next(_numbers)}.yaml"
    points = file.with_suffix(".csv")
    points.write_text(text, encoding="utf-8")
    file.write_text(_sequence_text(points.name, len(trajectory.points), tolerances),
                    encoding="utf-8")

    def forget() -> None:
        file.unlink(missing_ok=True)
        points.unlink(missing_ok=True)

    arm_file = s.arm.source_file
    project = s.project
    check = check_sequence(file, start_deg=start, started=True,
                           arm_file=Path(arm_file) if arm_file else None,
                           project_dir=project.root if project is not None else None,
                           dry_run=False)
    if check.errors:
        forget()
        more = len(check.errors) - 1
        raise Refused(_in_operator_terms(check.errors[0], file)
                      + (f" (and {more} more)" if more else ""))
    if s.separation is not None:  # against the other arms where they stand (and go)
        try:
            s.separation.refuse_paths("trajectory", check.static.paths)
        except Refused:
            forget()
            raise
    return check, file


def run_trajectory(session: Any, trajectory: JointTrajectory, *, by: str | None = None,
                   log_dir: Path | None = None,
                   tolerances: TrajectoryTolerances | None = None):
    """Check ``trajectory`` (:func:`check_trajectory`, with ``tolerances``: the path and
    goal tolerances of joint_trajectory_controller, seqrun/arm/trajectory_tolerances.py)
    and run it as a sequence in the
    session (non-blocking: the session's activity, with its run folder; no report.html,
    so that the next trajectory need not wait for one: ``seqrun report RUN_DIR`` draws it).
    Refused with one line before anything is sent when it is not valid or the arm cannot
    move now."""
    check, file = check_trajectory(session, trajectory, tolerances=tolerances)
    try:
        return session.run_sequence(file, loaded=check.loaded, assume_yes=True, by=by,
                                    log_dir=log_dir, html_report=False)
    except Refused as exc:
        raise Refused(_in_operator_terms(str(exc), file)) from None
