"""A joint trajectory from another system (a ROS 2 ``JointTrajectory``), run as a sequence.

A trajectory is never streamed as it comes: it is written as a sequence of ``move`` steps
(one per point, joints in user degrees), checked by :func:`seqrun.service.checking.check_sequence`
from where the arm stands (the limits of the arm file, the locked joint, the workspace guards
and the link volumes along the ruckig trajectory each move will really stream) and then run by
the arm session like any sequence (:meth:`~seqrun.service.session.ArmSession.run_sequence`:
validated again from the measured joints, a run folder, the same per-cycle checks and Halt on
any fault). Anything wrong is :class:`~seqrun.errors.Refused` with one line naming the point,
before anything is sent.

What a point means here:

- ``positions`` are radians in seqrun's user coordinates (those of ``/<arm>/joint_states``:
  Totem = 0, the zero reference in force applied by the arm's driver);
- joints the trajectory does not name stay where they are; a locked joint may be named only
  at its locked value;
- the arm comes to rest at every point (a seqrun move ends in position); ``time_from_start``
  sets each segment's velocity caps (the distance over the time, at most the joint's limit),
  so a segment never runs faster than asked, and takes longer where the jerk-limited profile
  or a limit needs it; velocities and accelerations given per point are not used.
"""

from __future__ import annotations

import itertools
import json
import math
import numbers
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from seqrun.errors import Refused

__all__ = ["MAX_POINTS", "JointTrajectory", "TrajectoryPoint", "check_trajectory",
           "in_trajectory_terms", "run_trajectory", "trajectory_steps"]

#: More points than this is refused (each is a move that ends at rest).
MAX_POINTS = 500
#: A locked joint named in a trajectory must be this close to its locked value (degrees).
LOCKED_TOLERANCE_DEG = 0.01
#: The sequence file's first step is on this line (name, description, steps: before it).
_FIRST_STEP_LINE = 4


@dataclass(frozen=True)
class TrajectoryPoint:
    """One point: every named joint's position (radians) and when it is due (seconds after
    the trajectory starts)."""

    positions_rad: tuple[float, ...]
    time_from_start_s: float = 0.0


@dataclass(frozen=True)
class JointTrajectory:
    """What ``trajectory_msgs/JointTrajectory`` carries that seqrun uses."""

    joint_names: tuple[str, ...]
    points: tuple[TrajectoryPoint, ...]


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise Refused(f"{what}: {value!r} is not a number")
    x = float(value)
    if not math.isfinite(x):
        raise Refused(f"{what}: {value!r} is not a finite number")
    return x


def trajectory_steps(arm: Any, trajectory: JointTrajectory, start_deg: Mapping[str, float],
                     move_velocities_deg_s: Mapping[str, float]) -> list[str]:
    """The ``move`` steps (one YAML flow mapping each) of ``trajectory`` from ``start_deg``
    (user degrees, every joint). A segment without time (``time_from_start`` not after the
    previous point's) moves at ``move_velocities_deg_s`` (the session's). Refused: no point,
    too many, an unknown, repeated or locked joint, a point of the wrong length, a position
    that is not a finite number, times that go back."""
    names = list(trajectory.joint_names)
    if not names:
        raise Refused("trajectory: no joint names")
    if not trajectory.points:
        raise Refused("trajectory: no points")
    if len(trajectory.points) > MAX_POINTS:
        raise Refused(f"trajectory: {len(trajectory.points)} points, at most {MAX_POINTS} "
                      "(the arm comes to rest at each)")
    joints = {j.name: j for j in arm.joints}
    for name in names:
        if not isinstance(name, str) or name not in joints:
            raise Refused(f"trajectory: unknown joint {name!r} (joints: "
                          f"{', '.join(joints)})")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise Refused(f"trajectory: joint {repeated[0]} is named twice")
    steps = []
    here = {n: float(v) for n, v in start_deg.items()}
    before_s = 0.0
    total = len(trajectory.points)
    for number, point in enumerate(trajectory.points, start=1):
        where = f"trajectory point {number}/{total}"
        if len(point.positions_rad) != len(names):
            raise Refused(f"{where}: {len(point.positions_rad)} positions for "
                          f"{len(names)} joints")
        due_s = _number(point.time_from_start_s, f"{where}: time_from_start")
        if due_s < before_s:
            raise Refused(f"{where}: time_from_start {due_s:g} s is before the previous "
                          f"point's {before_s:g} s")
        targets: dict[str, float] = {}
        for name, value in zip(names, point.positions_rad):
            degrees = math.degrees(_number(value, f"{where}: {name}"))
            joint = joints[name]
            if joint.locked is not None:
                if abs(degrees - joint.locked) > LOCKED_TOLERANCE_DEG:
                    raise Refused(f"{where}: {name} is locked at {joint.locked:g}° in the "
                                  f"arm file; the trajectory asks {degrees:.3f}°")
                continue
            targets[name] = round(degrees, 6)
        if not targets:
            raise Refused(f"{where}: no joint that can move")
        params: dict[str, Any] = {"joints": targets,
                                  "label": f"ROS trajectory point {number}/{total}"
                                           f" (t={due_s:g} s)"}
        duration = due_s - before_s
        caps = {}
        for name, target in targets.items():
            limit = joints[name].max_velocity_deg_s
            distance = abs(target - here.get(name, target))
            if duration > 0:
                if distance > 0:
                    caps[name] = round(min(limit, max(distance / duration, 1e-3)), 6)
            else:
                caps[name] = min(limit, float(move_velocities_deg_s.get(name, limit)))
        if caps:
            params["velocity_deg_s"] = caps
        steps.append("move: " + json.dumps(params))
        here.update(targets)
        before_s = due_s
    return steps


