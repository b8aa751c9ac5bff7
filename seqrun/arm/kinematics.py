"""Forward kinematics of a serial revolute chain, vectorised over many configurations.

Pure numpy, no I/O. The chain convention is the reference's (thesis 3.2)::

    T(q) = B · Rz(q1) · F2·Rz(q2) · F3·Rz(q3) · … · Fn·Rz(qn) · E

with ``B`` the mount-to-joint-1 frame, ``Fi`` the frame of joint i in joint i-1, ``E`` the
flange-to-end-effector frame; every joint turns about its own z axis. Angles are radians in
user coordinates (Totem = zeros), lengths millimetres.

Every function takes configurations of shape ``(..., n)`` and returns ``(..., ...)`` with the
same leading shape: a dry run evaluates thousands of samples in one call. The only Python
loop runs over the n joints of the chain, never over samples.

Orientation as roll/pitch/yaw is the reference's ZYX convention ``R = Rz(yaw) Ry(pitch)
Rx(roll)``; it is singular at pitch = ±90°, so orientations are compared as rotation matrices
(:func:`orientation_error`), never as angle triples.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple, cast

import numpy as np

from seqrun.arm.description import GuardPoint

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription, Frame, Tool

__all__ = [
    "GUARD_POINT_FRAMES",
    "Chain",
    "Pose",
    "fk",
    "frame_transforms",
    "heights_of_points",
    "jacobian",
    "matrix_from_rpy",
    "orientation_error",
    "frame_origins",
    "point_heights",
    "point_positions",
    "points_of_origins",
    "pose_from_user_deg",
    "rpy_from_matrix",
    "user_joint_values",
]

#: Which frame's origin each guard point is, as an index into :func:`frame_transforms`
#: (0 = joint 1, ..., n-1 = joint n, n = tool). A joint frame's origin lies on that joint's
#: axis, so it is the point the joint physically turns around: the shoulder is where joint 2
#: (first pitch) sits, the elbow joint 4, the wrist joint 6 (wrist pitch), the flange joint 7
#: (the reference's E goes "flange to end-effector", so joint 7's origin is the flange).
#: These joint numbers are those of a 7-joint arm like the LWA 3.
GUARD_POINT_FRAMES: dict[GuardPoint, int] = {
    "shoulder": 1,
    "elbow": 3,
    "wrist": 5,
    "flange": 6,
}


def _homogeneous(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    frame = np.zeros(np.broadcast_shapes(rotation.shape[:-2], translation.shape[:-1]) + (4, 4))
    frame[..., :3, :3] = rotation
    frame[..., :3, 3] = translation
    frame[..., 3, 3] = 1.0
    return frame


def _cos_sin_deg(angle_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of degrees, exact for quarter turns (cos 90° is 0, not 6e-17), because the
    reference frames are quarter turns and exact zeros keep printed matrices clean."""
    angle_deg = np.asarray(angle_deg, dtype=float)
    quarter = np.remainder(angle_deg, 360.0) / 90.0
    exact = quarter == np.round(quarter)
    index = np.round(quarter).astype(int) % 4
    cos = np.where(exact, np.array([1.0, 0.0, -1.0, 0.0])[index], np.cos(np.radians(angle_deg)))
    sin = np.where(exact, np.array([0.0, 1.0, 0.0, -1.0])[index], np.sin(np.radians(angle_deg)))
    return cos, sin


