"""End-effector targets and straight-line tool paths (pure: no I/O, no clock).

Shared by static validation (from the tracked joints) and the move steps (from the
measured joints), so both solve the same problem the same way:

- :func:`resolve_target`: the 4x4 tool target of a step (absolute in the base frame, or
  relative to the current tool pose in the base or the tool frame);
- :func:`plan_linear`: a straight line of the tool, time-parametrized by a jerk-limited
  1-D ruckig profile on the path parameter, sampled every ``sample_s``, every sample
  solved by IK from the previous one, checked for reachability, joint velocity and
  manipulability; the result streams as a :class:`~seqrun.arm.planner.SampledPlan`.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Trajectory

from seqrun.arm.description import ArmDescription
from seqrun.errors import SeqrunError
from seqrun.arm.ik import ORIENTATION_WEIGHT_MM, IkSolver, Unreachable, rotation_vector, target_frame
from seqrun.arm.kinematics import jacobian
from seqrun.arm.planner import SampledPlan

if TYPE_CHECKING:  # annotations only: numpy.typing is an import of its own at run time
    import numpy.typing as npt

__all__ = ["LinearPath", "LinearPlan", "PathError", "displacement", "manipulability", "plan_linear",
           "resolve_target", "solver_for"]


class PathError(SeqrunError):
    """A straight-line move that cannot be done as asked; ``fraction`` is where (0..1)."""

    def __init__(self, message: str, fraction: float | None = None, *,
                 unreachable: bool = False) -> None:
        super().__init__(message)
        self.fraction = fraction
        self.unreachable = unreachable  # a sample no configuration reaches


#: The solvers built lately, newest last: a solver keeps its arm, and a process that runs one
#: sequence after another loads the arm afresh for each run (the solvers of the arms before
#: are dropped instead of kept for the life of the process). A few arms and their tools.
_SOLVERS: OrderedDict[tuple[int, str | None, bool], IkSolver] = OrderedDict()
_SOLVERS_KEPT = 16


def solver_for(arm: ArmDescription, tool: str | None, *, tracking: bool = False) -> IkSolver:
    """A cached solver for ``arm`` and ``tool`` (KeyError for an unknown tool).
    ``tracking``: no restarts, so that a path's samples stay on one branch."""
    key = (id(arm), tool, tracking)
    solver = _SOLVERS.get(key)
    if solver is None or solver.arm is not arm:
        solver = IkSolver(arm, tool, restarts=0 if tracking else 40)
        _SOLVERS[key] = solver
        while len(_SOLVERS) > _SOLVERS_KEPT:
            _SOLVERS.popitem(last=False)
    _SOLVERS.move_to_end(key)
    return solver


def unknown_tool(arm: ArmDescription, tool: str | None) -> str:
    """The one line for a tool name the arm file does not define."""
    names = ", ".join(t.name for t in arm.tools) or "none defined"
    return f"unknown tool '{tool}' (the arm file's tools: {names})"


def tool_axis(arm: ArmDescription, tool: str | None) -> np.ndarray:
    """The unit vector, in the tool's own tip frame, along which the tool sticks out of the
    flange: the end-effector frame's -z (its z axis points back into the arm), turned by
    the tool's rpy_deg. KeyError for an unknown tool."""
    from seqrun.arm.kinematics import frame_matrix

    found = arm.tool(tool)
    if found is None:
        return np.array([0.0, 0.0, -1.0])
    return frame_matrix(found)[:3, :3].T @ np.array([0.0, 0.0, -1.0])


def pointing_up_hint(arm: ArmDescription, tool: str | None, target: np.ndarray) -> str:
    """For an unreachable target that points the tool upwards: the rpy that points it down
    instead (the usual intent near the desk), else ""."""
    axis = tool_axis(arm, tool)
    if float((target[:3, :3] @ axis)[2]) < 0.5:
        return ""
    down = np.array([0.0, 0.0, -1.0])
    turn = np.cross(axis, down)
    if float(np.linalg.norm(turn)) < 1e-9:  # the axis is -z (no turn) or +z (half a turn)
        rotation = np.eye(3) if float(axis @ down) > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        angle = math.atan2(float(np.linalg.norm(turn)), float(axis @ down))
        rotation = _rodrigues(turn / np.linalg.norm(turn) * angle)
    from seqrun.arm.kinematics import rpy_from_matrix

    rpy = ", ".join(f"{round(float(v), 3) + 0.0:g}" for v in np.degrees(rpy_from_matrix(rotation)))
    return (f"; this orientation points the tool up (the end-effector's z axis points back "
            f"into the arm: [180, 0, 0] is Totem's); pointing down is rpy_deg [{rpy}] with any "
            f"yaw (docs/sequence-format.md, 'Tools and frames')")


