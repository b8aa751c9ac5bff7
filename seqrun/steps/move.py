"""move: one synchronized ruckig motion to a pose, to joint angles or to a tool pose.

A tool pose (``position_mm``) is solved by inverse kinematics: at validation from the
tracked joints, at run time again from the measured ones (:mod:`seqrun.steps.move_tool`
holds what ``move`` and ``move_linear`` share of that).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar, Literal

from pydantic import ConfigDict, Field, model_validator
from pydantic_core import PydanticCustomError

from seqrun.steps.kind import StepKind
from seqrun.steps.params import (
    HazardKey,
    Finite,
    JointName,
    PoseName,
    Positive,
    Scale,
    StepParams,
    Vector3,
    check_pose_target,
    exactly_one,
    one_key_value,
)

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.arm.poses import PoseSource
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class MoveParams(StepParams):
    """Move the arm to a pose or to joint angles: one synchronized, jerk-limited motion in
    which all commanded joints arrive together. Joints not named do not move."""

    kind: ClassVar[str] = "move"
    yaml_name: ClassVar[str] = "move"
    model_config = ConfigDict(json_schema_extra=exactly_one("pose", "joints", "position_mm"))

    pose: PoseName | None = Field(
        None, description="Move every joint to this pose (a file in poses/), e.g. totem.")
    joints: dict[JointName, Finite] | None = Field(
        None, min_length=1,
        description="Target angles of some joints in user degrees, e.g. {j1: 10, j4: -30}; "
                    "the others stay where they are.")
    relative: bool = Field(
        False, description="true: the joints values (or position_mm/rpy_deg) are offsets from "
                           "where the joints (or the tool) are.")
    position_mm: Vector3 | None = Field(
        None, description="Move the tool to this position [x, y, z] in mm (base frame), solved "
                          "by inverse kinematics; with relative: true, the displacement, in "
                          "the base or the tool frame (frame).")
    rpy_deg: Vector3 | None = Field(
        None, description="With position_mm: the tool orientation [roll, pitch, yaw] in degrees "
                          "(R = Rz(yaw) Ry(pitch) Rx(roll)); required unless relative, where "
                          "it is a rotation (default none).")
    frame: Literal["base", "tool"] = Field(
        "base", description="With relative position_mm: the frame the displacement is given "
                            "in (tool: e.g. [0, 0, 50] is 50 mm along the tool's z axis).")
    tool: str | None = Field(
        None, min_length=1, description="With position_mm: the arm file's tool whose centre "
                                        "point is moved (default: the arm's default_tool, "
                                        "else the end-effector frame).")
    velocity_deg_s: dict[JointName, Positive] = Field(
        default_factory=dict,
        description="Velocity cap of single joints in deg/s (at most the arm's maximum).")
    velocity_scale: Scale = Field(
        1.0, description="Fraction [0.01, 1] of the arm's velocity limits to use.")
    acceleration_scale: Scale = Field(
        1.0, description="Fraction [0.01, 1] of the arm's acceleration and jerk limits to use.")
    tolerance_deg: Positive | None = Field(
        None, description="In-position tolerance per joint in degrees "
                          "(default: the arm file's control.position_tolerance_deg).")
    timeout_s: Positive | None = Field(
        None, description="Time allowed for the whole move in seconds (default: the planned "
                          "duration plus the arm file's control.settle_timeout_s).")
    hazard: HazardKey = None

    @model_validator(mode="after")
    def _target(self) -> MoveParams:
        check_pose_target(self, "a move")
        if self.position_mm is not None:
            return self
        if (self.pose is None) == (self.joints is None):
            raise PydanticCustomError(
                "move_target", "a move needs either 'pose', 'joints' or 'position_mm'"
                if self.pose is None else "a move takes either 'pose' or 'joints', not both")
        if self.relative and self.joints is None:
            raise PydanticCustomError("move_relative",
                                      "'relative: true' needs 'joints' (a pose is absolute)")
        return self

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(pose=value)


def describe(params: MoveParams) -> str:
    if params.position_mm is not None:
        xyz = ", ".join(f"{v:g}" for v in params.position_mm)
        if params.relative:
            return f"move the tool by [{xyz}] mm ({params.frame} frame)"
        return f"move the tool to [{xyz}] mm"
    if params.pose is not None:
        return f"move to pose {params.pose}"
    sign = "by" if params.relative else "to"
    return "move " + ", ".join(f"{j} {sign} {v:g}°" for j, v in (params.joints or {}).items())


def poses(params: MoveParams) -> tuple[str, ...]:
    return (params.pose,) if params.pose is not None else ()


def resolve_move_target(params: MoveParams, current_deg: Mapping[str, float],
                        arm: ArmDescription, poses: PoseSource) -> dict[str, float]:
    """Target of a move for every joint of the arm (user degrees, arm order).

    Joints the move does not name keep their ``current_deg`` value; ``relative`` values are
    added to it; locked joints are always at their locked value. ``poses``: the sequence's
    frozen poses (a run uses only these) or a pose folder. Raises :class:`UserInputError`
    for an unknown pose or joint.
    """
    from seqrun.arm.poses import pose_joints_deg
    from seqrun.errors import UserInputError

    target: dict[str, float] = {}
    for joint in arm.joints:
        if joint.locked is not None:
            target[joint.name] = float(joint.locked)
        elif joint.name in current_deg:
            target[joint.name] = float(current_deg[joint.name])
        else:
            raise UserInputError(f"no current position for joint {joint.name}")
    if params.pose is not None:
        given = pose_joints_deg(params.pose, poses)
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


# --------------------------------------------------------------------------- static checks
def check(checker: CheckContext, step: ResolvedStep[MoveParams], params: MoveParams) -> None:
    from seqrun.formatting import format_number as f, format_range

    if params.position_mm is not None:
        _move_to_tool_pose(checker, step, params)
        return
    # which joints, and where to
    pose_limits: Mapping[str, object] = {}  # joints outside the arm's limits: the pose's error
    where: dict[str, tuple[str, ...]]
    if params.pose is not None:
        pose = checker.pose(step, params.pose, target=True)
        if pose is None:
            return  # its file has errors, reported there
        pose_limits = checker.pose_limit_findings.get(params.pose, {})
        names = [j.name for j in checker.arm.joints if j.name in pose and j.locked is None]
        given = {n: float(pose[n]) for n in names}
        where = {n: ("pose",) for n in names}
    else:
        joints = params.joints or {}
        names = checker.names(step, joints, ("joints",), as_keys=True, what="moving")
        given = {n: float(joints[n]) for n in names}
        where = {n: ("joints", n) for n in names}
    _velocities(checker, step, params)
    if not names:
        return
    if not checker.incomplete:
        checker.motion_allowed(step, names)
    if checker.powered_off is not None:
        checker.errors.append(step.error(
            f"move after power_off (at {checker.powered_off.location}): the zero reference "
            "is recorded for the pose the arm stands in; nothing may move after it"))

    # targets inside the limits in force; a joint outside may only come back inside
    target = {n: s.position for n, s in checker.joints.items()}
    refused: set[str] = set()  # targets outside: not tracked (no cascade of findings)
    for name in names:
        state = checker.joints[name]
        value = state.position + given[name] if params.relative else given[name]
        target[name] = value
        lo, hi = state.limits or state.joint.limits_deg
        source = "its limits" if state.limits is None or tuple(
            state.limits) == tuple(state.joint.limits_deg) else "the limits written by " \
            "set_limits"
        if name in pose_limits:
            refused.add(name)  # outside the arm's limits: the pose file's error
        elif params.relative and (checker.position_unknown or checker.lost_at is not None):
            refused.add(name)  # where it starts is not known
        elif not lo <= value <= hi:
            refused.add(name)
            how = (f" ({f(state.position)}° {'+' if given[name] >= 0 else '-'} "
                   f"{f(abs(given[name]))}°)" if params.relative else "")
            checker.errors.append(step.error(
                f"{name} target {f(value)}°{how} is outside {source} {format_range(lo, hi)}",
                *where[name]))
        elif not lo <= state.position <= hi:
            outside = lo - state.position if state.position < lo else state.position - hi
            verb = "starts at" if state.at_start else "is at"
            checker.notes.append(step.error(
                f"{name} {verb} {f(state.position)}°, {f(outside)}° outside its limit "
                f"{format_range(lo, hi)}; this move brings it back inside", *where[name]))
    if not checker.position_unknown and not refused and checker.lost_at is None:
        checker.guards_along_plan(step, params, target)  # (a target outside: that error only)
    _timeout(checker, step, params, target, [n for n in names if n not in refused])
    for name in names:
        if name in refused:
            continue
        state = checker.joints[name]
        if target[name] != state.position:
            state.at_start = False
        state.position = target[name]
    if not refused and not params.relative and set(names) >= set(checker.unlocked_names()):
        checker.lost_at = None  # every joint is where this move says again
        checker.position_unknown = False


def _velocities(checker: CheckContext, step: ResolvedStep[MoveParams], params: MoveParams) -> None:
    from seqrun.formatting import format_number as f

    for name in checker.names(step, params.velocity_deg_s, ("velocity_deg_s",),
                              as_keys=True, what="a velocity for"):
        value = params.velocity_deg_s[name]
        bound = checker.file_limits.velocity(name)
        held = checker.limits.velocity(name)
        if value > bound.value:
            checker.errors.append(step.error(
                f"velocity_deg_s of {name} {f(value)} deg/s is above its maximum "
                f"{f(bound.value)} deg/s (from the {bound.source})"
                if bound.source == "arm file" else
                f"velocity_deg_s of {name} {f(value)} deg/s is above its maximum "
                f"{f(bound.value)} deg/s (from {bound.source})",
                "velocity_deg_s", name))
        elif value > held.value:
            checker.notes.append(step.error(
                f"velocity_deg_s of {name} {f(value)} deg/s is above the MaxVel its "
                f"module holds, {f(held.value)} deg/s ({held.source}): planned within "
                "that", "velocity_deg_s", name))


def _timeout(checker: CheckContext, step: ResolvedStep[MoveParams], params: MoveParams,
             target: dict[str, float],
             names: list[str]) -> None:
    """A move's ``timeout_s``: within the arm file's bound, and not shorter than the
    move planned with the limits in force."""
    from seqrun.formatting import format_number as f

    if params.timeout_s is None:
        return
    if params.timeout_s > checker.arm.control.max_wait_s:
        checker.errors.append(step.error(
            f"timeout_s {f(params.timeout_s)} s is longer than the arm file allows "
            f"(control.max_wait_s = {f(checker.arm.control.max_wait_s)} s)", "timeout_s"))
        return
    duration = None if checker.position_unknown else _planned_duration(checker, step, params, target, names)
    if duration is not None and duration > params.timeout_s:
        checker.errors.append(step.error(
            f"timeout_s {f(params.timeout_s)} s is shorter than the move, planned to "
            f"take {f(duration)} s with the limits in force; give it more time or let "
            "it default (the planned duration plus control.settle_timeout_s)",
            "timeout_s"))


def _planned_duration(checker: CheckContext, step: ResolvedStep[MoveParams],
                      params: MoveParams, target: dict[str, float],
                      names: list[str]) -> float | None:
    import numpy as np

    from seqrun.errors import PlanningError
    from seqrun.arm.planner import Limits, plan_move

    order = checker.arm.joint_names
    start = [checker.joints[n].position for n in order]
    active = [order.index(n) for n in names
              if abs(target[n] - checker.joints[n].position) > 1e-9]
    velocity, acceleration = checker.limits.maxima()
    try:
        limits = Limits.from_arm(checker.arm, velocity_scale=min(
                                     params.velocity_scale, checker.hazard_speed_scale(step)),
                                 acceleration_scale=params.acceleration_scale,
                                 velocity_deg_s=params.velocity_deg_s,
                                 max_velocity_deg_s=velocity,
                                 max_acceleration_deg_s2=acceleration)
        plan = plan_move(np.radians(start), np.radians([target[n] for n in order]),
                         limits, active)
    except (PlanningError, KeyError, ValueError):
        return None  # what makes it unplannable is reported elsewhere
    return plan.duration


def _move_to_tool_pose(checker: CheckContext, step: ResolvedStep[MoveParams],
                       params: MoveParams) -> None:
    """A move to an end-effector pose: IK from the tracked joints (the solution nearest
    them), then the same checks as a move to those joints."""
    from seqrun.arm.cartesian import pointing_up_hint, solver_for
    from seqrun.arm.ik import Unreachable

    _velocities(checker, step, params)
    checker.motion_allowed(step, checker.unlocked_names())
    target = checker.tool_target(step, params)
    if target is None:
        return
    try:
        solution = solver_for(checker.arm, params.tool).solve(target, checker.tracked())
    except Unreachable as exc:
        hint = pointing_up_hint(checker.arm, params.tool, target)
        checker.errors.append(step.error(f"end-effector target {exc}{hint}", "position_mm"))
        checker.lost_at = step  # the run ends here: no second error about the steps after
        return
    joints = solution.joints_deg
    if checker.outside_limits(step, joints, "the end-effector target"):
        checker.lost_at = step
        return
    checker.solution_note(step, joints)
    checker.guards_along_plan(step, params, dict(zip(checker.arm.joint_names, joints)))
    checker.arrive(step, joints)


# --------------------------------------------------------------------------- run
def run(step: ResolvedStep[MoveParams], ex: StepContext) -> dict:
    import numpy as np

    from seqrun.arm.planner import Limits

    params = step.params
    if params.position_mm is not None:  # an end-effector target
        return _run_to_tool_pose(step, ex)
    current = ex.read_arm()
    current_deg = {j.name: float(v) for j, v in zip(ex.arm.joints, current.user_deg)}
    # The pose as it was validated (frozen when the sequence was loaded), never the file now.
    target = resolve_move_target(params, current_deg, ex.arm, ex.poses)
    target_deg = np.array([target[j.name] for j in ex.arm.joints])
    named = set(ex.arm.joint_names) if params.pose is not None else set(params.joints or {})
    active = [i for i in ex.movable if ex.arm.joints[i].name in named]
    velocity, acceleration = ex.limits_in_force.maxima()
    limits = Limits.from_arm(ex.arm, velocity_scale=_capped(step, ex),
                             acceleration_scale=params.acceleration_scale, speed=ex.speed,
                             velocity_deg_s=params.velocity_deg_s,
                             max_velocity_deg_s=velocity, max_acceleration_deg_s2=acceleration)
    tolerance = params.tolerance_deg or ex.arm.control.position_tolerance_deg
    detail = ex.move(target_deg, active, limits, tolerance_deg=tolerance,
                     timeout_s=params.timeout_s, start=current)
    # Which limits bound the plan, and where they come from (report, dry-run table).
    narrowed = ex.limits_in_force.narrowed([ex.arm.joints[i].name for i in active])
    if narrowed:
        detail["limits_in_force"] = narrowed
    else:
        detail["limits_from"] = "arm file"
    return detail


def _run_to_tool_pose(step: ResolvedStep[MoveParams], ex: StepContext) -> dict:
    """A move to an end-effector pose: IK from the measured joints, then an ordinary move."""
    from seqrun.arm.cartesian import solver_for
    from seqrun.arm.ik import Unreachable
    from seqrun.arm.planner import Limits
    from seqrun.errors import RunAborted
    from seqrun.steps.move_tool import agree, tool_target

    params = step.params
    reading = ex.read_arm()  # read once: the IK start and the move's start agree
    measured = reading.user_deg
    try:
        solution = solver_for(ex.arm, params.tool).solve(tool_target(params, ex, measured),
                                                         measured)
    except Unreachable as exc:
        raise RunAborted("unreachable", f"end-effector target {exc}") from None
    detail = agree(step, ex, solution.joints_deg)
    limits = Limits.from_arm(ex.arm, velocity_scale=_capped(step, ex),
                             acceleration_scale=params.acceleration_scale, speed=ex.speed,
                             velocity_deg_s=params.velocity_deg_s)
    tolerance = params.tolerance_deg or ex.arm.control.position_tolerance_deg
    ex.emit("ik_solved", joints_deg=detail["ik_solution_deg"])
    metrics = ex.move(solution.joints_deg, list(ex.movable), limits, tolerance_deg=tolerance,
                      timeout_s=params.timeout_s, start=reading)
    return {**detail, **metrics}


def _capped(step: ResolvedStep[MoveParams], ex: StepContext) -> float:
    """The step's velocity scale under its hazard class's speed cap (the smaller), as
    the validation planned it (docs/safety.md, 'Hazard classes')."""
    hazard = ex.hazards.get(step.number)
    return min(step.params.velocity_scale, hazard.speed_scale if hazard is not None else 1.0)


KIND = StepKind(
    name="move", params=MoveParams, describe=describe, check=check, run=run, poses=poses,
    value=one_key_value("move", MoveParams, text=("pose", PoseName)),
    shorthand=" Shorthand: 'move: totem' (a pose name).", example="move: totem", motion=True)
