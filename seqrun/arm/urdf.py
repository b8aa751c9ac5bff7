"""The arm as a URDF document (Unified Robot Description Format), for robot_state_publisher,
RViz, Foxglove and MoveIt: a pure function of the arm description (no I/O).

The tree is seqrun's chain (:mod:`seqrun.arm.kinematics`) joint by joint, so that a URDF
reader's forward kinematics is seqrun's (tests/test_urdf.py compares them to 1e-6 mm):

- links ``<prefix>base`` (the mount), ``<prefix><joint>`` for every joint (the joint's frame
  after its rotation, as seqrun's ``/tf``), ``<prefix>end_effector`` and one link per tool,
  ``<prefix>tool_<name>`` (its TCP frame). With the prefix of seqrun's ``/tf`` (``lwa3/``)
  the link names are the frames seqrun publishes, so RViz draws the model on them as they are.
- joint ``<joint>`` (the arm file's name: the names of ``joint_states``) is ``revolute``
  about z with the frame F_i of the arm file as its origin, the arm file's limits (radians)
  and velocity limit (rad/s); a **locked** joint is ``fixed``, its origin ``F_i·Rz(locked)``:
  it is never commanded, so a URDF user (robot_state_publisher, MoveIt) must not plan it.
- ``<prefix>end_effector`` and the tools hang on fixed joints (the arm file's ``tool`` frame
  and each tool's TCP frame).
- visuals and collision shapes: every capsule of ``geometry.capsules`` and of the tools as a
  cylinder between two spheres. A URDF shape is rigid in one link, while seqrun's capsule
  joins two frame origins: a capsule whose ends are fixed in one link is that link's (exact);
  one whose ends move against each other (the LWA 3's forearm: j4 to j6 bends with j5, whose
  axis does not pass through j4's origin) is drawn through the joint origins between them,
  one capsule per piece (``forearm 1/2``, ``forearm 2/2``): the shape follows the modules,
  seqrun's checks keep the straight segment. A tool without capsules is its tip line: a thin
  visual cylinder, no collision shape (it has no thickness).

Not in the URDF: inertia (the arm file has no masses: the model is for drawing, planning
and collision checking, not for a dynamics simulation), effort limits (the modules limit
current, ``max_current_a``, not torque: effort="0" says "not given"), acceleration and jerk
limits (URDF has no place for them; ros2_control reads them from its joint_limits file).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

import numpy as np

from seqrun.arm.description import ArmDescription, Frame, Tool
from seqrun.arm.kinematics import frame_matrix, rpy_from_matrix
from seqrun.arm.tools import tool_parts

__all__ = ["UrdfJoint", "UrdfShape", "robot_tree", "urdf"]

#: A point counts as on a joint's axis (so that joint's rotation does not move it) within
#: this distance, mm: far below anything the arm file states, far above rounding.
_ON_AXIS_MM = 1e-9
#: The tip line of a tool without capsules, drawn as a cylinder of this radius (mm).
_TIP_LINE_RADIUS_MM = 1.0
_MATERIALS = {"link": "0.55 0.6 0.68 1", "tool": "0.9 0.6 0.15 1"}


@dataclass(frozen=True)
class UrdfJoint:
    """One joint of the tree: ``origin`` is the child's frame in the parent's at zero angle
    (4x4, mm), ``origin_rpy_rad`` its rotation as URDF's roll/pitch/yaw."""

    name: str
    kind: str  # "revolute" or "fixed"
    parent: str
    child: str
    origin: np.ndarray
    origin_rpy_rad: tuple[float, float, float]
    lower_rad: float = 0.0
    upper_rad: float = 0.0
    velocity_rad_s: float = 0.0


@dataclass(frozen=True)
class UrdfShape:
    """A capsule (or a piece of one) in ``link``'s frame: segment ``start_mm``-``end_mm``,
    ``radius_mm``; ``collision`` False: drawn only (a tool's tip line)."""

    name: str
    link: str
    start_mm: tuple[float, float, float]
    end_mm: tuple[float, float, float]
    radius_mm: float
    material: str
    collision: bool = True


def _frame_rpy(frame: Frame | Tool) -> tuple[float, float, float]:
    r, p, y = frame.rpy_deg
    return math.radians(r), math.radians(p), math.radians(y)


def _rot_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)


