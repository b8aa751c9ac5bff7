"""Static validation of a loaded sequence against the arm and a start state.

:func:`validate_sequence` walks the flattened steps and tracks, per joint, the position
(the targets of the moves before) and what the modules have been told: Reset, Home,
Halt, the limits written by ``set_limits``. It reports, each at the ``file:line:col`` of
the offending value:

- the start-up order the hardware needs: Home before any motion (after Reset), the
  limits written before moving (the modules' stored limits are narrower), Reset before
  Home and before writing parameters, and Reset again after a Halt;
- joints the arm does not have, and any command to a locked joint;
- every commanded target inside the limits in force; a joint that *starts* outside
  (Park's j4 at -120.32° against -120…120) may only move back inside, which is a note;
- velocities and limit overrides within the arm file's maxima;
- workspace guards (``workspace.guards`` of the arm file) along each move, taken as a
  straight line in joint space (the executor checks the real trajectory as it runs);
- checkpoints that cannot pass: the end-effector of the tracked joints is compared with
  the expected pose.

The executor runs it again with the measured start state (``start_deg``) and
``started=True`` when the modules report that they are reset, homed and limited.
:func:`resolve_move_target` and :func:`resolve_checkpoint` are the pure helpers it shares
with the executor.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from seqrun.arm import ArmDescription, Joint
from seqrun.errors import SequenceInvalid, SourceError, UserInputError
from seqrun.schema import (
    CheckpointParams,
    HaltParams,
    HomeParams,
    LoadedSequence,
    MoveParams,
    ResetParams,
    ResolvedStep,
    SetLimitsParams,
)

__all__ = [
    "GUARD_SAMPLES",
    "ValidationResult",
    "commanded_joints",
    "park_deg",
    "pose_joints_deg",
    "resolve_checkpoint",
    "resolve_move_target",
    "validate_sequence",
]

#: Samples per move when checking workspace guards along the joint-space path.
GUARD_SAMPLES = 64
#: Name of the pose a freshly powered-on arm is in (the modules' zeros).
START_POSE = "park"


@dataclass
class ValidationResult:
    """Errors (the sequence must not run) and notes (worth knowing, not wrong)."""

    errors: list[SourceError] = field(default_factory=list)
    notes: list[SourceError] = field(default_factory=list)
    #: Joint positions after the last step (user degrees, every joint of the arm).
    final_deg: dict[str, float] = field(default_factory=dict)

    @property
    def valid(self) -> bool:
        return not self.errors


# --------------------------------------------------------------------------- helpers
def _f(value: float) -> str:
    """A number for messages: at most 3 decimals, no trailing zeros, no '-0'."""
    return f"{round(float(value), 3) + 0.0:g}"


def _range(lo: float, hi: float) -> str:
    return f"{_f(lo)}…{_f(hi)}"


def pose_joints_deg(name: str, poses_dir: str | Path) -> dict[str, float]:
    """Joint angles of pose ``name`` (user degrees). Raises :class:`UserInputError` for an
    unknown pose, :class:`SequenceInvalid` for a broken pose file."""
    from seqrun.poses import find_pose

    path = find_pose(name, poses_dir)
    return dict(_pose_joints(path, path.stat().st_mtime_ns))


@functools.lru_cache(maxsize=64)
def _pose_joints(path: Path, mtime_ns: int) -> tuple[tuple[str, float], ...]:
    # Keyed on the file's mtime: a pose file edited between runs is read again.
    from seqrun.poses import load_pose

    return tuple(load_pose(path).joints_deg.items())


def park_deg(poses_dir: str | Path) -> dict[str, float]:
    """The default start state: the Park pose (where a freshly powered-on arm is)."""
    return pose_joints_deg(START_POSE, poses_dir)


def commanded_joints(params: MoveParams, arm: ArmDescription,
                     poses_dir: str | Path) -> list[str]:
    """The joints a move commands, in arm order: every unlocked joint of the pose, or the
    unlocked joints named in ``joints``. The others are not part of the motion."""
    names = (pose_joints_deg(params.pose, poses_dir) if params.pose is not None
             else params.joints or {})
    return [j.name for j in arm.joints if j.name in names and j.locked is None]


def resolve_move_target(params: MoveParams, current_deg: Mapping[str, float],
                        arm: ArmDescription, poses_dir: str | Path) -> dict[str, float]:
    """Target of a move for every joint of the arm (user degrees, arm order).

    Joints the move does not name keep their ``current_deg`` value; ``relative`` values are
    added to it; locked joints are always at their locked value. Raises
    :class:`UserInputError` for an unknown pose or joint.
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
        given = pose_joints_deg(params.pose, poses_dir)
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


