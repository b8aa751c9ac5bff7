"""Pose files as the faces use them: the poses on a search path, a pose by name and its
findings against the arm, the names a session can move to, and a pose saved from the
arm's measured joints (the console's "save pose", ``seqrun pose save``).

The file format and the checks are :mod:`seqrun.arm.poses`; this is where a face finds a
pose and where a reading of the arm becomes a pose file.
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from seqrun.errors import Refused

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription

__all__ = ["check_pose_name", "find_named_pose", "list_poses", "pose_findings", "pose_names",
           "save_measured_pose", "save_session_pose"]


def find_named_pose(name: str, poses_dir: Any):
    """The pose file ``name`` on the search path ``poses_dir`` (--poses-dir, or the
    campaign's poses then the shipped ones for the default), loaded."""
    from seqrun.arm.poses import find_pose, load_pose
    from seqrun.service.campaigns import pose_search_path

    return load_pose(find_pose(name, pose_search_path(poses_dir)))


def list_poses(poses_dir: Any) -> list[tuple[str, Path, Any, str | None]]:
    """``(name, file, pose or None, its first error or None)`` of every pose file on the
    search path (one broken file does not hide the others)."""
    from seqrun.arm.poses import available_poses, load_pose
    from seqrun.errors import SequenceInvalid

    found: list[tuple[str, Path, Any, str | None]] = []
    for name, path in available_poses(poses_dir).items():
        try:
            found.append((name, path, load_pose(path), None))
        except SequenceInvalid as exc:
            found.append((name, path, None, str(exc.errors[0])))
    return found


def pose_findings(pose: Any, arm: ArmDescription) -> list[tuple[bool, str]]:
    """A pose checked against the arm: ``(is a problem, line)`` for each finding, in order
    (the others are notes, already marked as such)."""
    from seqrun.arm.poses import NOTE_PREFIX, check_pose

    return [(not f.startswith(NOTE_PREFIX), f) for f in check_pose(pose, arm)]


def check_pose_name(name: str) -> None:
    """A name a pose file may have; :class:`~seqrun.errors.UserInputError` otherwise."""
    from seqrun.arm.poses import check_pose_name as check

    check(name)


def pose_names(poses_dir: Any) -> list[str]:
    """Every pose on the search path ``poses_dir`` (first match of a name wins)."""
    from seqrun.arm.poses import available_poses

    return list(available_poses(poses_dir))


def save_measured_pose(path: Path, name: str, arm: ArmDescription,
                       joints_deg: Mapping[str, float], *, simulator: bool,
                       description: str = ""):
    """Write pose ``name`` to ``path`` from the measured joints (user degrees, the locked
    joints left out), with its end-effector pose and the time; the pose it wrote.
    ``ValueError``: joints the pose format refuses."""
    from seqrun.arm.poses import pose_document, save_pose

    pose = pose_document(name, arm, dict(joints_deg), description=description,
                         source="simulator" if simulator else "arm",
                         saved_at=datetime.now(timezone.utc).replace(microsecond=0))
    path.parent.mkdir(parents=True, exist_ok=True)
    save_pose(path, pose)
    return pose


def save_session_pose(session: Any, name: str, *, overwrite: bool = False,
                      description: str = "") -> Path:
    """The session's ``save_pose``: the measured joints into the project's poses folder."""
    from seqrun.arm.poses import check_pose_name
    from seqrun.errors import UserInputError

    try:
        check_pose_name(name)
    except UserInputError as exc:
        raise Refused(str(exc)) from None
    now = session.telemetry.condition()
    if not now.measured or now.stale:
        raise Refused("save pose: no current reading of the arm")
    folder = session.project.poses_dir if session.project is not None else Path("poses")
    path = Path(folder) / f"{name}.yaml"
    if path.exists() and not overwrite:
        raise Refused(f"save pose: {path} exists (overwrite it explicitly)")
    values = {j.name: round(float(x), 3) for j, x in zip(session.arm.joints, now.joints)
              if j.locked is None and x is not None}
    try:
        save_measured_pose(path, name, session.arm, values,
                           simulator=session.connection.is_simulator, description=description)
    except ValueError as exc:
        raise Refused(f"save pose: {exc}") from None
    return path