def frame_matrix(frame: Frame | Tool) -> np.ndarray:
    """The 4x4 transform of a frame or tool (xyz in mm, rpy in degrees)."""
    cos, sin = _cos_sin_deg(np.asarray(frame.rpy_deg, dtype=float))
    return _homogeneous(_rpy_matrix(cos, sin), np.asarray(frame.xyz_mm, dtype=float))


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=float)  # own copy, so freezing it cannot affect the caller
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class Chain:
    """The fixed geometry of a serial chain of revolute joints (4x4 homogeneous frames, mm).

    ``links[k]`` is the frame of joint k+2 in the frame of joint k+1 (the reference's F2..Fn).
    The arrays are read-only so that a chain shared between threads cannot change.
    """

    base: np.ndarray  # (4, 4) mount -> joint 1, before Rz(q1)
    links: np.ndarray  # (n-1, 4, 4) F2 .. Fn
    tool: np.ndarray  # (4, 4) joint n (flange) -> end-effector
    _turns: _Turns = field(init=False, repr=False)

    def __post_init__(self) -> None:
        base, links, tool = (_readonly(a) for a in (self.base, self.links, self.tool))
        if base.shape != (4, 4) or tool.shape != (4, 4):
            raise ValueError("base and tool must be 4x4 homogeneous frames")
        if links.ndim != 3 or links.shape[1:] != (4, 4):
            raise ValueError(f"links must have shape (n-1, 4, 4), not {links.shape}")
        object.__setattr__(self, "base", base)
        object.__setattr__(self, "links", links)
        object.__setattr__(self, "tool", tool)
        object.__setattr__(self, "_turns", _turn_terms(base, links))

    @property
    def dof(self) -> int:
        return len(self.links) + 1

    @classmethod
    def from_arm(cls, arm: ArmDescription) -> Chain:
        """The chain of ``arm.kinematics``; one per kinematics object in a process (a
        validation, its dry run and the executor's checks ask for it a dozen times)."""
        kin = arm.kinematics
        kept = _chains.get(id(kin))
        if kept is not None and kept[0]() is kin:
            return kept[1]
        links = (np.stack([frame_matrix(f) for f in kin.links]) if kin.links
                 else np.zeros((0, 4, 4)))
        chain = cls(base=frame_matrix(kin.base), links=links, tool=frame_matrix(kin.tool))
        try:
            kept = (weakref.ref(kin), chain)
        except TypeError:  # a kinematics object without weak references: not kept
            return chain
        if len(_chains) >= _CHAINS_KEPT:
            _chains.clear()
        _chains[id(kin)] = kept
        return chain


class _Turns(NamedTuple):
    """``F·Rz(q) = cos_term·cos q + sin_term·sin q + constant`` for B, F2 .. Fn (each
    ``(n, 4, 4)``), except for the frames in ``general``, which take the product itself
    (``frames``: B, F2 .. Fn as they are)."""

    cos_term: np.ndarray
    sin_term: np.ndarray
    constant: np.ndarray
    general: tuple[int, ...]
    frames: np.ndarray


def _turn_terms(base: np.ndarray, links: np.ndarray) -> _Turns:
    """The :class:`_Turns` of a chain.

    ``F·Rz(q)`` keeps F's columns 2 and 3 and mixes columns 0 and 1 by cos and sin. When a
    row has at most one non-zero in those two columns (quarter-turn frames, as the LWA 3's),
    every entry is one rounded product: exactly what the 4x4 BLAS product computes whatever
    its order of summation or fused multiply-adds; adding ``constant`` (+0 where F·Rz has
    a zero) gives zeros the sign the product gives them (tests/test_kinematics.py compares
    the two bit for bit)."""
    frames = np.concatenate([base[None], links])
    clean = frames + 0.0
    exact = np.all((clean[..., 0] == 0) | (clean[..., 1] == 0), axis=-1)
    cos_term, sin_term, constant = (np.zeros_like(clean) for _ in range(3))
    cos_term[..., 0], cos_term[..., 1] = clean[..., 0], clean[..., 1]
    sin_term[..., 0], sin_term[..., 1] = clean[..., 1], -clean[..., 0]
    constant[..., 2:] = clean[..., 2:]
    for array in (cos_term, sin_term, constant, frames):
        array.setflags(write=False)
    return _Turns(cos_term, sin_term, constant, tuple(np.flatnonzero(~exact).tolist()), frames)


_CHAINS_KEPT = 16
_chains: dict[int, tuple[weakref.ref, Chain]] = {}