class _Tree:
    """The chain's frames by index: 0 the mount, 1..n the joints, n+1 the end-effector.
    ``steps[k]`` (k >= 1) is frame k in frame k-1 before joint k turns (B, F2..Fn, E)."""

    def __init__(self, arm: ArmDescription) -> None:
        kin = arm.kinematics
        self.arm = arm
        self.n = arm.dof
        self.steps = [np.eye(4)] + [frame_matrix(f) for f in (kin.base, *kin.links, kin.tool)]
        self.locked = [None] + [j.locked for j in arm.joints] + [None]

    def _turn(self, k: int, vector: np.ndarray, sign: float) -> np.ndarray | None:
        """``Rz(±q_k)·vector`` when it does not depend on q_k: joint k locked, or the point
        on its axis; None when it does."""
        if k > self.n:  # the end-effector: no joint
            return vector
        locked = self.locked[k]
        if locked is not None:
            return _rot_z(sign * math.radians(locked)) @ vector
        if abs(vector[0]) <= _ON_AXIS_MM and abs(vector[1]) <= _ON_AXIS_MM:
            return vector
        return None

    def origin_in(self, b: int, k: int) -> np.ndarray | None:
        """The origin of frame ``b`` in frame ``k`` (mm) when no free joint moves it there;
        None otherwise."""
        point = np.array([0.0, 0.0, 0.0, 1.0])
        if b > k:  # F_{k+1}·Rz(q_{k+1}) ··· F_b·0
            point = self.steps[b] @ point
            for j in range(b - 1, k, -1):
                turned = self._turn(j, point, 1.0)
                if turned is None:
                    return None
                point = self.steps[j] @ turned
        elif b < k:  # Rz(-q_k)·F_k⁻¹ ··· Rz(-q_{b+1})·F_{b+1}⁻¹·0
            for j in range(b + 1, k + 1):
                turned = self._turn(j, np.linalg.solve(self.steps[j], point), -1.0)
                if turned is None:
                    return None
                point = turned
        return point[:3]


def _xyz(values: np.ndarray) -> tuple[float, float, float]:
    return float(values[0]) + 0.0, float(values[1]) + 0.0, float(values[2]) + 0.0


def robot_tree(arm: ArmDescription, prefix: str = ""
               ) -> tuple[list[str], list[UrdfJoint], list[UrdfShape]]:
    """The URDF's links (root first), joints and shapes, link names prefixed with
    ``prefix``."""
    tree = _Tree(arm)
    n = arm.dof
    frame_names = ["base"] + arm.joint_names + ["end_effector"]
    links = [f"{prefix}{name}" for name in frame_names]
    joints: list[UrdfJoint] = []
    frames = [arm.kinematics.base, *arm.kinematics.links]
    for k, joint in enumerate(arm.joints, start=1):
        origin = tree.steps[k]
        rpy = _frame_rpy(frames[k - 1])
        if joint.locked is None:
            lower, upper = (math.radians(v) for v in joint.limits_deg)
            joints.append(UrdfJoint(joint.name, "revolute", links[k - 1], links[k], origin,
                                    rpy, lower, upper,
                                    math.radians(joint.max_velocity_deg_s)))
            continue
        if joint.locked != 0:
            origin = origin @ _rot_z(math.radians(joint.locked))
            roll, pitch, yaw = rpy_from_matrix(origin)
            rpy = (float(roll), float(pitch), float(yaw))
        joints.append(UrdfJoint(joint.name, "fixed", links[k - 1], links[k], origin, rpy))
    joints.append(UrdfJoint(f"{prefix}flange_to_end_effector", "fixed", links[n], links[n + 1],
                            tree.steps[n + 1], _frame_rpy(arm.kinematics.tool)))
    for tool in arm.tools:
        links.append(f"{prefix}tool_{tool.name}")
        joints.append(UrdfJoint(f"{prefix}end_effector_to_tool_{tool.name}", "fixed",
                                links[n + 1], links[-1], frame_matrix(tool),
                                _frame_rpy(tool)))
    index = {name: i for i, name in enumerate(frame_names)}
    shapes: list[UrdfShape] = []
    for capsule in arm.geometry.capsules:
        a, b = sorted((index[capsule.start], index[capsule.end]))
        pieces = _pieces(tree, a, b)
        for number, (k, start, end) in enumerate(pieces, start=1):
            if (a, b) != (index[capsule.start], index[capsule.end]):
                start, end = end, start
            name = capsule.name if len(pieces) == 1 else f"{capsule.name} {number}/{len(pieces)}"
            shapes.append(UrdfShape(name, links[k], _xyz(start), _xyz(end),
                                    float(capsule.radius_mm), "link"))
    for part in tool_parts(arm):
        thick = part.radius_mm > 0
        shapes.append(UrdfShape(part.label, links[n + 1], part.start_mm, part.end_mm,
                                part.radius_mm if thick else _TIP_LINE_RADIUS_MM, "tool",
                                collision=thick))
    return links, joints, shapes