_numbers = itertools.count(1)
_folder: list[Path] = []


def _private_folder() -> Path:
    """One folder per process for the trajectories' sequence files (a run's records copy
    the file when it starts; a refused one is removed at once)."""
    if not _folder:
        _folder.append(Path(tempfile.mkdtemp(prefix="seqrun-trajectories-")))
    return _folder[0]


def _sequence_text(steps: Sequence[str]) -> str:
    return ("name: ros_trajectory\n"
            "description: a joint trajectory received over ROS 2 (seqrun ros)\n"
            "steps:\n" + "".join(f"  - {s}\n" for s in steps))


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


def _in_operator_terms(error: Any, file: Path, steps: int) -> str:
    """A finding about the generated file as the point it is about (a finding about
    another file, the arm's or a pose's, keeps its ``file:line:col``)."""
    if isinstance(error, str):
        return error.replace(f"{file}:", "trajectory:").replace(str(file), "the trajectory")
    message = str(error.message).replace(str(file), "the trajectory")
    if _same_file(error.file, file):
        point = int(error.line) - _FIRST_STEP_LINE + 1
        if 1 <= point <= steps:
            return f"trajectory point {point}/{steps}: {message}"
        return f"trajectory: {message}"
    return f"{error.file}:{error.line}:{error.column}: {message}"


def check_trajectory(session: Any, trajectory: JointTrajectory, folder: Path | None = None):
    """Write ``trajectory`` as a sequence and check it from where the arm stands (the one
    validate call, :func:`~seqrun.service.checking.check_sequence`, without the dry run:
    what ``seqrun run`` checks before the bus). Returns the check (valid) and the file;
    Refused with the first finding, in terms of the trajectory's points."""
    from seqrun.service.checking import check_sequence

    s = session
    s.motion.check_movable("trajectory")
    start = s.telemetry.joints_deg()
    steps = trajectory_steps(s.arm, trajectory, start, s.move_velocities())
    folder = Path(folder) if folder is not None else _private_folder()
    file = folder / f"ros_trajectory_{next(_numbers)}.yaml"
    file.write_text(_sequence_text(steps), encoding="utf-8")
    arm_file = s.arm.source_file
    project = s.project
    check = check_sequence(file, start_deg=start, started=True,
                           arm_file=Path(arm_file) if arm_file else None,
                           project_dir=project.root if project is not None else None,
                           dry_run=False)
    if check.errors:
        file.unlink(missing_ok=True)
        more = len(check.errors) - 1
        raise Refused(_in_operator_terms(check.errors[0], file, len(steps))
                      + (f" (and {more} more)" if more else ""))
    if s.separation is not None:  # against the other arms where they stand (and go)
        try:
            s.separation.refuse_paths("trajectory", check.static.paths)
        except Refused:
            file.unlink(missing_ok=True)
            raise
    return check, file


def run_trajectory(session: Any, trajectory: JointTrajectory, *, by: str | None = None,
                   log_dir: Path | None = None):
    """Check ``trajectory`` (:func:`check_trajectory`) and run it as a sequence in the
    session (non-blocking: the session's activity, with its run folder; no report.html,
    so that the next trajectory need not wait for one: ``seqrun report RUN_DIR`` draws it).
    Refused with one line before anything is sent when it is not valid or the arm cannot
    move now."""
    check, file = check_trajectory(session, trajectory)
    try:
        return session.run_sequence(file, loaded=check.loaded, assume_yes=True, by=by,
                                    log_dir=log_dir, html_report=False)
    except Refused as exc:
        raise Refused(_in_operator_terms(str(exc), file, len(check.loaded.steps))) from None
