"""Where a step goes: move targets and checkpoint poses, from the poses frozen with a sequence.

Shared by the static checks (:mod:`seqrun.sequence.validation`, from the tracked joints) and the
step handlers (:mod:`seqrun.steps`, from the measured joints): both resolve a target the
same way. Pose lookups by name: the poses a sequence froze when it was loaded
(:attr:`seqrun.sequence.loader.LoadedSequence.poses`), or a pose folder (the start pose of a check,
read once per file version). Cartesian targets are :mod:`seqrun.arm.cartesian`.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from seqrun.defaults import START_POSE
from seqrun.errors import UserInputError

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.arm.poses import PoseDirs
    from seqrun.steps.checkpoint import CheckpointParams
    from seqrun.steps.move import MoveParams

__all__ = [
    "PoseSource",
    "commanded_joints",
    "park_deg",
    "pose_joints_deg",
    "resolve_checkpoint",
    "resolve_move_target",
]


def pose_joints_deg(name: str, poses_dir: PoseDirs) -> dict[str, float]:
    """Joint angles of pose ``name`` (user degrees), from a pose folder or a search path of
    folders (first match wins, as :func:`seqrun.arm.poses.find_pose`). Raises
    :class:`UserInputError` for an unknown pose, :class:`SequenceInvalid` for a broken pose
    file."""
    from seqrun.arm.poses import find_pose

    path = find_pose(name, poses_dir)
    return dict(_pose_joints(path, path.stat().st_mtime_ns))


@functools.lru_cache(maxsize=64)
def _pose_joints(path: Path, mtime_ns: int) -> tuple[tuple[str, float], ...]:
    # Keyed on the file's mtime: a pose file edited between runs is read again.
    from seqrun.arm.poses import load_pose

    return tuple(load_pose(path).joints_deg.items())


def park_deg(poses_dir: PoseDirs) -> dict[str, float]:
    """The default start state: the Park pose (where a freshly powered-on arm is)."""
    return pose_joints_deg(START_POSE, poses_dir)


#: Where poses come from: the poses a sequence froze when it was loaded
#: (:attr:`LoadedSequence.poses`, name -> FrozenPose or joint mapping), or a folder.
PoseSource = Mapping | str | Path


def _pose_deg(name: str, poses: PoseSource) -> dict[str, float]:
    if isinstance(poses, Mapping):
        if name not in poses:
            raise UserInputError(f"pose '{name}' was not read with the sequence")
        entry = poses[name]
        return dict(getattr(entry, "joints_deg", entry))
    return pose_joints_deg(name, poses)


def commanded_joints(params: MoveParams, arm: ArmDescription,
                     poses: PoseSource) -> list[str]:
    """The joints a move commands, in arm order: every unlocked joint of the pose, or the
    unlocked joints named in ``joints``. The others are not part of the motion."""
    names = (_pose_deg(params.pose, poses) if params.pose is not None
             else params.joints or {})
    return [j.name for j in arm.joints if j.name in names and j.locked is None]


def resolve_move_target(params: MoveParams, current_deg: Mapping[str, float],
                        arm: ArmDescription, poses: PoseSource) -> dict[str, float]:
    """Target of a move for every joint of the arm (user degrees, arm order).

    Joints the move does not name keep their ``current_deg`` value; ``relative`` values are
    added to it; locked joints are always at their locked value. ``poses``: the sequence's
    frozen poses (a run uses only these) or a pose folder. Raises :class:`UserInputError`
    for an unknown pose or joint.
    """
    target: dict[str, float] = {}
    for joint in arm.joints:
        if joint.locked is not None:
            target[joint.name] = float(joint.locked)
        elif joint.name in current_deg:
            target[joint.name] = float(current_deg[joint.name])
        else:
            raise UserInputError(f"no current position for joint {joint.name}")
    if params.pose is not None:
        given = _pose_deg(params.pose, poses)
        relative = False
    else:
        given, relative = dict(params.joints or {}), params.relative
    for name, value in given.items():
        if name not in target:
            raise UserInputError(f"unknown joint '{name}' (the arm has "
                                 f"{', '.join(arm.joint_names)})")
        if arm.joint(name).locked is not None:
            continue
        target[name] = target[name] + value if relative else float(value)
    return target


def resolve_checkpoint(params: CheckpointParams, arm: ArmDescription, poses: PoseSource
                       ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Expected end-effector of a checkpoint: ``(position_mm (3,), rotation (3, 3),
    position_tolerance_mm, angle_tolerance_deg)``."""
    from seqrun.arm.kinematics import matrix_from_rpy, pose_from_user_deg

    if params.pose is not None:
        joints = _pose_deg(params.pose, poses)
        joints = {j.name: (j.locked if j.locked is not None else joints.get(j.name, 0.0))
                  for j in arm.joints}
        pose = pose_from_user_deg(arm, joints)
        position, rotation = pose.position_mm, pose.rotation
    else:
        assert params.position_mm is not None and params.rpy_deg is not None
        position = np.asarray(params.position_mm, dtype=float)
        rotation = matrix_from_rpy(np.radians(params.rpy_deg))
    return (np.array(position, dtype=float), np.array(rotation, dtype=float),
            float(params.position_tolerance_mm), float(params.angle_tolerance_deg))
