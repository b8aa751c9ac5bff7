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
- workspace guards (``workspace.guards`` of the arm file) along each move's ruckig plan,
  the trajectory the executor streams (sampled at 100 Hz), with the smallest clearance of
  every move in :attr:`ValidationResult.clearances`;
- checkpoints that cannot pass: the end-effector of the tracked joints is compared with
  the expected pose (relative checkpoints: with how far the tool moved in the last move);
- the arm file's link volumes along each planned trajectory (:attr:`ValidationResult.proximities`);
- end-effector targets solved by IK (:attr:`ValidationResult.targets_deg`) and straight
  lines of the tool sampled and checked sample by sample (seqrun/cartesian.py).

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
from typing import TYPE_CHECKING

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

if TYPE_CHECKING:
    from seqrun.poses import PoseDirs

__all__ = [
    "PLAN_SAMPLE_S",
    "Clearance",
    "Proximity",
    "ValidationResult",
    "commanded_joints",
    "format_number",
    "park_deg",
    "pose_joints_deg",
    "resolve_checkpoint",
    "resolve_move_target",
    "validate_sequence",
]

#: Name of the pose a freshly powered-on arm is in (the modules' zeros).
from seqrun.defaults import START_POSE  # noqa: E402,F401  (re-exported)


#: Sampling period (s) of a planned trajectory when guards are checked along it: the
#: executor's control cycle at 100 Hz.
PLAN_SAMPLE_S = 0.01


@dataclass(frozen=True)
class Clearance:
    """The smallest distance to a guard along one move, and where it occurs."""

    step: int
    guard: str
    point: str
    z_mm: float
    margin_mm: float          # z minus the guard's height: below 0 the move is refused
    t_s: float                # plan time of the lowest sample
    duration_s: float         # the move's planned duration

    def as_dict(self) -> dict:
        return {"step": self.step, "guard": self.guard, "point": self.point,
                "z_mm": round(self.z_mm, 2), "margin_mm": round(self.margin_mm, 2),
                "t_s": round(self.t_s, 3), "duration_s": round(self.duration_s, 3)}


@dataclass(frozen=True)
class Proximity:
    """The smallest clearance between link volumes and obstacles (or two links) along one
    move, and where it occurs."""

    step: int
    pair: str                 # "wrist~desk", "column~forearm"
    distance_mm: float        # surface to surface; negative: they overlap
    t_s: float
    duration_s: float

    def as_dict(self) -> dict:
        return {"step": self.step, "pair": self.pair,
                "distance_mm": round(self.distance_mm, 2), "t_s": round(self.t_s, 3),
                "duration_s": round(self.duration_s, 3)}


def plan_samples(plan, period_s: float = PLAN_SAMPLE_S) -> tuple[np.ndarray, np.ndarray]:
    """Times and joint positions (rad, every joint) of a plan every ``period_s`` and at its
    end: what a guard check along the real trajectory looks at."""
    count = max(2, int(math.ceil(plan.duration / period_s)) + 1)
    times = np.linspace(0.0, plan.duration, count)
    return times, plan.sample(times)


@dataclass
class ValidationResult:
    """Errors (the sequence must not run) and notes (worth knowing, not wrong)."""

    errors: list[SourceError] = field(default_factory=list)
    notes: list[SourceError] = field(default_factory=list)
    #: Joint positions after the last step (user degrees, every joint of the arm).
    final_deg: dict[str, float] = field(default_factory=dict)
    #: Smallest guard clearance of each move (step number -> Clearance).
    clearances: dict[int, "Clearance"] = field(default_factory=dict)
    #: Joint solution (user degrees, every joint) of each end-effector target, by step number:
    #: the run solves again from the measured joints and must land close to it.
    targets_deg: dict[int, np.ndarray] = field(default_factory=dict)
    #: Smallest link-volume clearance of each move (step number -> Proximity).
    proximities: dict[int, "Proximity"] = field(default_factory=dict)

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


