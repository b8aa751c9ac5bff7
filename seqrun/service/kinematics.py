"""The arm's kinematics as the faces ask for it (the pure maths is
:mod:`seqrun.arm.kinematics`, :mod:`seqrun.arm.ik`).

- the end effector of a reading: ``seqrun status``, the session's status, a run's status
  over its control socket, the live view;
- ``seqrun fk`` and ``seqrun ik``: a pose of joint angles, joint angles of a tool target;
- the console's 3D view: the chain as frames, guards, link volumes, obstacles;
- ``seqrun urdf``, the ROS node's ``robot_description``: the arm as a URDF document.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.arm.kinematics import Pose

__all__ = ["ForwardKinematics", "InverseKinematics", "arm_scene", "end_effector",
           "fixed_transforms", "link_transforms", "robot_description",
           "end_effector_pose", "forward_kinematics", "inverse_kinematics"]


def end_effector(arm: ArmDescription, joints_deg: Sequence[float]) -> dict[str, list[float]]:
    """``{"position_mm": [x, y, z], "rpy_deg": [roll, pitch, yaw]}`` (rounded to 1 µm and
    0.001°) of the end effector with every joint at ``joints_deg`` (user degrees)."""
    import numpy as np

    from seqrun.arm.kinematics import Chain, fk, rpy_from_matrix

    frame = fk(Chain.from_arm(arm), np.radians(np.asarray(joints_deg, dtype=float)))
    return {"position_mm": [round(float(x), 3) for x in frame[:3, 3]],
            "rpy_deg": [round(float(x), 3)
                        for x in np.degrees(rpy_from_matrix(frame[:3, :3]))]}


def end_effector_pose(arm: ArmDescription, joints_deg: Sequence[float]
                      ) -> tuple[list[float], list[float]]:
    """``([x, y, z] mm, [roll, pitch, yaw] deg)`` of the end effector, unrounded (a live
    view formats them itself)."""
    import numpy as np

    from seqrun.arm.kinematics import Chain, fk, rpy_from_matrix

    frame = fk(Chain.from_arm(arm), np.radians(np.asarray(joints_deg, dtype=float)))
    return ([float(x) for x in frame[:3, 3]],
            [float(x) for x in np.degrees(rpy_from_matrix(frame[:3, :3]))])


@dataclass
class ForwardKinematics:
    """``seqrun fk``: the pose and what the operator should know about the joints given."""

    pose: Pose
    #: One line each: a locked joint given another value, a joint outside its limits.
    notes: list[str] = field(default_factory=list)


def forward_kinematics(arm: ArmDescription,
                       joints: Sequence[float] | Mapping[str, float]) -> ForwardKinematics:
    """The end-effector pose of ``joints`` (user degrees: one per joint, or a pose's by
    name). A maths question: a locked joint given another value is computed as given, with
    a note that the arm would not do it. Bad joints: :class:`~seqrun.errors.UserInputError`."""
    from seqrun.arm.kinematics import LOCKED_TOLERANCE_DEG, pose_from_user_deg
    from seqrun.errors import UserInputError

    given = joints if isinstance(joints, Mapping) else dict(zip(arm.joint_names, joints))
    off = [j for j in arm.joints if j.locked is not None and j.name in given
           and abs(given[j.name] - j.locked) > LOCKED_TOLERANCE_DEG]
    notes = [f"note: {joint.name} is locked at {joint.locked:g} deg on the arm; computed "
             f"with {given[joint.name]:g} deg as given" for joint in off]
    maths_arm = arm if not off else arm.model_copy(update={"joints": [
        j.model_copy(update={"locked": None}) if j in off else j for j in arm.joints]})
    try:
        pose = pose_from_user_deg(maths_arm, joints)
    except ValueError as exc:  # locked joint moved, unknown joint in a pose file, ...
        raise UserInputError(str(exc)) from None
    for joint in arm.joints:
        lo, hi = joint.limits_deg
        value = given.get(joint.name)
        if value is not None and not lo <= value <= hi:
            notes.append(f"note: {joint.name} {value:g} deg is outside its limits "
                         f"[{lo:g}, {hi:g}]")
    return ForwardKinematics(pose, notes)


@dataclass
class InverseKinematics:
    """``seqrun ik``: the solution (None: unreachable, ``unreachable`` says why), the seed
    it started from (user degrees, every joint) and the tool it put at the target."""

    solution: Any
    seed_deg: Any
    tool: str | None
    unreachable: str | None = None


def inverse_kinematics(arm: ArmDescription, position_mm: Sequence[float],
                       rpy_deg: Sequence[float], *, tool: str | None,
                       seed: Sequence[float] | Mapping[str, float]) -> InverseKinematics:
    """Joint angles that put ``tool`` (None: the arm's default, else the end-effector
    frame) at the position and orientation, inside the joint limits, from ``seed`` (user
    degrees). A bad seed or an unknown tool: :class:`~seqrun.errors.UserInputError`."""
    from seqrun.arm.cartesian import unknown_tool
    from seqrun.arm.ik import IkSolver, Unreachable, target_frame
    from seqrun.arm.kinematics import user_joint_values
    from seqrun.errors import UserInputError

    try:
        seed_deg = user_joint_values(arm, seed)
    except ValueError as exc:
        raise UserInputError(f"seed: {exc}") from None
    try:
        solver = IkSolver(arm, tool)
    except KeyError:
        raise UserInputError(unknown_tool(arm, tool)) from None
    found = arm.tool(tool)
    name = found.name if found is not None else None
    try:
        solution = solver.solve(target_frame(position_mm, rpy_deg), seed_deg)
    except Unreachable as exc:
        return InverseKinematics(None, seed_deg, name, str(exc))
    return InverseKinematics(solution, seed_deg, name)


def arm_scene(arm: ArmDescription) -> dict[str, Any]:
    """What a 3D view needs of the arm: the joints (limits, locked value), the chain as 4x4
    frames (the view multiplies them with Rz(q) per joint, the reference convention of
    :mod:`seqrun.arm.kinematics`, computed by the code the validator uses), the guards,
    link volumes, the tools' volumes (in the end-effector frame; radius 0: a tip line) and
    obstacles."""
    from seqrun.arm.kinematics import Chain
    from seqrun.arm.tools import tool_parts

    def rows(matrix: Any) -> list[list[float]]:
        return [[round(float(v), 9) for v in row] for row in matrix]

    chain = Chain.from_arm(arm)
    return {
        "name": arm.name,
        "joints": [{"name": j.name, "module": j.module, "limits_deg": list(j.limits_deg),
                    "locked": j.locked, "max_velocity_deg_s": j.max_velocity_deg_s}
                   for j in arm.joints],
        "chain": {"base": rows(chain.base), "links": [rows(m) for m in chain.links],
                  "tool": rows(chain.tool)},
        "guards": [{"name": g.name, "min_z_mm": g.min_z_mm, "points": list(g.points)}
                   for g in arm.workspace.guards],
        "capsules": [{"name": c.name, "start": c.start, "end": c.end,
                      "radius_mm": c.radius_mm} for c in arm.geometry.capsules],
        "tool_parts": [{"label": t.label, "tool": t.tool, "start_mm": list(t.start_mm),
                        "end_mm": list(t.end_mm), "radius_mm": t.radius_mm}
                       for t in tool_parts(arm)],
        "obstacles": [o.model_dump(mode="json", exclude_none=True)
                      for o in arm.geometry.obstacles],
    }


def link_transforms(arm: ArmDescription, joints_deg: Sequence[float], prefix: str
                    ) -> list[tuple[str, str, tuple[float, float, float],
                                    tuple[float, float, float, float]]]:
    """The chain at ``joints_deg`` (user degrees, every joint) as a tree of frames, each
    relative to its parent: ``(parent, child, translation_m, quaternion_xyzw)``, from
    ``{prefix}base`` through ``{prefix}<joint>`` (each joint's frame after its rotation) to
    ``{prefix}end_effector``, by the forward kinematics the validator uses. What a ``/tf``
    publisher sends."""
    import numpy as np

    from seqrun.arm.kinematics import Chain, frame_transforms

    frames = frame_transforms(Chain.from_arm(arm),
                              np.radians(np.asarray(joints_deg, dtype=float)))
    names = [f"{prefix}base"] + [f"{prefix}{j.name}" for j in arm.joints] + [f"{prefix}end_effector"]
    out = []
    parent_frame = np.eye(4)
    for k, frame in enumerate(frames):
        relative = np.linalg.solve(parent_frame, frame)
        translation = tuple(float(v) / 1000.0 for v in relative[:3, 3])
        out.append((names[k], names[k + 1], translation, _quaternion_xyzw(relative[:3, :3])))
        parent_frame = frame
    return out  # type: ignore[return-value]


def _quaternion_xyzw(rotation: Any) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w; w >= 0) of a rotation matrix (Shepperd's method:
    the largest of the four terms first, so no division by a small number)."""
    import math

    m = rotation
    trace = float(m[0, 0] + m[1, 1] + m[2, 2])
    if trace > 0:
        s = math.sqrt(trace + 1.0) * 2
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = (s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = ((m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4, (m[1, 0] - m[0, 1]) / s)
    norm = math.sqrt(sum(float(v) * float(v) for v in q))
    sign = -1.0 if q[3] < 0 else 1.0
    x, y, z, w = (sign * float(v) / norm for v in q)
    return (x, y, z, w)


def robot_description(arm: ArmDescription, frame_prefix: str = "") -> str:
    """The arm as a URDF document (:mod:`seqrun.arm.urdf`), its link names prefixed with
    ``frame_prefix`` (``lwa3/``: the frames of seqrun's ``/tf``): what ``seqrun urdf``
    writes, the ROS node publishes on ``robot_description`` and run.mcap carries."""
    from seqrun.arm.urdf import urdf

    return urdf(arm, frame_prefix)


def fixed_transforms(arm: ArmDescription, prefix: str
                     ) -> list[tuple[str, str, tuple[float, float, float],
                                     tuple[float, float, float, float]]]:
    """The frames that never move against their parent, as :func:`link_transforms` gives
    them ``(parent, child, translation_m, quaternion_xyzw)``: the URDF's fixed joints (a
    locked joint, the end-effector on the flange, the tools' TCPs): what ``/tf_static``
    carries once, where ``/tf`` carries the others."""
    from seqrun.arm.urdf import robot_tree

    _, joints, _ = robot_tree(arm, prefix)
    out = []
    for joint in joints:
        if joint.kind == "fixed":
            x, y, z = (float(v) / 1000.0 for v in joint.origin[:3, 3])
            out.append((joint.parent, joint.child, (x, y, z),
                        _quaternion_xyzw(joint.origin[:3, :3])))
    return out