def tool_pose(solver: IkSolver, joints_deg: npt.ArrayLike) -> np.ndarray:
    """The tool frame (4x4, mm) at every-joint user degrees."""
    q = np.radians(np.asarray(joints_deg, dtype=float))[solver.active]
    return solver.forward(q)[0]


def _rodrigues(vector: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(vector))
    if angle < 1e-15:
        return np.eye(3)
    k = vector / angle
    skew = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * skew + (1 - math.cos(angle)) * skew @ skew


def resolve_target(current: np.ndarray, position_mm: Sequence[float],
                   rpy_deg: Sequence[float] | None, *, relative: bool,
                   frame: str = "base") -> np.ndarray:
    """The tool target: absolute (base frame), or relative to ``current`` (4x4): in the base
    frame a displacement of the position and a rotation about the base axes through the
    tool point; in the tool frame ``current · Δ``."""
    if not relative:
        return target_frame(position_mm, rpy_deg if rpy_deg is not None else (0, 0, 0))
    delta = target_frame(position_mm, rpy_deg if rpy_deg is not None else (0, 0, 0))
    if frame == "tool":
        return current @ delta
    target = np.eye(4)
    target[:3, :3] = delta[:3, :3] @ current[:3, :3]
    target[:3, 3] = current[:3, 3] + delta[:3, 3]
    return target


@dataclass(frozen=True)
class LinearPath:
    """The straight line of the tool from ``start`` to ``end`` (4x4 frames, mm); the
    orientation turns about one fixed axis at a rate proportional to the distance."""

    start: np.ndarray
    end: np.ndarray

    @property
    def length_mm(self) -> float:
        return float(np.linalg.norm(self.end[:3, 3] - self.start[:3, 3]))

    @property
    def turn(self) -> np.ndarray:
        """Rotation vector (rad) from the start orientation to the end, in the start frame."""
        return rotation_vector(self.start[:3, :3].T @ self.end[:3, :3])

    def frame_at(self, s: float) -> np.ndarray:
        frame = np.eye(4)
        frame[:3, 3] = self.start[:3, 3] + s * (self.end[:3, 3] - self.start[:3, 3])
        frame[:3, :3] = self.start[:3, :3] @ _rodrigues(s * self.turn)
        return frame

    def deviation_mm(self, points: np.ndarray) -> np.ndarray:
        """Distance (mm) of points ``(..., 3)`` from the segment."""
        a, b = self.start[:3, 3], self.end[:3, 3]
        ab = b - a
        points = np.asarray(points, dtype=float)
        denom = float(ab @ ab)
        s = np.zeros(points.shape[:-1]) if denom == 0 else np.clip((points - a) @ ab / denom, 0, 1)
        return np.linalg.norm(points - (a + s[..., None] * ab), axis=-1)


def manipulability(solver: IkSolver, q_deg: np.ndarray) -> np.ndarray:
    """Yoshikawa's sqrt(det(J Jᵀ)) of the active joints, position rows in units of
    :data:`~seqrun.arm.ik.ORIENTATION_WEIGHT_MM` (dimensionless), for ``(..., dof)`` degrees."""
    jac = jacobian(solver.chain, np.radians(q_deg))[..., solver.active].copy()
    jac[..., :3, :] /= ORIENTATION_WEIGHT_MM
    det = np.linalg.det(jac @ np.swapaxes(jac, -1, -2))
    return np.sqrt(np.maximum(det, 0.0))


@dataclass(frozen=True)
class LinearPlan:
    plan: SampledPlan
    path: LinearPath
    joints_deg: np.ndarray         # (k, dof) the solved samples
    min_manipulability: float
    min_manipulability_at: float   # fraction of the way
    peak_velocity_deg_s: np.ndarray


def _profile(path: LinearPath, speed_mm_s: float, rotation_speed_deg_s: float,
             acceleration_mm_s2: float, jerk_mm_s3: float) -> Trajectory:
    """Jerk-limited rest-to-rest profile of the path parameter s: 0 -> 1."""
    length, angle = path.length_mm, float(np.linalg.norm(path.turn))
    rotation = math.radians(rotation_speed_deg_s)
    # the rotation's acceleration and jerk scale with its speed as the line's do
    ratios = []
    if length > 1e-9:
        ratios.append((speed_mm_s / length, acceleration_mm_s2 / length, jerk_mm_s3 / length))
    if angle > 1e-9:
        scale = rotation / speed_mm_s
        ratios.append((rotation / angle, acceleration_mm_s2 * scale / angle,
                       jerk_mm_s3 * scale / angle))
    inp = InputParameter(1)
    inp.current_position, inp.target_position = [0.0], [1.0]
    inp.current_velocity = inp.current_acceleration = [0.0]
    inp.target_velocity = inp.target_acceleration = [0.0]
    inp.max_velocity = [min(r[0] for r in ratios)]
    inp.max_acceleration = [min(r[1] for r in ratios)]
    inp.max_jerk = [min(r[2] for r in ratios)]
    trajectory = Trajectory(1)
    result = Ruckig(1).calculate(inp, trajectory)
    if result not in (Result.Working, Result.Finished):
        raise PathError(f"the path profile could not be planned: {result}")
    return trajectory


