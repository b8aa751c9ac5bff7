"""Static validation of a loaded sequence against the arm and a start state.

:func:`validate_sequence` walks the flattened steps and tracks, per joint, the position
(the targets of the moves before) and what the modules have been told: Reset, Home,
Halt, the limits written by ``set_limits``. Each step kind's own checks are its
``check`` (``seqrun/steps/<kind>.py``, found through :mod:`seqrun.steps.registry`);
:class:`Checker` holds what they share: the tracked joints and modules, the findings,
and the checks every kind may use. They report, each at the ``file:line:col`` of the
offending value:

- the start-up order the hardware needs: Home before any motion (after Reset), the
  limits written before moving (the modules' stored limits are narrower), Reset before
  Home and before writing parameters, and Reset again after a Halt;
- joints the arm does not have, and any command to a locked joint;
- every commanded target inside the limits in force; a joint that *starts* outside (an
  arm powered off outside its limits) may only move back inside, which is a note;
- velocities and limit overrides within the arm file's maxima;
- workspace guards (``workspace.guards`` of the arm file) along each move's ruckig plan,
  the trajectory the executor streams (sampled at 100 Hz), with the smallest clearance of
  every move in :attr:`ValidationResult.clearances`;
- checkpoints that cannot pass: the end-effector of the tracked joints is compared with
  the expected pose (relative checkpoints: with how far the tool moved in the last move);
- the arm file's link volumes along each planned trajectory (:attr:`ValidationResult.proximities`);
- end-effector targets solved by IK (:attr:`ValidationResult.targets_deg`) and straight
  lines of the tool sampled and checked sample by sample (seqrun/arm/cartesian.py).

The executor runs it again with the measured start state (``start_deg``) and
``started=True`` when the modules report that they are reset, homed and limited.
A kind's check sees the :class:`Checker` as a
:class:`~seqrun.steps.check_context.CheckContext` (the step layer's protocol); where a move
or a checkpoint goes is its kind's own (``seqrun.steps.move.resolve_move_target``,
``seqrun.steps.checkpoint.resolve_checkpoint``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from seqrun.steps._expression_checks import check_monitors
from seqrun.steps._flow_checks import check_block, check_flow
from seqrun.arm.description import ArmDescription
from seqrun.errors import PlanningError, SourceError
from seqrun.formatting import format_number as _f
from seqrun.formatting import format_range
from seqrun.arm.limits import READBACK, LimitsInForce
from seqrun.arm.poses import park_deg
from seqrun.sequence.hazard_classes import HazardFinding, classify
from seqrun.steps.check_context import TrackedJoint
from seqrun.steps.blocks import has_rescue, normal_path, rescue_paths
from seqrun.steps.registry import step_kind
from seqrun.yamlsource import sort_errors

if TYPE_CHECKING:
    from seqrun.arm.geometry import Geometry
    from seqrun.arm.ik import IkSolver
    from seqrun.arm.kinematics import Chain
    from seqrun.sequence.loader import LoadedSequence
    from seqrun.steps.check_context import PlannedMoveParams
    from seqrun.steps.params import ToolParams, ToolTargetParams
    from seqrun.steps.resolved import ResolvedStep

__all__ = [
    "PLAN_SAMPLE_S",
    "Checker",
    "Clearance",
    "Proximity",
    "ValidationResult",
    "validate_sequence",
]


#: Step kinds that change the modules' start-up state (reset, homed, limits, halted,
#: powered off): one left out makes the start-up order unknown from there.
STARTUP_STATE_KINDS = frozenset({"reset", "home", "set_limits", "halt", "power_off"})

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
    #: The sampled planned path of each move (step number -> (times s, joints rad)).
    paths: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict,
                                                            repr=False)
    #: Each motion step of class caution or hazardous (step number -> HazardFinding):
    #: its speed cap and whether it needs a signed confirm (docs/safety.md).
    hazards: dict[int, HazardFinding] = field(default_factory=dict)

    @property
    def valid(self) -> bool:
        return not self.errors


# --------------------------------------------------------------------------- tracking
class Checker:
    """The state the step kinds' checks share while walking the steps: the joints and
    modules as the steps before left them (:class:`~seqrun.steps.check_context.TrackedJoint`),
    the limits in force, the findings (``errors``, ``notes``), and the checks more than one
    kind needs. The kinds see it as a :class:`~seqrun.steps.check_context.CheckContext`."""

    def __init__(self, loaded: LoadedSequence, arm: ArmDescription,
                 start_deg: Mapping[str, float], started: bool,
                 module_limits: Mapping[str, tuple[float, float]] | None = None,
                 incomplete: bool = False) -> None:
        self.loaded = loaded
        # Steps were left out (they failed on their own): from the first one that may have
        # changed the modules' start-up state (reset, home, limits, halt), that order is not
        # checked (``incomplete``); from one that may have moved the arm, what depends on
        # where the joints are is not checked until a move says where they are again
        # (``position_unknown``). Everything else is, so that one pass shows every problem.
        self.incomplete = incomplete
        self.position_unknown = incomplete
        self._left_out: dict[int, list[str | None]] = {}
        for before, kind in getattr(loaded, "left_out", ()):
            self._left_out.setdefault(before, []).append(kind)
        self.arm = arm
        self.poses_dir = loaded.pose_path or loaded.poses_dir
        self.poses = loaded.poses
        self.errors: list[SourceError] = []
        self.notes: list[SourceError] = []
        self.joints: dict[str, TrackedJoint] = {}
        self._chain: Chain | None = None
        self._geometry: Geometry | None = None
        self.speed = 1.0  # the run's speed override: the plans guards are checked along
        self.clearances: dict[int, Clearance] = {}
        self.targets_deg: dict[int, np.ndarray] = {}
        self.proximities: dict[int, Proximity] = {}
        self.hazards: dict[int, HazardFinding] = {}
        self.motion_start_deg: np.ndarray | None = None  # where the last move started
        # The step after which where the arm stands is not known (an unreachable target):
        # the checks that compare with it are left out until a move says again.
        self.lost_at: ResolvedStep | None = None
        # Limits the file itself sets (arm file, its set_limits): exceeding them is an
        # error. ``limits`` adds what the modules hold: moves are planned within it.
        self.file_limits = LimitsInForce(arm)
        self.limits = LimitsInForce(arm)
        self.pose_checked: dict[str, bool] = {}  # pose name -> usable
        # pose -> joint -> its finding at the pose file's line
        self.pose_limit_findings: dict[str, dict[str, SourceError]] = {}
        self.reported_pose_limits: set[tuple[str, str]] = set()
        self.powered_off: ResolvedStep | None = None  # the power_off step, once there is one
        #: The arm's id in a campaign with several arms (None: the one arm).
        self.arm_id: str | None = getattr(loaded, "arm_id", None)
        #: The sampled planned path of each move (step number -> (times s, joints rad)):
        #: the arms of a campaign are checked against each other along them.
        self.paths: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        for joint in arm.joints:
            position = joint.locked if joint.locked is not None else start_deg.get(joint.name)
            if position is None or not math.isfinite(position):
                what = "is missing" if position is None else f"is {position}"
                self.errors.append(loaded.location.error(
                    f"start state: {joint.name} {what} (a finite angle is needed for every "
                    "unlocked joint)"))
                position = 0.0
            state = TrackedJoint(joint, float(position))
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
    def pose(self, step: ResolvedStep, name: str, *, target: bool) -> dict[str, float] | None:
        """The frozen joints of pose ``name``; None if it cannot be used (reported)."""
        frozen = self.poses.get(name)
        if frozen is None:
            return None  # unknown or broken pose file: reported when the sequence was loaded
        if name not in self.pose_checked:
            from seqrun.arm.poses import pose_findings

            usable = True
            limits: dict[str, SourceError] = {}
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
                    f"{joint} {_f(value)}° is outside its limits {format_range(lo, hi)}: pose "
                    f"'{name}' cannot be a move target (used at {step.where('pose')})"))
        return frozen.joints_deg if self.pose_checked[name] else None

    # -- common checks
    def names(self, step: ResolvedStep, names: list[str] | Mapping[str, Any], path: tuple,
              *, as_keys: bool, what: str) -> list[str]:
        """Known, unlocked joint names among ``names``; errors for the others."""
        good = []
        for i, name in enumerate(names):
            where = path + ((name,) if as_keys else (i,))
            if name not in self.joints:
                self.errors.append(step.error(
                    f"unknown joint '{name}' (the arm has {', '.join(self.arm.joint_names)})",
                    *where, key=as_keys))
            elif (locked := self.joints[name].joint.locked) is not None:
                self.errors.append(step.error(
                    f"{name} is locked at {_f(locked)}°: {what} a "
                    "locked joint is not allowed (seqrun never commands it)", *where,
                    key=as_keys))
            else:
                good.append(name)
        return good

    def modules(self, step: ResolvedStep, joints: str | list[str]) -> list[TrackedJoint]:
        """The joints a module command (reset, home, halt) addresses: every one for
        'all', else the known ones named (errors for the others)."""
        if joints == "all":
            return list(self.joints.values())
        names = self.names(step, list(joints), ("joints",), as_keys=False,
                           what=f"a {step.kind} of")
        return [self.joints[n] for n in names]

    # -- shared by the step kinds' checks
    def after_halt(self, step: ResolvedStep, what: str) -> None:
        """A wait or checkpoint reads the modules, which report HALTED until Reset: after
        a halt it can only fail."""
        halted = [s.joint.name for s in self.joints.values() if s.halted and not s.locked]
        if halted and not self.incomplete:
            self.errors.append(step.error(
                f"{what} after halt{self.which(halted)}: the modules report HALTED until "
                "Reset and this step reads them, so it can never pass; reset first"))

    def motion_allowed(self, step: ResolvedStep, names: list[str]) -> None:
        """The start-up order before moving ``names``: reset, home, limits, no halt."""
        states = [self.joints[n] for n in names]
        not_homed = [s.joint.name for s in states if not s.homed]
        not_reset = [s.joint.name for s in states if not s.reset]
        halted = [s.joint.name for s in states if s.halted]
        no_limits = [s.joint.name for s in states if s.limits is None]
        if not_homed:
            first = "; reset them first, then home" if not_reset else ""
            self.errors.append(step.error(
                f"move before home{self.which(not_homed, names)}: the modules refuse motion "
                f"until Home{first}"))
        elif not_reset:
            self.errors.append(step.error(
                f"move before reset{self.which(not_reset, names)}: the modules refuse motion "
                "until Reset"))
        if halted:
            self.errors.append(step.error(
                f"move after halt{self.which(halted, names)}: the modules refuse motion until "
                "Reset"))
        if no_limits and not not_homed:
            self.errors.append(step.error(
                f"move before set_limits{self.which(no_limits, names)}: write the joint "
                "limits first (the modules' stored limits are narrower than the arm file's)"))

    def which(self, names: list[str], of: list[str] | None = None) -> str:
        """" (j1, j2)" naming ``names`` in a message, or "" when they are all of ``of``
        (default: every unlocked joint)."""
        everything = of if of is not None else [s.joint.name for s in self.joints.values()
                                                 if not s.locked]
        return "" if sorted(names) == sorted(everything) else f" ({', '.join(names)})"

    def guards_along_plan(self, step: ResolvedStep, params: PlannedMoveParams,
                          target: dict[str, float]) -> None:
        """Workspace guards along the trajectory the executor will stream: the ruckig plan
        of this move (its limits and scales, the run's speed), sampled every
        :data:`PLAN_SAMPLE_S` seconds. The plan's time-synchronized path is not the straight
        line in joint space and can dip lower. Records the move's smallest clearance."""
        from seqrun.arm.planner import Limits, plan_move

        names = self.arm.joint_names
        start = np.array([self.joints[n].position for n in names])
        end = np.array([target[n] for n in names])
        moving = [i for i, j in enumerate(self.arm.joints)
                  if j.locked is None and abs(end[i] - start[i]) > 1e-9]
        if not moving:
            return
        velocity, acceleration = self.limits.maxima()  # the limits in force, as the run
        # The hazard class's speed cap narrows the plan, and the plan it narrows is the
        # one checked: a class derived from this plan's clearance that caps it lower is
        # planned and checked again (at most twice: there are two capped classes).
        cap, errors = self.hazard_speed_scale(step), len(self.errors)
        for _ in range(3):
            try:
                limits = Limits.from_arm(self.arm,
                                         velocity_scale=min(params.velocity_scale, cap),
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
            self.check_path_guards(step, *plan_samples(plan), what="planned trajectory")
            derived = self.hazard_speed_scale(step)
            if len(self.errors) > errors or derived >= cap:
                return
            cap = derived

    def hazard_speed_scale(self, step: ResolvedStep) -> float:
        """The speed cap of ``step``'s hazard class as far as it is known (given, or
        derived from the clearances recorded so far); 1.0: none."""
        finding, _ = classify(step, self.arm, motion=True, closest=self.closest(step))
        return finding.speed_scale if finding is not None else 1.0

    def closest(self, step: ResolvedStep) -> tuple[float, str] | None:
        """The move's smallest planned clearance (mm) so far, to a guard or between link
        volumes and obstacles, and what it is to (None: none recorded)."""
        found: list[tuple[float, str]] = []
        clearance = self.clearances.get(step.number)
        if clearance is not None:
            found.append((clearance.margin_mm, f"guard {clearance.guard}"))
        proximity = self.proximities.get(step.number)
        if proximity is not None:
            found.append((proximity.distance_mm, proximity.pair.replace("~", " to ")))
        return min(found, default=None)

    def check_path_guards(self, step: ResolvedStep, times: np.ndarray, path_rad: np.ndarray,
                          *, what: str) -> None:
        """Guards along sampled joint configurations (rad) at ``times`` (s): an error for
        every watched point (the hand, the tool, ...) that goes below a guard, at its
        lowest; the smallest clearance is kept. Then the link and tool volumes against the
        obstacles and each other (:meth:`_path_collisions`). Every collision of the move
        is reported, in the order they happen: one pass shows them all."""
        from seqrun.arm.geometry import Geometry
        from seqrun.arm.kinematics import Chain, frame_origins, points_of_origins

        self.paths[step.number] = (times, path_rad)
        guards = self.arm.workspace.guards
        if not guards and self.arm.geometry.capsules == [] and not self.arm.tools:
            return
        if self._chain is None:
            self._chain = Chain.from_arm(self.arm)
        if self._geometry is None:
            self._geometry = Geometry(self.arm)
        # one forward kinematics of the samples for the link and tool volumes and the guards
        origins = frame_origins(self._chain, path_rad, self._geometry.ee_points)
        found = self._path_collisions(step, times, path_rad, what=what, origins=origins)
        found += self._guard_crossings(step, times, what=what, origins=origins)
        found.sort(key=lambda item: item[0])  # stable: a guard's points in watched order
        self.errors.extend(error for _, error in found)

    def _guard_crossings(self, step: ResolvedStep, times: np.ndarray, *, what: str,
                         origins: np.ndarray) -> list[tuple[float, SourceError]]:
        """Every watched point below every guard (time of its lowest, error); the move's
        smallest guard clearance is kept."""
        from seqrun.arm.kinematics import points_of_origins

        guards = self.arm.workspace.guards
        if not guards:
            return []
        assert self._chain is not None and self._geometry is not None
        dof = self._chain.dof
        points: dict[str, np.ndarray] = dict(points_of_origins(origins, dof))
        labels: dict[str, str] = {}
        tools = self._geometry.tools
        if not tools.empty:
            # a guard that watches the end-effector watches what the flange carries too
            lowest_tool, part = tools.lowest(origins[..., dof + 1:, :])
            points["tool"] = lowest_tool
            labels = {"tool": tools.parts[int(part[int(np.argmin(lowest_tool[:, 2]))])].label}
        duration = float(times[-1]) if len(times) else 0.0
        found: list[tuple[float, SourceError]] = []
        for guard in guards:
            watched = list(guard.points)
            if "end_effector" in watched and "tool" in points:
                watched.append("tool")
            for point in sorted(watched, key=lambda p: float(points[p][:, 2].min())):
                heights = points[point][:, 2]
                i = int(np.argmin(heights))
                clearance = Clearance(step.number, guard.name, labels.get(point, point),
                                      float(heights[i]), float(heights[i]) - guard.min_z_mm,
                                      float(times[i]), duration)
                kept = self.clearances.get(step.number)
                if kept is None or clearance.margin_mm < kept.margin_mm:
                    self.clearances[step.number] = clearance
                if heights[i] < guard.min_z_mm:
                    name = labels.get(point, point.replace('_', '-'))
                    found.append((float(times[i]), step.error(
                        f"this move takes the {name} down to z = "
                        f"{_f(heights[i])} mm (at {times[i]:.2f} s of {duration:.2f} s, "
                        f"{what}), below the '{guard.name}' guard at "
                        f"{_f(guard.min_z_mm)} mm")))
        return found

    def _path_collisions(self, step: ResolvedStep, times: np.ndarray, path_rad: np.ndarray,
                         *, what: str, origins: np.ndarray) -> list[tuple[float, SourceError]]:
        """Link and tool capsules against obstacles and non-neighbouring links along the
        samples (``origins``: their frames' origins,
        :func:`~seqrun.arm.kinematics.frame_origins`): (time, error) of every pair that
        comes within the margin, at its closest; the move's smallest clearance is kept."""
        if self._geometry is None or self._geometry.empty:
            return []
        margin = self._geometry.margin_mm
        smallest, close = self._geometry.within(path_rad, origins, margin)
        if smallest is None:
            return []
        duration = float(times[-1]) if len(times) else 0.0
        self.proximities[step.number] = Proximity(step.number, smallest.pair,
                                                  smallest.distance_mm,
                                                  float(times[smallest.index]), duration)
        found: list[tuple[float, SourceError]] = []
        for pair in close:
            a, b = pair.pair.split("~", 1)
            at = float(times[pair.index])
            how = ("into" if pair.distance_mm < 0 else "within "
                   f"{_f(pair.distance_mm)} mm of")
            found.append((at, step.error(
                f"this move takes the {a} {how} the {b} (at {at:.2f} s of {duration:.2f} s, "
                f"{what}); the arm file's geometry margin is {_f(margin)} mm")))
        return found

    # -- end-effector targets (seqrun/arm/cartesian.py)
    def tool_target(self, step: ResolvedStep, params: ToolTargetParams) -> np.ndarray | None:
        """The step's tool target (4x4) from the tracked joints; None after an error."""
        from seqrun.arm.cartesian import resolve_target, tool_pose

        assert params.position_mm is not None  # (only steps with a tool target come here)
        solver = self.tool_solver(step, params)
        if solver is None:
            return None
        current = tool_pose(solver, self.tracked())
        return resolve_target(current, params.position_mm, params.rpy_deg,
                              relative=params.relative, frame=params.frame)

    def tool_solver(self, step: ResolvedStep, params: ToolParams) -> IkSolver | None:
        """The IK solver of the step's tool; None (and an error at ``tool``) for a tool the
        arm file does not define."""
        from seqrun.arm.cartesian import solver_for, unknown_tool

        try:
            return solver_for(self.arm, params.tool)
        except KeyError:
            self.errors.append(step.error(unknown_tool(self.arm, params.tool), "tool"))
            return None

    def tracked(self) -> np.ndarray:
        """Where the steps so far leave every joint (user degrees, arm order)."""
        return np.array([self.joints[n].position for n in self.arm.joint_names])

    def unlocked_names(self) -> list[str]:
        return [j.name for j in self.arm.joints if j.locked is None]

    def outside_limits(self, step: ResolvedStep, joints_deg: np.ndarray, what: str) -> bool:
        """Errors for joints outside the limits in force (set_limits may narrow the arm's)."""
        bad = False
        for name in self.unlocked_names():
            state = self.joints[name]
            lo, hi = state.limits or state.joint.limits_deg
            values = np.atleast_2d(joints_deg)[:, self.arm.index(name)]
            worst = values[np.argmax(np.maximum(lo - values, values - hi))]
            if not lo - 1e-9 <= worst <= hi + 1e-9:
                bad = True
                self.errors.append(step.error(
                    f"{what} puts {name} at {_f(worst)}°, outside the limits in force "
                    f"{format_range(lo, hi)}", "position_mm"))
        return bad

    def arrive(self, step: ResolvedStep, joints_deg: np.ndarray) -> None:
        """An end-effector target's solution (every joint): tracked from here on, and kept
        for the run to compare its own solution with."""
        self.targets_deg[step.number] = np.asarray(joints_deg, dtype=float).copy()
        self.lost_at = None
        self.position_unknown = False
        for name in self.unlocked_names():
            state = self.joints[name]
            value = float(joints_deg[self.arm.index(name)])
            if value != state.position:
                state.at_start = False
            state.position = value

    def solution_note(self, step: ResolvedStep, joints_deg: np.ndarray, extra: str = "") -> None:
        """A note at ``position_mm``: the joints an end-effector target was solved to."""
        values = ", ".join(f"{n} {_f(joints_deg[self.arm.index(n)])}°"
                           for n in self.unlocked_names())
        self.notes.append(step.error(f"end-effector target solved: {values}{extra}",
                                     "position_mm"))

    def _pass_left_out(self, kinds: list[str | None]) -> None:
        """Steps left out here: what they may have changed is no longer known."""
        for name in kinds:
            kind = step_kind(name) if name is not None else None
            if kind is None or kind.motion:
                self.position_unknown = True
            if kind is None or name in STARTUP_STATE_KINDS:
                self.incomplete = True

    def run(self) -> ValidationResult:
        at = getattr(self.loaded, "monitors_at", None)
        if at is not None:  # the sequence's monitors: once, where they are written
            check_monitors(self, at, self.loaded.monitors)
        for index, step in enumerate(self.loaded.steps):
            self._pass_left_out(self._left_out.get(index, []))
            kind = step_kind(step.kind)
            errors, notes = len(self.errors), len(self.notes)
            if kind.motion:
                self.motion_start_deg = self.tracked()
            kind.check(self, step, step.params)
            check_monitors(self, step, step.params.monitors)
            check_flow(self, step, step.params, motion=kind.motion)
            if step.blocks:
                check_block(self, step)
            finding, wrong = classify(step, self.arm, motion=kind.motion,
                                      closest=self.closest(step))
            if wrong is not None:
                self.errors.append(wrong)
            if finding is not None:
                self.hazards[step.number] = finding
            # a step's findings in the order they appear in its text, then those in other
            # files (the pose file it names)
            here = step.location.file
            self.errors[errors:] = sorted(self.errors[errors:], key=lambda e: _position(e, here))
            self.notes[notes:] = sorted(self.notes[notes:], key=lambda n: _position(n, here))
        final = {n: s.position for n, s in self.joints.items()}
        # Errors in the order `seqrun validate` prints a file's load errors: by position
        # within a file, the files in the order the steps reach them (a pose file after the
        # step naming it), duplicates dropped; every command reports this one order.
        # Notes stay in step order (a step of an included file comes where it runs).
        result = ValidationResult(sort_errors(self.errors),
                                  list(dict.fromkeys(self.notes)), final)
        result.clearances = dict(self.clearances)
        result.targets_deg = dict(self.targets_deg)
        result.proximities = dict(self.proximities)
        result.paths = dict(self.paths)
        result.hazards = dict(self.hazards)
        return result


def _position(item: SourceError, file: str) -> tuple[bool, int, int]:
    return item.file != file, item.line, item.column


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
    :func:`seqrun.sequence.loader.load_sequence_partial`); the checks that depend on the steps before
    (start-up order, positions: guards, checkpoints, relative targets) are skipped. Never
    raises for a bad sequence: everything is in the result.
    """
    if start_deg is None:
        start_deg = park_deg(loaded.pose_path or loaded.poses_dir)

    def check(steps: Sequence[ResolvedStep] | None = None) -> ValidationResult:
        checked = loaded if steps is None else _on_path(loaded, steps)
        checker = Checker(checked, arm, start_deg, started, module_limits, incomplete)
        checker.speed = speed
        return checker.run()

    if not has_rescue(loaded.steps):
        return check()
    # the normal path, then each block's rescue path: every step is checked where it can
    # run (docs/safety.md, 'What a rescue may follow')
    result = check(normal_path(loaded.steps))
    for path in rescue_paths(loaded.steps).values():
        other = check(path)
        result.errors = sort_errors(result.errors + other.errors)
        result.notes = list(dict.fromkeys(result.notes + other.notes))
        for mine, theirs in ((result.clearances, other.clearances),
                             (result.targets_deg, other.targets_deg),
                             (result.proximities, other.proximities),
                             (result.paths, other.paths),
                             (result.hazards, other.hazards)):
            for number, value in theirs.items():
                mine.setdefault(number, value)  # type: ignore[attr-defined]
    return result


def _on_path(loaded: LoadedSequence, steps: Sequence[ResolvedStep]) -> LoadedSequence:
    """``loaded`` with only ``steps`` (the steps left out counted where they stood)."""
    from dataclasses import replace

    kept = {id(s) for s in steps}
    before = [0]
    for step in loaded.steps:
        before.append(before[-1] + (id(step) in kept))
    left_out = tuple((before[index], kind) for index, kind in getattr(loaded, "left_out", ()))
    return replace(loaded, steps=tuple(steps), left_out=left_out)