def _pieces(tree: _Tree, a: int, b: int) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """The capsule from frame origin ``a`` to ``b`` (a <= b) as ``(link, start, end)``
    pieces: one when both ends are fixed in one link, else through the origins between
    them, each piece as long as one link carries it."""
    pieces = []
    current = a
    while True:
        for end in range(b, current, -1):
            for k in range(current, end + 1):
                start_point, end_point = tree.origin_in(current, k), tree.origin_in(end, k)
                if start_point is not None and end_point is not None:
                    pieces.append((k, start_point, end_point))
                    break
            else:
                continue
            current = end
            break
        else:  # a = b: a point
            return [(a, np.zeros(3), np.zeros(3))]
        if current == b:
            return pieces


def _number(value: float) -> str:
    return repr(float(value) + 0.0)  # every digit: the reader's FK is seqrun's; no -0.0


def _numbers(values: tuple[float, ...] | np.ndarray) -> str:
    return " ".join(_number(v) for v in values)


def _origin(parent: ET.Element, xyz_m: tuple[float, ...] | np.ndarray,
            rpy_rad: tuple[float, ...] | np.ndarray) -> None:
    ET.SubElement(parent, "origin", xyz=_numbers(xyz_m), rpy=_numbers(rpy_rad))


def _cylinder_pose(start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, tuple[float, ...]]:
    """Middle (m) and roll/pitch/yaw of a URDF cylinder (centred, along its z) from start
    to end (mm): ``Rz(yaw)·Ry(pitch)`` turns z onto the segment (roll 0: the cylinder is
    round), with no angle near the triple's singularity to lose digits."""
    dx, dy, dz = end - start
    return (start + end) / 2000.0, (0.0, math.atan2(math.hypot(dx, dy), dz),
                                    math.atan2(dy, dx))


def _shape_elements(link: ET.Element, shape: UrdfShape) -> None:
    start, end = np.array(shape.start_mm, dtype=float), np.array(shape.end_mm, dtype=float)
    radius = _number(shape.radius_mm / 1000.0)
    kinds = ("visual", "collision") if shape.collision else ("visual",)
    for kind in kinds:
        geometries: list[tuple[np.ndarray, Any, str, dict[str, str]]] = []
        length = float(np.linalg.norm(end - start))
        if length > 0:
            middle, rpy = _cylinder_pose(start, end)
            geometries.append((middle, rpy, "cylinder", {"radius": radius,
                                                          "length": _number(length / 1000.0)}))
        for point in (start, end) if length > 0 else (start,):
            geometries.append((point / 1000.0, np.zeros(3), "sphere", {"radius": radius}))
        for middle, rpy, what, attributes in geometries:
            element = ET.SubElement(link, kind, name=f"{shape.name} {what}")
            _origin(element, middle, rpy)
            ET.SubElement(ET.SubElement(element, "geometry"), what, attributes)
            if kind == "visual":
                ET.SubElement(element, "material", name=shape.material)


def urdf(arm: ArmDescription, prefix: str = "", robot_name: str | None = None) -> str:
    """The URDF document (XML text) of ``arm``: see the module docstring. ``prefix`` goes
    before every link name (``lwa3/``: the frames of seqrun's ``/tf``), ``robot_name``
    (default: the prefix without its slash, else the arm's name) names the robot."""
    name = robot_name or prefix.strip("/") or arm.name
    robot = ET.Element("robot", name=name)
    # the arm's content only (not its file's path): the same arm gives the same text, so
    # run.mcap rebuilt from events.jsonl is the bag written live
    robot.append(ET.Comment(
        f" {arm.name.replace('--', '- -')}: made by `seqrun urdf` from its arm file. "
        "Lengths m, angles rad. "
        "Make it anew from the arm file rather than edit it. "))
    for material, rgba in _MATERIALS.items():
        ET.SubElement(ET.SubElement(robot, "material", name=material), "color", rgba=rgba)
    links, joints, shapes = robot_tree(arm, prefix)
    for link_name in links:
        link = ET.SubElement(robot, "link", name=link_name)
        for shape in shapes:
            if shape.link == link_name:
                _shape_elements(link, shape)
    for joint in joints:
        element = ET.SubElement(robot, "joint", name=joint.name, type=joint.kind)
        ET.SubElement(element, "parent", link=joint.parent)
        ET.SubElement(element, "child", link=joint.child)
        _origin(element, joint.origin[:3, 3] / 1000.0, joint.origin_rpy_rad)
        if joint.kind == "revolute":
            ET.SubElement(element, "axis", xyz="0 0 1")
            ET.SubElement(element, "limit", lower=_number(joint.lower_rad),
                          upper=_number(joint.upper_rad), velocity=_number(joint.velocity_rad_s),
                          effort="0")
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"