def pose_joints_deg(name: str, poses_dir: PoseDirs) -> dict[str, float]:
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
        self.poses_dir = loaded.pose_path or loaded.poses_dir
        self.poses = loaded.poses
        self.errors: list[SourceError] = []
        self.notes: list[SourceError] = []
        self.joints: dict[str, _JointState] = {}
        self._chain = None
        self.speed = 1.0  # the run's speed override: the plans guards are checked along
        self.clearances: dict[int, Clearance] = {}
        self.targets_deg: dict[int, np.ndarray] = {}
        self.proximities: dict[int, Proximity] = {}
        self.motion_start_deg: np.ndarray | None = None  # where the last move started
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
        if getattr(params, "position_mm", None) is not None:
            self._move_to_tool_pose(step, params)
            return
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
        if not self.incomplete and not refused:  # a target outside its limits: that error only
            self._guards_along_plan(step, params, target)
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

    def _guards_along_plan(self, step: ResolvedStep, params: MoveParams,
                           target: dict[str, float]) -> None:
        """Workspace guards along the trajectory the executor will stream: the ruckig plan
        of this move (its limits and scales, the run's speed), sampled every
        :data:`PLAN_SAMPLE_S` seconds. The plan's time-synchronized path is not the straight
        line in joint space and can dip lower. Records the move's smallest clearance."""
        from seqrun.planner import Limits, plan_move

        names = self.arm.joint_names
        start = np.array([self.joints[n].position for n in names])
        end = np.array([target[n] for n in names])
        moving = [i for i, j in enumerate(self.arm.joints)
                  if j.locked is None and abs(end[i] - start[i]) > 1e-9]
        if not moving:
            return
        velocity, acceleration = self.limits.maxima()  # the limits in force, as the run
        try:
            limits = Limits.from_arm(self.arm, velocity_scale=params.velocity_scale,
                                     acceleration_scale=params.acceleration_scale,
                                     speed=self.speed, velocity_deg_s={
                                         n: v for n, v in params.velocity_deg_s.items()
                                         if n in self.joints},
                                     max_velocity_deg_s=velocity,
                                     max_acceleration_deg_s2=acceleration)
            plan = plan_move(np.radians(start), np.radians(end), limits, moving)
        except PlanningError as exc:
            self.errors.append(step.error(f"this move cannot be planned: {exc}"))
            return
        self._check_path_guards(step, *plan_samples(plan), what="planned trajectory")

    def _check_path_guards(self, step: ResolvedStep, times: np.ndarray, path_rad: np.ndarray,
                           *, what: str) -> None:
        """Guards along sampled joint configurations (rad) at ``times`` (s): one error per
        guard, at the watched point that goes lowest; the smallest clearance is kept. Then
        the link volumes against the obstacles and each other (:meth:`_check_path_geometry`)."""
        self._check_path_geometry(step, times, path_rad, what=what)
        guards = self.arm.workspace.guards
        if not guards:
            return
        from seqrun.kinematics import Chain, point_positions

        if self._chain is None:
            self._chain = Chain.from_arm(self.arm)
        points = point_positions(self._chain, path_rad)
        duration = float(times[-1]) if len(times) else 0.0
        for guard in guards:
            lowest = min(guard.points, key=lambda p: float(points[p][:, 2].min()))
            heights = points[lowest][:, 2]
            i = int(np.argmin(heights))
            clearance = Clearance(step.number, guard.name, lowest, float(heights[i]),
                                  float(heights[i]) - guard.min_z_mm, float(times[i]), duration)
            kept = self.clearances.get(step.number)
            if kept is None or clearance.margin_mm < kept.margin_mm:
                self.clearances[step.number] = clearance
            if heights[i] < guard.min_z_mm:
                self.errors.append(step.error(
                    f"this move takes the {lowest.replace('_', '-')} down to z = "
                    f"{_f(heights[i])} mm (at {times[i]:.2f} s of {duration:.2f} s, {what}), "
                    f"below the '{guard.name}' guard at {_f(guard.min_z_mm)} mm"))

    def _check_path_geometry(self, step: ResolvedStep, times: np.ndarray, path_rad: np.ndarray,
                             *, what: str) -> None:
        """Link capsules against obstacles and non-neighbouring links along the samples."""
        if self.arm.geometry.capsules == []:
            return
        from seqrun.geometry import Geometry

        if getattr(self, "_geometry", None) is None:
            self._geometry = Geometry(self.arm)
        smallest = self._geometry.smallest(path_rad)
        if smallest is None:
            return
        duration = float(times[-1]) if len(times) else 0.0
        at = float(times[smallest.index])
        self.proximities[step.number] = Proximity(step.number, smallest.pair,
                                                  smallest.distance_mm, at, duration)
        margin = self._geometry.margin_mm
        if smallest.distance_mm < margin:
            a, b = smallest.pair.split("~", 1)
            how = ("into" if smallest.distance_mm < 0 else "within "
                   f"{_f(smallest.distance_mm)} mm of")
            self.errors.append(step.error(
                f"this move takes the {a} {how} the {b} (at {at:.2f} s of {duration:.2f} s, "
                f"{what}); the arm file's geometry margin is {_f(margin)} mm"))

    def _relative_checkpoint(self, step: ResolvedStep, params: CheckpointParams) -> None:
        """'The tool moved 50 mm along z': the tracked tool pose now against where the last
        move started."""
        from seqrun.cartesian import displacement, solver_for, tool_pose

        if self.motion_start_deg is None:
            self.errors.append(step.error("a relative checkpoint (moved_mm) needs a move before "
                                          "it", "moved_mm"))
            return
        try:
            solver = solver_for(self.arm, params.tool)
        except KeyError:
            names = ", ".join(t.name for t in self.arm.tools) or "none defined"
            self.errors.append(step.error(f"unknown tool '{params.tool}' (the arm file's tools: "
                                          f"{names})", "tool"))
            return
        moved = displacement(tool_pose(solver, self.motion_start_deg),
                             tool_pose(solver, self._tracked()), params.frame)
        off = float(np.linalg.norm(moved - np.asarray(params.moved_mm)))
        if off > params.position_tolerance_mm:
            self.errors.append(step.error(
                f"this checkpoint cannot pass: the last move takes the tool by "
                f"[{', '.join(_f(round(float(v), 3) + 0.0) for v in moved)}] mm ({params.frame} frame), {_f(off)} mm "
                f"from the expected [{', '.join(_f(v) for v in params.moved_mm)}] "
                f"(tolerance {_f(params.position_tolerance_mm)} mm)", "moved_mm"))

    # -- end-effector targets (seqrun/cartesian.py)
    def _tool_target(self, step: ResolvedStep, params) -> np.ndarray | None:
        """The step's tool target (4x4) from the tracked joints; None after an error."""
        from seqrun.cartesian import resolve_target, solver_for, tool_pose

        try:
            solver = solver_for(self.arm, params.tool)
        except KeyError:
            names = ", ".join(t.name for t in self.arm.tools) or "none defined"
            self.errors.append(step.error(f"unknown tool '{params.tool}' (the arm file's tools: "
                                          f"{names})", "tool"))
            return None
        current = tool_pose(solver, self._tracked())
        return resolve_target(current, params.position_mm, params.rpy_deg,
                              relative=params.relative, frame=params.frame)

    def _tracked(self) -> np.ndarray:
        return np.array([self.joints[n].position for n in self.arm.joint_names])

    def _unlocked_names(self) -> list[str]:
        return [j.name for j in self.arm.joints if j.locked is None]

    def _outside_limits(self, step: ResolvedStep, joints_deg: np.ndarray, what: str) -> bool:
        """Errors for joints outside the limits in force (set_limits may narrow the arm's)."""
        bad = False
        for name in self._unlocked_names():
            state = self.joints[name]
            lo, hi = state.limits or state.joint.limits_deg
            values = np.atleast_2d(joints_deg)[:, self.arm.index(name)]
            worst = values[np.argmax(np.maximum(lo - values, values - hi))]
            if not lo - 1e-9 <= worst <= hi + 1e-9:
                bad = True
                self.errors.append(step.error(
                    f"{what} puts {name} at {_f(worst)}°, outside the limits in force "
                    f"{_range(lo, hi)}", "position_mm"))
        return bad

    def _arrive(self, step: ResolvedStep, joints_deg: np.ndarray) -> None:
        self.targets_deg[step.number] = np.asarray(joints_deg, dtype=float).copy()
        for name in self._unlocked_names():
            state = self.joints[name]
            value = float(joints_deg[self.arm.index(name)])
            if value != state.position:
                state.at_start = False
            state.position = value

    def _solution_note(self, step: ResolvedStep, joints_deg: np.ndarray, extra: str = "") -> None:
        values = ", ".join(f"{n} {_f(joints_deg[self.arm.index(n)])}°"
                           for n in self._unlocked_names())
        self.notes.append(step.error(f"end-effector target solved: {values}{extra}",
                                     "position_mm"))

    def _move_to_tool_pose(self, step: ResolvedStep, params: MoveParams) -> None:
        """A move to an end-effector pose: IK from the tracked joints (the solution nearest
        them), then the same checks as a move to those joints."""
        from seqrun.cartesian import solver_for
        from seqrun.ik import Unreachable

        self._velocities(step, params)
        self._motion_allowed(step, self._unlocked_names())
        target = self._tool_target(step, params)
        if target is None:
            return
        try:
            solution = solver_for(self.arm, params.tool).solve(target, self._tracked())
        except Unreachable as exc:
            self.errors.append(step.error(f"end-effector target {exc}", "position_mm"))
            return
        joints = solution.joints_deg
        if self._outside_limits(step, joints, "the end-effector target"):
            return
        self._solution_note(step, joints)
        self._guards_along_plan(step, params, dict(zip(self.arm.joint_names, joints)))
        self._arrive(step, joints)

    def move_linear(self, step: ResolvedStep, params) -> None:
        """A straight line of the tool: every sample solved and checked now (reachable,
        limits, joint speeds, manipulability, guards along the samples)."""
        from seqrun.cartesian import PathError, plan_linear

        self._motion_allowed(step, self._unlocked_names())
        target = self._tool_target(step, params)
        if target is None:
            return
        keep = 1 - self.arm.control.tracking_reserve
        max_velocity = np.array([self.limits.velocity(n).value for n in self.arm.joint_names]) * keep
        try:
            linear = plan_linear(
                self.arm, params.tool, self._tracked(), target,
                speed_mm_s=params.speed_mm_s * self.speed,
                rotation_speed_deg_s=params.rotation_speed_deg_s * self.speed,
                acceleration_mm_s2=params.acceleration_mm_s2 * self.speed,
                jerk_mm_s3=params.jerk_mm_s3 * self.speed, max_velocity_deg_s=max_velocity)
        except PathError as exc:
            self.errors.append(step.error(f"straight line: {exc}", "position_mm"))
            return
        if self._outside_limits(step, linear.joints_deg[1:], "the straight line"):
            return
        self._check_path_guards(step, linear.plan.times, linear.plan.positions,
                                what="straight line of the tool")
        self._solution_note(step, linear.joints_deg[-1],
                            f" ({linear.path.length_mm:.1f} mm in {linear.plan.duration:.2f} s, "
                            f"smallest manipulability {linear.min_manipulability:.3f})")
        self._arrive(step, linear.joints_deg[-1])

    def checkpoint(self, step: ResolvedStep, params: CheckpointParams) -> None:
        if getattr(params, "moved_mm", None) is not None:
            self._relative_checkpoint(step, params)
            return
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
                    "wait": self.wait, "checkpoint": self.checkpoint,
                    "move_linear": self.move_linear, "power_off": self.power_off}
        for step in self.loaded.steps:
            handler = handlers.get(step.kind)
            if handler is not None:
                errors, notes = len(self.errors), len(self.notes)
                if step.kind in ("move", "move_linear"):
                    self.motion_start_deg = self._tracked()
                handler(step, step.params)  # type: ignore[operator]
                # a step's findings in the order they appear in its text
                self.errors[errors:] = sorted(self.errors[errors:], key=_position)
                self.notes[notes:] = sorted(self.notes[notes:], key=_position)
        final = {n: s.position for n, s in self.joints.items()}
        # In step order (a step of an included file comes where it runs), duplicates dropped.
        result = ValidationResult(list(dict.fromkeys(self.errors)),
                                  list(dict.fromkeys(self.notes)), final)
        result.clearances = dict(self.clearances)
        result.targets_deg = dict(self.targets_deg)
        result.proximities = dict(self.proximities)
        return result