def resolve_checkpoint(params: CheckpointParams, arm: ArmDescription, poses_dir: str | Path
                       ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Expected end-effector of a checkpoint: ``(position_mm (3,), rotation (3, 3),
    position_tolerance_mm, angle_tolerance_deg)``."""
    from seqrun.kinematics import matrix_from_rpy, pose_from_user_deg

    if params.pose is not None:
        joints = pose_joints_deg(params.pose, poses_dir)
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


# --------------------------------------------------------------------------- tracking
@dataclass
class _JointState:
    joint: Joint
    position: float
    reset: bool = False
    homed: bool = False
    halted: bool = False
    limits: tuple[float, float] | None = None  # written MinPos/MaxPos
    max_velocity: float = 0.0
    max_velocity_from: str = "the arm file"
    at_start: bool = True  # still at its start position (for the wording of notes)

    @property
    def locked(self) -> bool:
        return self.joint.locked is not None


class _Validator:
    def __init__(self, loaded: LoadedSequence, arm: ArmDescription,
                 start_deg: Mapping[str, float], started: bool) -> None:
        self.loaded = loaded
        self.arm = arm
        self.poses_dir = loaded.pose_path or loaded.poses_dir
        self.errors: list[SourceError] = []
        self.notes: list[SourceError] = []
        self.joints: dict[str, _JointState] = {}
        self._chain = None
        for joint in arm.joints:
            position = joint.locked if joint.locked is not None else start_deg.get(joint.name)
            if position is None or not math.isfinite(position):
                what = "is missing" if position is None else f"is {position}"
                self.errors.append(loaded.location.error(
                    f"start state: {joint.name} {what} (a finite angle is needed for every "
                    "unlocked joint)"))
                position = 0.0
            state = _JointState(joint, float(position),
                                max_velocity=joint.max_velocity_deg_s)
            if started:
                state.reset = state.homed = True
                state.limits = tuple(joint.limits_deg)  # type: ignore[assignment]
            self.joints[joint.name] = state
        unknown = [n for n in start_deg if n not in self.joints]
        if unknown:
            self.errors.append(loaded.location.error(
                f"start state: unknown joint(s) {', '.join(map(str, unknown))} (the arm has "
                f"{', '.join(arm.joint_names)})"))

    # -- common checks
    def _names(self, step: ResolvedStep, names: list[str] | dict, path: tuple,
               *, as_keys: bool, what: str) -> list[str]:
        """Known, unlocked joint names among ``names``; errors for the others."""
        good = []
        for i, name in enumerate(names):
            where = path + ((name,) if as_keys else (i,))
            if name not in self.joints:
                self.errors.append(step.error(
                    f"unknown joint '{name}' (the arm has {', '.join(self.arm.joint_names)})",
                    *where, key=as_keys))
            elif self.joints[name].locked:
                self.errors.append(step.error(
                    f"{name} is locked at {_f(self.joints[name].joint.locked)}°: {what} a "
                    "locked joint is not allowed (seqrun never commands it)", *where,
                    key=as_keys))
            else:
                good.append(name)
        return good

    def _modules(self, step: ResolvedStep, joints: str | list[str]) -> list[_JointState]:
        if joints == "all":
            return list(self.joints.values())
        names = self._names(step, list(joints), ("joints",), as_keys=False,
                            what=f"a {step.kind} of")
        return [self.joints[n] for n in names]

    # -- steps
    def reset(self, step: ResolvedStep, params: ResetParams) -> None:
        for state in self._modules(step, params.joints):
            state.reset, state.halted = True, False

    def home(self, step: ResolvedStep, params: HomeParams) -> None:
        targets = self._modules(step, params.joints)
        not_reset = [s.joint.name for s in targets if not s.reset and not s.locked]
        if not_reset:
            self.errors.append(step.error(
                f"home before reset{self._which(not_reset)}: reset the modules first (Reset "
                "clears the error state they power up with)"))
        for state in targets:
            state.homed = True

    def halt(self, step: ResolvedStep, params: HaltParams) -> None:
        for state in self._modules(step, params.joints):
            state.halted = True

    def set_limits(self, step: ResolvedStep, params: SetLimitsParams) -> None:
        unlocked = [s for s in self.joints.values() if not s.locked]
        not_reset = [s.joint.name for s in unlocked if not s.reset]
        if not_reset:
            self.errors.append(step.error(
                f"set_limits before reset{self._which(not_reset)}: the modules accept "
                "parameters only after Reset"))
        for name in self._names(step, params.limits_deg, ("limits_deg",), as_keys=True,
                                what="writing limits to"):
            lo, hi = params.limits_deg[name]
            alo, ahi = self.joints[name].joint.limits_deg
            if lo < alo or hi > ahi:
                self.errors.append(step.error(
                    f"limits_deg of {name} {_range(lo, hi)} go beyond the arm's limits "
                    f"{_range(alo, ahi)}; an override may only narrow them",
                    "limits_deg", name))
        for key, attr in (("max_velocity_deg_s", "max_velocity_deg_s"),
                          ("max_acceleration_deg_s2", "max_acceleration_deg_s2")):
            values = getattr(params, key)
            for name in self._names(step, values, (key,), as_keys=True,
                                    what="writing limits to"):
                maximum = getattr(self.joints[name].joint, attr)
                if values[name] > maximum:
                    unit = "deg/s" if key.endswith("_s") else "deg/s^2"
                    self.errors.append(step.error(
                        f"{key} of {name} {_f(values[name])} {unit} is above the arm's "
                        f"maximum {_f(maximum)} {unit}", key, name))
        for state in unlocked:
            name = state.joint.name
            override = params.limits_deg.get(name)
            state.limits = (tuple(override) if override is not None  # type: ignore[assignment]
                            else tuple(state.joint.limits_deg))
            if name in params.max_velocity_deg_s:
                state.max_velocity = min(params.max_velocity_deg_s[name],
                                         state.joint.max_velocity_deg_s)
                state.max_velocity_from = f"set_limits at {step.location}"

    def move(self, step: ResolvedStep, params: MoveParams) -> None:
        # which joints, and where to
        if params.pose is not None:
            try:
                pose = pose_joints_deg(params.pose, self.poses_dir)
            except (UserInputError, SequenceInvalid):
                return  # reported when the sequence was loaded
            for name, value in pose.items():
                state = self.joints.get(name)
                if state is None:
                    self.errors.append(step.error(
                        f"pose '{params.pose}' has joint '{name}', which the arm does not have",
                        "pose"))
                elif state.locked and abs(value - state.joint.locked) > 1e-6:
                    self.errors.append(step.error(
                        f"pose '{params.pose}' sets {name} to {_f(value)}°, but {name} is "
                        f"locked at {_f(state.joint.locked)}°", "pose"))
            names = [j.name for j in self.arm.joints if j.name in pose and j.locked is None]
            given = {n: float(pose[n]) for n in names}
            where = {n: ("pose",) for n in names}
        else:
            joints = params.joints or {}
            names = self._names(step, joints, ("joints",), as_keys=True, what="moving")
            given = {n: float(joints[n]) for n in names}
            where = {n: ("joints", n) for n in names}
        self._velocities(step, params)
        if not names:
            return
        self._motion_allowed(step, names)
        if getattr(self, "powered_off", None) is not None:
            self.errors.append(step.error(
                f"move after power_off (at {self.powered_off.location}): the zero reference "
                "is recorded for the pose the arm stands in; nothing may move after it"))

        # targets inside the limits in force; a joint outside may only come back inside
        target = {n: s.position for n, s in self.joints.items()}
        refused: set[str] = set()  # targets outside: not tracked (no cascade of findings)
        for name in names:
            state = self.joints[name]
            value = state.position + given[name] if params.relative else given[name]
            target[name] = value
            lo, hi = state.limits or state.joint.limits_deg
            source = "its limits" if state.limits is None or tuple(
                state.limits) == tuple(state.joint.limits_deg) else "the limits written by " \
                "set_limits"
            if not lo <= value <= hi:
                refused.add(name)
                how = (f" ({_f(state.position)}° {'+' if given[name] >= 0 else '-'} "
                       f"{_f(abs(given[name]))}°)" if params.relative else "")
                self.errors.append(step.error(
                    f"{name} target {_f(value)}°{how} is outside {source} {_range(lo, hi)}",
                    *where[name]))
            elif not lo <= state.position <= hi:
                outside = lo - state.position if state.position < lo else state.position - hi
                verb = "starts at" if state.at_start else "is at"
                self.notes.append(step.error(
                    f"{name} {verb} {_f(state.position)}°, {_f(outside)}° outside its limit "
                    f"{_range(lo, hi)}; this move brings it back inside", *where[name]))
        self._guards(step, target)
        for name in names:
            if name in refused:
                continue
            state = self.joints[name]
            if target[name] != state.position:
                state.at_start = False
            state.position = target[name]

    def _velocities(self, step: ResolvedStep, params: MoveParams) -> None:
        for name in self._names(step, params.velocity_deg_s, ("velocity_deg_s",),
                                as_keys=True, what="a velocity for"):
            state = self.joints[name]
            value = params.velocity_deg_s[name]
            if value > state.max_velocity:
                self.errors.append(step.error(
                    f"velocity_deg_s of {name} {_f(value)} deg/s is above its maximum "
                    f"{_f(state.max_velocity)} deg/s (from {state.max_velocity_from})",
                    "velocity_deg_s", name))

    def _motion_allowed(self, step: ResolvedStep, names: list[str]) -> None:
        states = [self.joints[n] for n in names]
        not_homed = [s.joint.name for s in states if not s.homed]
        not_reset = [s.joint.name for s in states if not s.reset]
        halted = [s.joint.name for s in states if s.halted]
        no_limits = [s.joint.name for s in states if s.limits is None]
        if not_homed:
            first = "; reset them first, then home" if not_reset else ""
            self.errors.append(step.error(
                f"move before home{self._which(not_homed, names)}: the modules refuse motion "
                f"until Home{first}"))
        elif not_reset:
            self.errors.append(step.error(
                f"move before reset{self._which(not_reset, names)}: the modules refuse motion "
                "until Reset"))
        if halted:
            self.errors.append(step.error(
                f"move after halt{self._which(halted, names)}: the modules refuse motion until "
                "Reset"))
        if no_limits and not not_homed:
            self.errors.append(step.error(
                f"move before set_limits{self._which(no_limits, names)}: write the joint "
                "limits first (the modules' stored limits are narrower than the arm file's)"))

    def _which(self, names: list[str], of: list[str] | None = None) -> str:
        everything = of if of is not None else [s.joint.name for s in self.joints.values()
                                                 if not s.locked]
        return "" if sorted(names) == sorted(everything) else f" ({', '.join(names)})"

    def _guards(self, step: ResolvedStep, target: dict[str, float]) -> None:
        guards = self.arm.workspace.guards
        if not guards:
            return
        from seqrun.kinematics import Chain, point_positions

        if self._chain is None:
            self._chain = Chain.from_arm(self.arm)
        names = self.arm.joint_names
        start = np.array([self.joints[n].position for n in names])
        end = np.array([target[n] for n in names])
        fractions = np.linspace(0.0, 1.0, GUARD_SAMPLES + 1)[:, None]
        path = np.radians(start + (end - start) * fractions)
        points = point_positions(self._chain, path)
        for guard in guards:
            # one error per guard: the watched point that goes lowest, where it is lowest
            lowest = min(guard.points, key=lambda p: float(points[p][:, 2].min()))
            heights = points[lowest][:, 2]
            i = int(np.argmin(heights))
            if heights[i] < guard.min_z_mm:
                self.errors.append(step.error(
                    f"this move takes the {lowest.replace('_', '-')} down to z = "
                    f"{_f(heights[i])} mm ({round(float(fractions[i, 0]) * 100):d}% of the "
                    f"way, straight line in joint space), below the '{guard.name}' guard "
                    f"at {_f(guard.min_z_mm)} mm"))

    def checkpoint(self, step: ResolvedStep, params: CheckpointParams) -> None:
        from seqrun.kinematics import orientation_error, pose_from_user_deg

        try:
            position, rotation, pos_tol, ang_tol = resolve_checkpoint(params, self.arm,
                                                                      self.poses_dir)
        except (UserInputError, SequenceInvalid):
            return  # reported when the sequence was loaded
        except ValueError as exc:
            self.errors.append(step.error(f"checkpoint: {exc}", "pose"))
            return
        pose = pose_from_user_deg(self.arm, {n: s.position for n, s in self.joints.items()})
        distance = float(np.linalg.norm(pose.position_mm - position))
        angle = math.degrees(float(orientation_error(rotation, pose.rotation)))
        if distance > pos_tol or angle > ang_tol:
            at = ", ".join(_f(v) for v in pose.position_mm)
            rpy = ", ".join(_f(v) for v in pose.rpy_deg)
            self.errors.append(step.error(
                f"this checkpoint cannot pass: after the moves before it the end-effector is at "
                f"[{at}] mm, rpy [{rpy}]°, {_f(distance)} mm and {_f(angle)}° from the "
                f"expected pose (tolerances {_f(pos_tol)} mm, {_f(ang_tol)}°)"))

    def power_off(self, step: ResolvedStep, params) -> None:
        """The pose must be a power-off pose of the arm, and where the moves before end."""
        if params.pose not in self.arm.power_off_poses:
            known = ", ".join(self.arm.power_off_poses) or "none"
            self.errors.append(step.error(
                f"'{params.pose}' is not a power-off pose of arm '{self.arm.name}' (its "
                f"power-off poses: {known}; power_off_poses in the arm file)", "pose"))
            return
        target = self.arm.power_off_joints_deg(params.pose)
        tolerance = params.tolerance_deg or self.arm.control.position_tolerance_deg
        off = [f"{n} {_f(s.position)}° (pose {_f(target[n])}°)"
               for n, s in self.joints.items()
               if not s.locked and abs(s.position - target[n]) > tolerance]
        if off:
            self.errors.append(step.error(
                f"this power_off cannot pass: after the moves before it the arm is not in "
                f"{params.pose}: {', '.join(off)}"))
        self.powered_off = step

    def run(self) -> ValidationResult:
        handlers = {"reset": self.reset, "home": self.home, "halt": self.halt,
                    "set_limits": self.set_limits, "move": self.move,
                    "checkpoint": self.checkpoint, "power_off": self.power_off}
        for step in self.loaded.steps:
            handler = handlers.get(step.kind)
            if handler is not None:
                errors, notes = len(self.errors), len(self.notes)
                handler(step, step.params)  # type: ignore[operator]
                # a step's findings in the order they appear in its text
                self.errors[errors:] = sorted(self.errors[errors:], key=_position)
                self.notes[notes:] = sorted(self.notes[notes:], key=_position)
        final = {n: s.position for n, s in self.joints.items()}
        # In step order (a step of an included file comes where it runs), duplicates dropped.
        return ValidationResult(list(dict.fromkeys(self.errors)),
                                list(dict.fromkeys(self.notes)), final)


def _position(item: SourceError) -> tuple[int, int]:
    return item.line, item.column


def validate_sequence(loaded: LoadedSequence, arm: ArmDescription,
                      start_deg: Mapping[str, float] | None = None, *,
                      started: bool = False) -> ValidationResult:
    """Check a loaded sequence against ``arm`` starting at ``start_deg`` (user degrees;
    default the Park pose of the project's poses folder).

    ``started=True``: the modules are already reset, homed and have the arm file's limits
    (the executor passes what it measured). Never raises for a bad sequence: everything
    is in the result.
    """
    if start_deg is None:
        start_deg = park_deg(loaded.pose_path or loaded.poses_dir)
    return _Validator(loaded, arm, start_deg, started).run()