def _rot_z(q: np.ndarray) -> np.ndarray:
    """(...,) angles -> (..., 4, 4) pure rotations about z."""
    c, s = np.cos(q), np.sin(q)
    rot = np.zeros(q.shape + (4, 4))
    rot[..., 0, 0] = c
    rot[..., 0, 1] = -s
    rot[..., 1, 0] = s
    rot[..., 1, 1] = c
    rot[..., 2, 2] = 1.0
    rot[..., 3, 3] = 1.0
    return rot


def _joint_angles(chain: Chain, q_rad: np.ndarray | Sequence[float]) -> np.ndarray:
    q = np.asarray(q_rad, dtype=float)
    if q.ndim == 0 or q.shape[-1] != chain.dof:
        raise ValueError(f"expected joint angles of shape (..., {chain.dof}), got {q.shape}")
    return q


def _turned_frames(chain: Chain, q: np.ndarray) -> np.ndarray:
    """``B·Rz(q1), F2·Rz(q2), …, Fn·Rz(qn)``: ``(..., n, 4, 4)``, equal bit for bit to the
    4x4 products (see :func:`_turn_terms`), all joints at once instead of n BLAS calls."""
    cos_term, sin_term, constant, general, frames = chain._turns
    if q.ndim == 1:
        turned = cos_term * np.cos(q)[:, None, None]
        turned += sin_term * np.sin(q)[:, None, None]
        turned += constant
    else:
        # Joint-major (n, samples): each operation runs over all samples at once; only the
        # entries that Rz changes (rows 0-2 of columns 0 and 1) are computed.
        flat = q.reshape(-1, q.shape[-1])
        cos, sin = np.cos(flat).T.copy(), np.sin(flat).T.copy()
        turned = np.empty(flat.shape + (4, 4))
        turned[...] = constant
        for i, j in _TURNED_ENTRIES:
            entry = cos_term[:, i, j, None] * cos
            entry += sin_term[:, i, j, None] * sin
            entry += constant[:, i, j, None]
            turned[:, :, i, j] = entry.T
        turned = turned.reshape(q.shape + (4, 4))
    for k in general:  # not a quarter-turn frame: the product itself
        turned[..., k, :, :] = frames[k] @ _rot_z(q[..., k])
    return turned


_TURNED_ENTRIES = [(i, j) for i in range(3) for j in range(2)]


def frame_transforms(chain: Chain, q_rad: np.ndarray | Sequence[float]) -> np.ndarray:
    """Frames of joints 1..n (each after its own rotation), then the tool: ``(..., n+1, 4, 4)``.

    Frame i is ``B · Rz(q1) · F2·Rz(q2) · … · Fi·Rz(qi)``; the last entry is :func:`fk`.
    """
    q = _joint_angles(chain, q_rad)
    turned = _turned_frames(chain, q)  # (..., n, 4, 4)
    n = chain.dof
    frames = np.empty(q.shape[:-1] + (n + 1, 4, 4))
    if q.ndim == 1:
        frames[...] = _frames_of_one(chain, turned)
        return frames
    frames[..., 0, :, :] = turned[..., 0, :, :]
    for k in range(1, n):  # each product straight into its place (the same BLAS call)
        np.matmul(frames[..., k - 1, :, :], turned[..., k, :, :], out=frames[..., k, :, :])
    np.matmul(frames[..., n - 1, :, :], chain.tool, out=frames[..., n, :, :])
    return frames