def _position(item: SourceError) -> tuple[int, int]:
    return item.line, item.column


def validate_sequence(loaded: LoadedSequence, arm: ArmDescription,
                      start_deg: Mapping[str, float] | None = None, *,
                      started: bool = False, speed: float = 1.0,
                      module_limits: Mapping[str, tuple[float, float]] | None = None,
                      incomplete: bool = False) -> ValidationResult:
    """Check a loaded sequence against ``arm`` starting at ``start_deg`` (user degrees;
    default the Park pose of the project's poses folder).

    ``started=True``: the modules are already reset, homed and have the arm file's limits
    (the executor passes what it measured). ``speed``: the run's speed override, which
    shapes the plans the guards are checked along. ``module_limits``: MaxVel (deg/s) and
    MaxAcc (deg/s^2) per joint as read back from the modules (moves are planned within
    them). ``incomplete``: ``loaded`` lacks steps that failed on their own (see
    :func:`seqrun.schema.load_sequence_partial`); the checks that depend on the steps before
    (start-up order, positions: guards, checkpoints, relative targets) are skipped. Never
    raises for a bad sequence: everything is in the result.
    """
    if start_deg is None:
        start_deg = park_deg(loaded.pose_path or loaded.poses_dir)
    validator = _Validator(loaded, arm, start_deg, started, module_limits, incomplete)
    validator.speed = speed
    return validator.run()
