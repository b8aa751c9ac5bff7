"""Field values of the ROS messages seqrun publishes (pure: numpy and the kinematics).

Everything is plain Python (floats, tuples, dicts) in ROS units: radians, metres, seconds,
quaternions ``(x, y, z, w)``; stamps are integer nanoseconds of the Unix epoch.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from seqrun.ros_messages.names import RosNames

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription

#: Colours (r, g, b, a) of the shapes: link volumes, guard planes, obstacles.
CAPSULE_RGBA = (0.26, 0.55, 0.96, 0.45)
GUARD_RGBA = (0.95, 0.62, 0.10, 0.25)
OBSTACLE_RGBA = (0.55, 0.55, 0.55, 0.35)
#: visualization_msgs/Marker's numbers of the shapes.
MARKER_TYPES = {"cube": 1, "sphere": 2, "cylinder": 3}
#: Side of the square drawn for a guard's height or a plane obstacle (m).
PLANE_SIDE_M = 2.0
#: Thickness of those squares (m).
PLANE_THICKNESS_M = 0.002


def stamp_ns(epoch_s: float) -> int:
    """Seconds of the epoch as integer nanoseconds (a ROS stamp, an MCAP log time)."""
    return int(round(epoch_s * 1e9))


def split_stamp(ns: int) -> tuple[int, int]:
    """``builtin_interfaces/Time`` (sec, nanosec) of a stamp in nanoseconds."""
    return ns // 1_000_000_000, ns % 1_000_000_000


def joint_state(names: Sequence[str], positions_deg: Sequence[float],
                velocities_deg_s: Sequence[float] | None = None) -> dict[str, Any]:
    """``sensor_msgs/JointState`` fields (without the header): radians, rad/s."""
    return {"name": list(names),
            "position": [math.radians(float(v)) for v in positions_deg],
            "velocity": ([] if velocities_deg_s is None
                         else [math.radians(float(v)) for v in velocities_deg_s]),
            "effort": []}


def quaternion_xyzw(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of a 3x3 rotation matrix (w >= 0)."""
    m = np.asarray(rotation, dtype=float)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = (((m[2, 1] - m[1, 2]) / s), ((m[0, 2] - m[2, 0]) / s),
             ((m[1, 0] - m[0, 1]) / s), 0.25 * s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = (0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s,
             (m[2, 1] - m[1, 2]) / s)
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = ((m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s,
             (m[0, 2] - m[2, 0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s,
             (m[1, 0] - m[0, 1]) / s)
    norm = math.sqrt(sum(c * c for c in q))
    x, y, z, w = (float(c) / norm for c in q)
    return (-x, -y, -z, -w) if w < 0 else (x, y, z, w)


@dataclass(frozen=True)
class Transform:
    """One ``geometry_msgs/TransformStamped`` (without the stamp): ``child`` in ``parent``."""

    parent: str
    child: str
    translation_m: tuple[float, float, float]
    rotation_xyzw: tuple[float, float, float, float]


def _frames(arm: ArmDescription, joints_deg: Sequence[float]) -> np.ndarray:
    """Frames of the joints (after their rotation), then the end-effector, in the base
    frame, mm: :func:`seqrun.arm.kinematics.frame_transforms` (the validator's FK)."""
    from seqrun.arm.kinematics import Chain, frame_transforms

    return frame_transforms(Chain.from_arm(arm), np.radians(np.asarray(joints_deg, float)))


def transforms(arm: ArmDescription, joints_deg: Sequence[float],
               names: RosNames | None = None) -> list[Transform]:
    """Every link of the chain as tf sees it: base -> j1 -> ... -> jn -> end_effector, each
    frame in its parent (seqrun's FK of ``joints_deg``, user degrees)."""
    names = names or RosNames.of(arm)
    frames = _frames(arm, joints_deg)
    parents = np.concatenate([np.eye(4)[None], frames[:-1]])
    # parent^-1 . frame of rigid frames: R_p^T R, R_p^T (t - t_p)
    rotations = np.einsum("kji,kjl->kil", parents[:, :3, :3], frames[:, :3, :3])
    offsets = np.einsum("kji,kj->ki", parents[:, :3, :3],
                        frames[:, :3, 3] - parents[:, :3, 3]) / 1000.0
    ids = names.frames
    return [Transform(ids[k], ids[k + 1], _point(offsets[k]), quaternion_xyzw(rotations[k]))
            for k in range(len(frames))]


@dataclass(frozen=True)
class Shape:
    """One marker: a ``visualization_msgs/Marker`` / a Foxglove scene primitive, in the
    arm's base frame. ``kind``: cube, sphere or cylinder (the cylinder's axis is the
    pose's z); ``scale_m``: its size (a sphere's and cylinder's diameters, then height)."""

    namespace: str
    id: int
    kind: str
    position_m: tuple[float, float, float]
    rotation_xyzw: tuple[float, float, float, float]
    scale_m: tuple[float, float, float]
    rgba: tuple[float, float, float, float]
    #: The capsule, guard or obstacle it draws.
    label: str = ""


def _rotation_z_to(direction: np.ndarray) -> tuple[float, float, float, float]:
    """The rotation that turns the z axis onto ``direction``."""
    d = np.asarray(direction, float)
    n = float(np.linalg.norm(d))
    if n == 0.0:
        return (0.0, 0.0, 0.0, 1.0)
    z = d / n
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return quaternion_xyzw(np.column_stack([x, y, z]))


def _point(values: Any) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))


def capsule_shapes(arm: ArmDescription, joints_deg: Sequence[float]) -> list[Shape]:
    """The link volumes at ``joints_deg``: per capsule a cylinder between its two frame
    origins and a sphere at each end (the capsule's rounded ends)."""
    capsules = arm.geometry.capsules
    if not capsules:
        return []
    frames = _frames(arm, joints_deg)
    index = {name: k for k, name in enumerate(arm.joint_names)}
    origins = {"base": np.zeros(3), "end_effector": frames[-1][:3, 3]}
    origins.update({name: frames[k][:3, 3] for name, k in index.items()})
    out: list[Shape] = []
    for n, capsule in enumerate(capsules):
        a = origins[capsule.start] / 1000.0
        b = origins[capsule.end] / 1000.0
        d = 2.0 * capsule.radius_mm / 1000.0
        length = float(np.linalg.norm(b - a))
        out.append(Shape("capsules", 3 * n, "cylinder", _point((a + b) / 2),
                         _rotation_z_to(b - a), (d, d, length), CAPSULE_RGBA, capsule.name))
        for k, end in ((1, a), (2, b)):
            out.append(Shape("capsules", 3 * n + k, "sphere", _point(end), (0.0, 0.0, 0.0, 1.0),
                             (d, d, d), CAPSULE_RGBA, capsule.name))
    return out


def static_shapes(arm: ArmDescription) -> list[Shape]:
    """What does not move with the arm: each guard's height as a square at ``min_z_mm``
    (the watched points stay above it) and the obstacles (plane, box, cylinder)."""
    from seqrun.arm.kinematics import matrix_from_rpy

    out: list[Shape] = []
    flat = (PLANE_SIDE_M, PLANE_SIDE_M, PLANE_THICKNESS_M)
    for n, guard in enumerate(arm.workspace.guards):
        out.append(Shape("guards", n, "cube", (0.0, 0.0, guard.min_z_mm / 1000.0),
                         (0.0, 0.0, 0.0, 1.0), flat, GUARD_RGBA, guard.name))
    for n, obstacle in enumerate(arm.geometry.obstacles):
        if obstacle.plane is not None:
            p = obstacle.plane
            # the square's top face on the plane (its thickness inside the obstacle)
            normal = np.asarray(p.normal, float) / np.linalg.norm(p.normal)
            centre = np.asarray(p.point_mm, float) / 1000.0 - normal * PLANE_THICKNESS_M / 2
            out.append(Shape("obstacles", n, "cube", _point(centre), _rotation_z_to(normal),
                             flat, OBSTACLE_RGBA, obstacle.name))
        elif obstacle.box is not None:
            box = obstacle.box
            rotation = matrix_from_rpy(np.radians(box.rpy_deg))
            out.append(Shape("obstacles", n, "cube", _point(np.asarray(box.center_mm) / 1000.0),
                             quaternion_xyzw(rotation),
                             _point(np.asarray(box.size_mm) / 1000.0), OBSTACLE_RGBA,
                             obstacle.name))
        elif obstacle.cylinder is not None:
            cyl = obstacle.cylinder
            axis = np.asarray(cyl.axis, float) / np.linalg.norm(cyl.axis)
            centre = np.asarray(cyl.base_mm, float) / 1000.0 + axis * cyl.height_mm / 2000.0
            d = 2.0 * cyl.radius_mm / 1000.0
            out.append(Shape("obstacles", n, "cylinder", _point(centre), _rotation_z_to(axis),
                             (d, d, cyl.height_mm / 1000.0), OBSTACLE_RGBA, obstacle.name))
    return out


def marker_shapes(arm: ArmDescription, joints_deg: Sequence[float] | None = None
                  ) -> list[Shape]:
    """The guards and obstacles, and (given the joints) the link capsules."""
    shapes = static_shapes(arm)
    if joints_deg is not None:
        shapes += capsule_shapes(arm, joints_deg)
    return shapes