def plan_linear(arm: ArmDescription, tool: str | None, start_deg: npt.ArrayLike,
                target: np.ndarray, *, speed_mm_s: float, rotation_speed_deg_s: float,
                acceleration_mm_s2: float, jerk_mm_s3: float,
                max_velocity_deg_s: np.ndarray | None = None,
                sample_s: float | None = None) -> LinearPlan:
    """Sample, solve and check a straight line of the tool from where ``start_deg`` puts it
    to ``target`` (4x4). Raises :class:`PathError` saying where and why it cannot be done.

    ``max_velocity_deg_s`` (every joint): the joint speeds the samples may need (default
    the arm's maxima less the tracking reserve).
    """
    solver = solver_for(arm, tool, tracking=True)
    start = np.asarray(start_deg, dtype=float)
    path = LinearPath(tool_pose(solver, start), np.asarray(target, dtype=float))
    if path.length_mm < 1e-6 and float(np.linalg.norm(path.turn)) < 1e-9:
        raise PathError("the tool is already at the end of the line: nothing to move")
    profile = _profile(path, speed_mm_s, rotation_speed_deg_s, acceleration_mm_s2, jerk_mm_s3)
    period = sample_s or arm.cartesian.linear_sample_s
    duration = float(profile.duration)
    count = max(2, int(math.ceil(duration / period)) + 1)
    times = np.linspace(0.0, duration, count)
    fractions = np.array([profile.at_time(float(t))[0][0] for t in times])
    fractions[0], fractions[-1] = 0.0, 1.0
    joints = np.empty((count, arm.dof))
    joints[0] = start
    for k in range(1, count):
        try:
            joints[k] = solver.solve(path.frame_at(float(fractions[k])), joints[k - 1]).joints_deg
        except Unreachable as exc:
            where = f"at {fractions[k] * 100:.0f}% of the way"
            previous = joints[k - 1]
            for i in solver.active:
                joint = arm.joints[i]
                lo, hi = joint.limits_deg
                if hi - lo < 360 and min(previous[i] - lo, hi - previous[i]) < 0.5:
                    bound = lo if previous[i] - lo < hi - previous[i] else hi
                    raise PathError(f"{joint.name} reaches its limit {bound:g}° {where}: the "
                                    "line cannot go on inside the joint limits",
                                    float(fractions[k]), unreachable=True) from None
            raise PathError(
                f"the line leaves the workspace {where} (no solution next to the previous "
                f"sample; closest {exc.position_error_mm:.2f} mm away)",
                float(fractions[k]), unreachable=True) from None
    limit = (max_velocity_deg_s if max_velocity_deg_s is not None else
             np.array([j.max_velocity_deg_s for j in arm.joints])
             * (1 - arm.control.tracking_reserve))
    velocity = np.abs(np.diff(joints, axis=0)) / np.diff(times)[:, None]
    over = velocity > limit
    if np.any(over):
        k, i = np.argwhere(over)[0]
        raise PathError(
            f"{arm.joints[i].name} would have to turn at {velocity[k, i]:.1f} deg/s at "
            f"{fractions[k + 1] * 100:.0f}% of the way (limit {limit[i]:.1f} deg/s): lower "
            "speed_mm_s or rotation_speed_deg_s, or keep away from singular configurations",
            float(fractions[k + 1]))
    measure = manipulability(solver, joints)
    worst = int(np.argmin(measure))
    threshold = arm.cartesian.min_manipulability
    if measure[worst] < threshold:
        raise PathError(
            f"the line passes near a singular configuration at {fractions[worst] * 100:.0f}% "
            f"of the way (manipulability {measure[worst]:.3f}, below the arm's "
            f"{threshold:g})", float(fractions[worst]))
    active = tuple(i for i in solver.active
                   if float(np.ptp(joints[:, i])) > 1e-9)
    plan = SampledPlan(active, times, np.radians(joints))
    return LinearPlan(plan, path, joints, float(measure[worst]), float(fractions[worst]),
                      np.max(velocity, axis=0))


def displacement(before: np.ndarray, after: np.ndarray, frame: str) -> np.ndarray:
    """How far the tool moved from ``before`` to ``after`` (4x4 frames), mm, expressed in the
    base frame or in the tool's frame at ``before``."""
    moved = after[:3, 3] - before[:3, 3]
    return before[:3, :3].T @ moved if frame == "tool" else moved