def frame_origins(chain: Chain, q_rad: np.ndarray | Sequence[float],
                  ee_points: np.ndarray | None = None) -> np.ndarray:
    """The origins (mm) of :func:`frame_transforms`' frames, ``(..., n+1, 3)``, the same bits
    without keeping every 4x4 frame (guards and link volumes along a path need the points).
    ``ee_points`` ``(m, 3)``: points of the end-effector frame (a tool's volume), appended
    in the base frame: ``(..., n+1+m, 3)``."""
    q = _joint_angles(chain, q_rad)
    turned = _turned_frames(chain, q)
    n = chain.dof
    extra = 0 if ee_points is None else len(ee_points)
    origins = np.empty(q.shape[:-1] + (n + 1 + extra, 3))
    current = turned[..., 0, :, :]
    origins[..., 0, :] = current[..., :3, 3]
    for k in range(1, n):
        current = current @ turned[..., k, :, :]
        origins[..., k, :] = current[..., :3, 3]
    end = current @ chain.tool
    origins[..., n, :] = end[..., :3, 3]
    if ee_points is not None and extra:
        origins[..., n + 1:, :] = (np.einsum("...ij,mj->...mi", end[..., :3, :3], ee_points)
                                   + end[..., None, :3, 3])
    return origins


def _frames_of_one(chain: Chain, turned: np.ndarray) -> list[np.ndarray]:
    """The frames of one configuration from its :func:`_turned_frames`, each its own 4x4
    array: ``ndarray.dot`` is the same BLAS product as ``@`` with a third of the overhead."""
    turns = list(turned)
    frame = turns[0]
    frames = [frame]
    for turn in turns[1:]:
        frame = frame.dot(turn)
        frames.append(frame)
    frames.append(frame.dot(chain.tool))
    return frames


def fk(chain: Chain, q_rad: np.ndarray | Sequence[float]) -> np.ndarray:
    """End-effector frame in the base frame, ``(..., 4, 4)``, translation in mm."""
    q = _joint_angles(chain, q_rad)
    turned = _turned_frames(chain, q)
    current = turned[..., 0, :, :]
    for k in range(1, chain.dof):
        current = current @ turned[..., k, :, :]
    return current @ chain.tool


def point_positions(chain: Chain, q_rad: np.ndarray | Sequence[float]) -> dict[GuardPoint, np.ndarray]:
    """Positions (mm, ``(..., 3)``) of every guard point, see :data:`GUARD_POINT_FRAMES`.

    The end-effector is the tool point (the origin of :func:`fk`).
    """
    _check_guard_frames(chain.dof)
    return points_of_origins(frame_origins(chain, q_rad))


def point_heights(chain: Chain, q_rad: np.ndarray | Sequence[float]) -> dict[GuardPoint, float]:
    """z (mm) of every guard point of one configuration ``(n,)``: the z of
    :func:`point_positions`, bit for bit, without the frames array and the position views
    (the run-time guard check asks every control cycle)."""
    q = _joint_angles(chain, q_rad)
    if q.ndim != 1:
        raise ValueError(f"expected one configuration of shape ({chain.dof},), got {q.shape}")
    _check_guard_frames(chain.dof)
    frames = _frames_of_one(chain, _turned_frames(chain, q))
    heights: dict[GuardPoint, float] = {
        name: float(frames[index][2, 3]) for name, index in GUARD_POINT_FRAMES.items()}
    heights["end_effector"] = float(frames[-1][2, 3])
    return heights


def heights_of_points(chain: Chain, q_rad: np.ndarray | Sequence[float],
                      ee_points: np.ndarray | None = None
                      ) -> tuple[dict[GuardPoint, float], list[float]]:
    """:func:`point_heights`, and the z (mm) of ``ee_points`` ``(m, 3)`` of the end-effector
    frame (a tool's volume) from the same forward kinematics."""
    q = _joint_angles(chain, q_rad)
    if q.ndim != 1:
        raise ValueError(f"expected one configuration of shape ({chain.dof},), got {q.shape}")
    _check_guard_frames(chain.dof)
    frames = _frames_of_one(chain, _turned_frames(chain, q))
    heights: dict[GuardPoint, float] = {
        name: float(frames[index][2, 3]) for name, index in GUARD_POINT_FRAMES.items()}
    end = frames[-1]
    heights["end_effector"] = float(end[2, 3])
    if ee_points is None or not len(ee_points):
        return heights, []
    return heights, (ee_points @ end[2, :3] + end[2, 3]).tolist()


