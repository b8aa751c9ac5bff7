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
from seqrun.errors import PlanningError, SequenceInvalid, SourceError, UserInputError
from seqrun.limits import READBACK, LimitsInForce
from seqrun.schema import (
    CheckpointParams,
    HaltParams,
    HomeParams,
    LoadedSequence,
    MoveParams,
    ResetParams,
    ResolvedStep,
    SetLimitsParams,
    WaitParams,
)

__all__ = [
    "GUARD_SAMPLES",
    "ValidationResult",
    "commanded_joints",
    "format_number",
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
def format_number(value: float) -> str:
    """A number for messages: at most 3 decimals, no trailing zeros, no '-0'; a number
    below 0.001 keeps 3 significant digits (a tolerance of 1e-06 is not "0")."""
    value = float(value)
    if value != 0 and abs(value) < 0.001:
        return f"{value:.3g}"
    return f"{round(value, 3) + 0.0:g}"


_f = format_number


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
    from seqrun.kinematics import matrix_from_rpy, pose_from_user_deg

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


# --------------------------------------------------------------------------- tracking
@dataclass
class _JointState:
    joint: Joint
    position: float
    reset: bool = False
    homed: bool = False
    halted: bool = False
    limits: tuple[float, float] | None = None  # written MinPos/MaxPos
    at_start: bool = True  # still at its start position (for the wording of notes)

    @property
    def locked(self) -> bool:
        return self.joint.locked is not None


class _Validator:
    def __init__(self, loaded: LoadedSequence, arm: ArmDescription,
                 start_deg: Mapping[str, float], started: bool,
                 module_limits: Mapping[str, tuple[float, float]] | None = None,
                 incomplete: bool = False) -> None:
        self.loaded = loaded
        # Steps were left out (they failed on their own): what depends on the steps before
        # (start-up order, where the joints are) is not checked, the rest is.
        self.incomplete = incomplete
        self.arm = arm
        self.poses = loaded.poses
        self.errors: list[SourceError] = []
        self.notes: list[SourceError] = []
        self.joints: dict[str, _JointState] = {}
        self._chain = None
        # Limits the file itself sets (arm file, its set_limits): exceeding them is an
        # error. ``limits`` adds what the modules hold: moves are planned within it.
        self.file_limits = LimitsInForce(arm)
        self.limits = LimitsInForce(arm)
        self.pose_checked: dict[str, bool] = {}  # pose name -> usable
        self.pose_limit_findings: dict[str, dict[str, str]] = {}  # pose -> joint -> message
        self.reported_pose_limits: set[tuple[str, str]] = set()
        for joint in arm.joints:
            position = joint.locked if joint.locked is not None else start_deg.get(joint.name)
            if position is None or not math.isfinite(position):
                what = "is missing" if position is None else f"is {position}"
                self.errors.append(loaded.location.error(
                    f"start state: {joint.name} {what} (a finite angle is needed for every "
                    "unlocked joint)"))
                position = 0.0
            state = _JointState(joint, float(position))
            if started:
                state.reset = state.homed = True
                state.limits = tuple(joint.limits_deg)  # type: ignore[assignment]
            self.joints[joint.name] = state
        unknown = [n for n in start_deg if n not in self.joints]
        if unknown:
            self.errors.append(loaded.location.error(
                f"start state: unknown joint(s) {', '.join(map(str, unknown))} (the arm has "
                f"{', '.join(arm.joint_names)})"))
        if module_limits:
            self.limits.read_back({n: v for n, v in module_limits.items() if n in self.joints})
            for name, bound in ((n, self.limits.velocity(n)) for n in module_limits
                                if n in self.joints):
                if bound.source == READBACK:
                    self.notes.append(loaded.location.error(
                        f"{name}: its module holds MaxVel {_f(bound.value)} deg/s, below the "
                        f"arm file's {_f(arm.joint(name).max_velocity_deg_s)} deg/s; moves "
                        "are planned within it until a set_limits writes it"))
            for name, bound in ((n, self.limits.acceleration(n)) for n in module_limits
                                if n in self.joints):
                if bound.source.startswith(READBACK):
                    self.notes.append(loaded.location.error(
                        f"{name}: its module holds MaxAcc {_f(module_limits[name][1])} "
                        f"deg/s^2; moves are planned within {_f(bound.value)} deg/s^2 "
                        f"({bound.source})"))

    # -- pose files, checked against the arm where they are written
    def _pose(self, step: ResolvedStep, name: str, *, target: bool) -> dict[str, float] | None:
        """The frozen joints of pose ``name``; None if it cannot be used (reported)."""
        frozen = self.poses.get(name)
        if frozen is None:
            return None  # unknown or broken pose file: reported when the sequence was loaded
        if name not in self.pose_checked:
            from seqrun.poses import pose_findings

            usable = True
            limits: dict[str, str] = {}
            for finding in pose_findings(frozen.pose, self.arm):
                error = frozen.document.error(finding.where, finding.message, key=finding.key)
                if finding.note:
                    limits[finding.joint or ""] = error
                else:
                    self.errors.append(error)
                    usable = False
            self.pose_checked[name] = usable
            self.pose_limit_findings[name] = limits
        if target:
            # A move target outside the arm's limits is the pose file's error, reported at
            # its line (once per pose; the steps that use it are named).
            for joint, error in self.pose_limit_findings[name].items():
                if (name, joint) in self.reported_pose_limits:
                    continue
                self.reported_pose_limits.add((name, joint))
                lo, hi = self.arm.joint(joint).limits_deg
                value = frozen.pose.joints_deg[joint]
                self.errors.append(SourceError(
                    error.file, error.line, error.column,
                    f"{joint} {_f(value)}° is outside its limits {_range(lo, hi)}: pose "
                    f"'{name}' cannot be a move target (used at {step.where('pose')})"))
        return frozen.joints_deg if self.pose_checked[name] else None

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
        if not_reset and not self.incomplete:
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
        if not_reset and not self.incomplete:
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
        written = {key: {n: v for n, v in getattr(params, key).items()
                         if n in self.joints and not self.joints[n].locked}
                   for key in ("max_velocity_deg_s", "max_acceleration_deg_s2")}
        for limits in (self.file_limits, self.limits):
            limits.written(f"set_limits at {step.location}", written["max_velocity_deg_s"],
                           written["max_acceleration_deg_s2"])

    def move(self, step: ResolvedStep, params: MoveParams) -> None:
        # which joints, and where to
        pose_limits: dict[str, str] = {}
        if params.pose is not None:
            pose = self._pose(step, params.pose, target=True)
            if pose is None:
                return  # its file has errors, reported there
            pose_limits = self.pose_limit_findings.get(params.pose, {})
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
        if not self.incomplete:
            self._motion_allowed(step, names)

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
            if name in pose_limits:
                refused.add(name)  # outside the arm's limits: the pose file's error
            elif params.relative and self.incomplete:
                refused.add(name)  # where it starts is not known
            elif not lo <= value <= hi:
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
        if not self.incomplete:
            self._guards(step, target)
        self._timeout(step, params, target, [n for n in names if n not in refused])
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
            value = params.velocity_deg_s[name]
            bound = self.file_limits.velocity(name)
            held = self.limits.velocity(name)
            if value > bound.value:
                self.errors.append(step.error(
                    f"velocity_deg_s of {name} {_f(value)} deg/s is above its maximum "
                    f"{_f(bound.value)} deg/s (from the {bound.source})"
                    if bound.source == "arm file" else
                    f"velocity_deg_s of {name} {_f(value)} deg/s is above its maximum "
                    f"{_f(bound.value)} deg/s (from {bound.source})",
                    "velocity_deg_s", name))
            elif value > held.value:
                self.notes.append(step.error(
                    f"velocity_deg_s of {name} {_f(value)} deg/s is above the MaxVel its "
                    f"module holds, {_f(held.value)} deg/s ({held.source}): planned within "
                    "that", "velocity_deg_s", name))

    def _timeout(self, step: ResolvedStep, params: MoveParams, target: dict[str, float],
                 names: list[str]) -> None:
        """A move's ``timeout_s``: within the arm file's bound, and not shorter than the
        move planned with the limits in force."""
        if params.timeout_s is None:
            return
        if params.timeout_s > self.arm.control.max_wait_s:
            self.errors.append(step.error(
                f"timeout_s {_f(params.timeout_s)} s is longer than the arm file allows "
                f"(control.max_wait_s = {_f(self.arm.control.max_wait_s)} s)", "timeout_s"))
            return
        duration = None if self.incomplete else self._planned_duration(params, target, names)
        if duration is not None and duration > params.timeout_s:
            self.errors.append(step.error(
                f"timeout_s {_f(params.timeout_s)} s is shorter than the move, planned to "
                f"take {_f(duration)} s with the limits in force; give it more time or let "
                "it default (the planned duration plus control.settle_timeout_s)",
                "timeout_s"))

    def _planned_duration(self, params: MoveParams, target: dict[str, float],
                          names: list[str]) -> float | None:
        from seqrun.planner import Limits, plan_move

        order = self.arm.joint_names
        start = [self.joints[n].position for n in order]
        active = [order.index(n) for n in names
                  if abs(target[n] - self.joints[n].position) > 1e-9]
        velocity, acceleration = self.limits.maxima()
        try:
            limits = Limits.from_arm(self.arm, velocity_scale=params.velocity_scale,
                                     acceleration_scale=params.acceleration_scale,
                                     velocity_deg_s=params.velocity_deg_s,
                                     max_velocity_deg_s=velocity,
                                     max_acceleration_deg_s2=acceleration)
            plan = plan_move(np.radians(start), np.radians([target[n] for n in order]),
                             limits, active)
        except (PlanningError, KeyError, ValueError):
            return None  # what makes it unplannable is reported elsewhere
        return plan.duration

    def _after_halt(self, step: ResolvedStep, what: str) -> None:
        """A wait or checkpoint reads the modules, which report HALTED until Reset: after
        a halt it can only fail."""
        halted = [s.joint.name for s in self.joints.values() if s.halted and not s.locked]
        if halted and not self.incomplete:
            self.errors.append(step.error(
                f"{what} after halt{self._which(halted)}: the modules report HALTED until "
                "Reset and this step reads them, so it can never pass; reset first"))

    def wait(self, step: ResolvedStep, params: WaitParams) -> None:
        self._after_halt(step, f"{step.kind}")
        bound = self.arm.control.max_wait_s
        for key in ("seconds", "timeout_s"):
            value = getattr(params, key)
            if value is not None and value > bound:
                self.errors.append(step.error(
                    f"{key} {_f(value)} s is longer than the arm file allows "
                    f"(control.max_wait_s = {_f(bound)} s)", key))

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

        self._after_halt(step, "checkpoint")
        if params.pose is not None and self._pose(step, params.pose, target=False) is None:
            return  # unknown pose or its file has errors: reported already
        try:
            position, rotation, pos_tol, ang_tol = resolve_checkpoint(params, self.arm,
                                                                      self.poses)
        except (UserInputError, SequenceInvalid):
            return  # reported when the sequence was loaded
        except ValueError as exc:
            self.errors.append(step.error(f"checkpoint: {exc}", "pose"))
            return
        if self.incomplete:
            return  # where the joints are after the moves before is not known
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

    def run(self) -> ValidationResult:
        handlers = {"reset": self.reset, "home": self.home, "halt": self.halt,
                    "set_limits": self.set_limits, "move": self.move,
                    "wait": self.wait, "checkpoint": self.checkpoint}
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
                      started: bool = False,
                      module_limits: Mapping[str, tuple[float, float]] | None = None,
                      incomplete: bool = False) -> ValidationResult:
    """Check a loaded sequence against ``arm`` starting at ``start_deg`` (user degrees;
    default the Park pose of the project's poses folder).

    ``started=True``: the modules are already reset, homed and have the arm file's limits
    (the executor passes what it measured). ``module_limits``: MaxVel (deg/s) and MaxAcc
    (deg/s^2) per joint as read back from the modules (moves are planned within them).
    ``incomplete``: ``loaded`` lacks steps that failed on their own (see
    :func:`seqrun.schema.load_sequence_partial`); the checks that depend on the steps before
    (start-up order, positions: guards, checkpoints, relative targets) are skipped. Never raises for a bad sequence: everything is in the result.
    """
    if start_deg is None:
        start_deg = park_deg(loaded.poses_dir)
    return _Validator(loaded, arm, start_deg, started, module_limits, incomplete).run()