def _check_guard_frames(dof: int) -> None:
    needed = max(GUARD_POINT_FRAMES.values()) + 1
    if dof < needed:
        raise ValueError(f"guard points are defined for arms with at least {needed} joints, "
                         f"this chain has {dof}")


def points_of_origins(origins: np.ndarray, dof: int | None = None
                      ) -> dict[GuardPoint, np.ndarray]:
    """:func:`point_positions` from :func:`frame_origins` already computed (one forward
    kinematics for the guards and the link volumes along a path); ``dof``: the chain's,
    when the origins end with points of the end-effector frame."""
    dof = origins.shape[-2] - 1 if dof is None else dof
    _check_guard_frames(dof)
    points: dict[GuardPoint, np.ndarray] = {
        name: origins[..., index, :] for name, index in GUARD_POINT_FRAMES.items()}
    points["end_effector"] = origins[..., dof, :]
    return points


def rpy_from_matrix(rotation: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (rad, ``(..., 3)``, each in (-π, π]) of ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

    Accepts ``(..., 3, 3)`` or homogeneous ``(..., 4, 4)`` matrices. These are the reference's
    formulas; at pitch = ±90° roll and yaw are not separable and the triple loses them (and
    loses digits close to it): compare orientations with :func:`orientation_error`.
    """
    r = np.asarray(rotation, dtype=float)
    roll = np.arctan2(r[..., 2, 1], r[..., 2, 2])
    pitch = np.arctan2(-r[..., 2, 0], np.hypot(r[..., 0, 0], r[..., 1, 0]))
    yaw = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    rpy = np.stack([roll, pitch, yaw], axis=-1)
    # atan2(-0.0, -1) is -π: report half turns as +π whatever the sign of a zero entry,
    # and a plain 0 instead of -0 (+ 0.0 turns -0.0 into 0.0).
    return np.where(rpy == -np.pi, np.pi, rpy) + 0.0


def matrix_from_rpy(rpy_rad: np.ndarray | Sequence[float]) -> np.ndarray:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` as ``(..., 3, 3)`` from roll, pitch, yaw ``(..., 3)`` rad."""
    rpy = np.asarray(rpy_rad, dtype=float)
    if rpy.shape[-1:] != (3,):
        raise ValueError(f"expected (..., 3) roll/pitch/yaw, got shape {rpy.shape}")
    return _rpy_matrix(np.cos(rpy), np.sin(rpy))


def _rpy_matrix(cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` from cos and sin of (roll, pitch, yaw), ``(..., 3)``."""
    cr, cp, cy = cos[..., 0], cos[..., 1], cos[..., 2]
    sr, sp, sy = sin[..., 0], sin[..., 1], sin[..., 2]
    rot = np.empty(cos.shape[:-1] + (3, 3))
    rot[..., 0, 0] = cy * cp
    rot[..., 0, 1] = cy * sp * sr - sy * cr
    rot[..., 0, 2] = cy * sp * cr + sy * sr
    rot[..., 1, 0] = sy * cp
    rot[..., 1, 1] = sy * sp * sr + cy * cr
    rot[..., 1, 2] = sy * sp * cr - cy * sr
    rot[..., 2, 0] = -sp
    rot[..., 2, 1] = cp * sr
    rot[..., 2, 2] = cp * cr
    return rot


def orientation_error(rotation_a: np.ndarray, rotation_b: np.ndarray) -> np.ndarray:
    """Angle (rad, in [0, π]) of the rotation ``Ra^T Rb`` that turns orientation a into b.

    ``atan2(sin, cos)`` from the skew part and the trace keeps full precision at both ends,
    where ``arccos((trace - 1) / 2)`` loses half the digits near 0 and near π.
    Accepts ``(..., 3, 3)`` or homogeneous ``(..., 4, 4)`` matrices.
    """
    a = np.asarray(rotation_a, dtype=float)[..., :3, :3]
    b = np.asarray(rotation_b, dtype=float)[..., :3, :3]
    relative = np.einsum("...ki,...kj->...ij", a, b)  # Ra^T Rb
    cos_angle = (np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0
    skew = np.stack([relative[..., 2, 1] - relative[..., 1, 2],
                     relative[..., 0, 2] - relative[..., 2, 0],
                     relative[..., 1, 0] - relative[..., 0, 1]], axis=-1)
    sin_angle = np.linalg.norm(skew, axis=-1) / 2.0
    return np.arctan2(sin_angle, cos_angle)


def jacobian(chain: Chain, q_rad: np.ndarray | Sequence[float]) -> np.ndarray:
    """Geometric Jacobian of the end-effector in the base frame, ``(..., 6, n)``.

    Rows 0-2: linear velocity (mm/rad), rows 3-5: angular velocity (rad/rad). Joint i turns
    about the z axis of its frame, through that frame's origin.
    """
    frames = frame_transforms(chain, q_rad)
    axes = frames[..., :-1, :3, 2]  # (..., n, 3)
    origins = frames[..., :-1, :3, 3]  # (..., n, 3)
    tip = frames[..., -1:, :3, 3]  # (..., 1, 3)
    linear = np.cross(axes, tip - origins)  # (..., n, 3)
    return np.concatenate([linear, axes], axis=-1).swapaxes(-1, -2)


@dataclass(frozen=True, eq=False)
class Pose:
    """End-effector pose for people: position (mm), roll/pitch/yaw (deg), rotation matrix."""

    position_mm: np.ndarray  # (3,)
    rpy_deg: np.ndarray  # (3,)
    rotation: np.ndarray  # (3, 3)


#: Tolerance (deg) within which a value given for a locked joint counts as its locked value.
LOCKED_TOLERANCE_DEG = 1e-6


def user_joint_values(arm: ArmDescription,
                      joints_deg: Sequence[float] | Mapping[str, float]) -> list[float]:
    """All joint angles (deg, in arm order) from a full sequence or a name -> value mapping.

    A mapping may leave out locked joints (they take their locked value); a value given for a
    locked joint must equal it. Raises ``ValueError`` naming unknown, missing or wrong joints.
    """
    if isinstance(joints_deg, Mapping):
        unknown = [name for name in joints_deg if name not in arm.joint_names]
        if unknown:
            raise ValueError(f"unknown joint(s) {', '.join(map(str, unknown))}; "
                             f"the arm has {', '.join(arm.joint_names)}")
        missing = [j.name for j in arm.joints if j.locked is None and j.name not in joints_deg]
        if missing:
            raise ValueError(f"missing joint(s) {', '.join(missing)}")
        values = [float(joints_deg[j.name]) if j.name in joints_deg
                  else float(cast(float, j.locked))  # (not missing: locked)
                  for j in arm.joints]
    else:
        values = [float(v) for v in joints_deg]
        if len(values) != arm.dof:
            raise ValueError(f"expected {arm.dof} joint angles ({', '.join(arm.joint_names)}), "
                             f"got {len(values)}")
    for joint, value in zip(arm.joints, values):
        if not math.isfinite(value):
            raise ValueError(f"{joint.name}: {value} is not a finite angle")
        if joint.locked is not None and abs(value - joint.locked) > LOCKED_TOLERANCE_DEG:
            raise ValueError(f"{joint.name} is locked at {joint.locked:g} deg, got {value:g}")
    return values


def pose_from_user_deg(arm: ArmDescription,
                       joints_deg: Sequence[float] | Mapping[str, float]) -> Pose:
    """End-effector pose of the arm at user-coordinate joint angles in degrees.

    See :func:`user_joint_values` for what is accepted; raises ``ValueError`` otherwise.
    """
    q = np.radians(user_joint_values(arm, joints_deg))
    frame = fk(Chain.from_arm(arm), q)
    rotation = frame[:3, :3].copy()
    return Pose(position_mm=frame[:3, 3].copy(),
                rpy_deg=np.degrees(rpy_from_matrix(rotation)),
                rotation=rotation)
