"""The arm description (``arms/*.yaml``): the single source of every number about the arm.

Joint limits, offsets, velocity/acceleration/jerk maxima, the locked joint, the kinematic
chain, CAN defaults, control-loop settings and workspace guards all come from this file;
nothing about the arm is hard-coded elsewhere. Angles are degrees in user coordinates
(Totem = zeros); ``module_position = user_position + offset`` (the driver converts:
:mod:`seqrun.drivers.powercube.units`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, field_validator, model_validator

from seqrun.arm.gripper import GripperSpec
from seqrun.arm.hazards import Hazards

if TYPE_CHECKING:
    from seqrun.errors import SourceError

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]

#: Points of the arm a workspace guard can watch (see :func:`seqrun.arm.kinematics.point_positions`).
GuardPoint = Literal["shoulder", "elbow", "wrist", "flange", "end_effector"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _no_items() -> list:
    """An empty list, as ``default_factory``: pydantic reads a factory's signature, and the
    builtin ``list``'s costs a tokenizer and a parse of its text signature, per field."""
    return []


class Joint(_Strict):
    name: str = Field(description="Joint name used in sequences, e.g. j1.")
    module: int = Field(ge=1, le=31, description="PowerCube module id on the CAN bus (any "
                                                 "1..31: a second arm on other ids is a "
                                                 "file, not code).")
    present: bool = Field(
        True, description="false: no module of this joint is on the bus (nothing is sent "
                          "to its id, nothing read); the joint must be locked, and the "
                          "kinematics keep its locked angle.")
    limits_deg: tuple[Finite, Finite] = Field(
        description="User-coordinate limits [min, max] in degrees, written as MinPos/MaxPos.")
    offset_deg: Finite = Field(0.0, description="module position minus user position, degrees.")
    locked: Finite | None = Field(
        None, description="If set, the joint is held at this user angle (deg) and never commanded.")
    max_velocity_deg_s: Positive = Field(description="Velocity limit, deg/s.")
    max_acceleration_deg_s2: Positive = Field(description="Acceleration limit, deg/s^2.")
    max_jerk_deg_s3: Positive = Field(description="Jerk limit for ruckig, deg/s^3.")
    max_current_a: Positive | None = Field(
        None, description="Current limit (MaxCur), A: written by set_limits (the thesis "
                          "wrote 2 A); a step may only lower it. Not given: the module's "
                          "stored MaxCur is left as it is.")

    @model_validator(mode="after")
    def _check(self) -> "Joint":
        lo, hi = self.limits_deg
        if not lo < hi:
            raise ValueError(f"limits_deg of {self.name}: min {lo} must be below max {hi}")
        if self.locked is not None and not lo <= self.locked <= hi:
            raise ValueError(f"locked value {self.locked} of {self.name} is outside its limits")
        if not self.present and self.locked is None:
            raise ValueError(f"{self.name} is not present (present: false): give its fixed "
                             "angle as locked, for the kinematics")
        return self


class Frame(_Strict):
    xyz_mm: tuple[Finite, Finite, Finite]
    rpy_deg: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)


class Kinematics(_Strict):
    base: Frame = Field(description="Mount to joint-1 frame.")
    links: list[Frame] = Field(description="F2..Fn: joint i-1 frame to joint i frame.")
    tool: Frame = Field(description="Last joint frame to the end-effector.")


class Watchdog(_Strict):
    enabled: bool = Field(False, description="Arm the modules' watchdog for every run and "
                                             "console activity (Config WATCHDOG_ENABLE, "
                                             "refreshed); velocity moves and jogs arm it "
                                             "anyway.")
    with_rt_priority: bool = Field(
        False, description="Arm it for every run and console activity whose control loop "
                           "runs at real-time priority (--rt-priority): a loop that is not "
                           "descheduled for the modules' timeout (about 50 ms). At normal "
                           "priority a busy host deschedules it for longer (docs/safety.md).")
    refresh_period_s: Positive = 0.03


class CanSettings(_Strict):
    bitrate: Literal[125000, 250000, 500000, 1000000] = 1000000
    response_timeout_s: Positive = 0.05
    watchdog: Watchdog = Watchdog()


class Control(_Strict):
    cycle_hz: Annotated[float, Field(ge=10, le=500)] = Field(
        100, description="Setpoint and monitoring loop rate of runs and of dry runs "
                         "(seqrun validate).")
    dry_run_cycle_hz: Annotated[float | None, Field(ge=5, le=500)] = Field(
        None, description="No longer used (ignored, with a note from seqrun validate): the "
                          "dry run streams at cycle_hz, as a run does, so that its figures "
                          "are the run's. Kept so that older arm files still load.")
    command_mode: Literal["ramp", "step"] = "ramp"
    tracking_reserve: Annotated[float, Field(ge=0, lt=0.5)] = Field(
        0.05, description="Fraction of each velocity limit kept out of the plans so that a "
                          "lagging joint can catch up with its plan without exceeding the limit.")
    module_acceleration_factor: Annotated[float, Field(ge=1, le=3)] = Field(
        1.5, description="TargetAcc sent to the modules as a multiple of the plan's "
                         "acceleration limit: the modules' own ramps must be able to follow.")
    max_following_error_deg: Positive = 4.0
    position_tolerance_deg: Positive = 0.2
    settle_timeout_s: Positive = 3.0
    max_wait_s: Positive = Field(
        600.0, description="Longest wait a sequence may ask for (wait seconds, timeout_s of "
                           "waits and moves), s; a longer one is a validation error.")
    max_dry_run_s: Positive = Field(
        7200.0, description="Simulated time after which a dry run (seqrun validate) stops "
                            "with an error, s: a bound on what one validation may cost.")


class Guard(_Strict):
    name: str
    min_z_mm: Finite = Field(description="Every watched point must stay above this height (mm).")
    points: list[GuardPoint] = Field(
        min_length=1, description="The points watched: joint axis points (shoulder, elbow, "
                                  "wrist, flange) and end_effector; a guard that watches "
                                  "end_effector watches every tool's volume too.")


class Workspace(_Strict):
    guards: list[Guard] = []


class ToolCapsule(_Strict):
    """A part of a tool's volume: the segment between two points of the end-effector frame,
    thickened by a radius (a link volume's shape, carried by the flange)."""

    name: str | None = Field(None, min_length=1, description="Names the part in messages "
                                                             "(tool probe/shaft).")
    start_mm: tuple[Finite, Finite, Finite] = Field(
        (0.0, 0.0, 0.0), description="One end, in the end-effector frame, mm.")
    end_mm: tuple[Finite, Finite, Finite] = Field(
        description="The other end, in the end-effector frame, mm (a tool along the flange's "
                    "axis: [0, 0, -length]).")
    radius_mm: Positive


class Tool(_Strict):
    """A tool on the flange: its tip frame (the tool centre point, TCP), where a Cartesian
    target of a sequence puts the tool, and its volume, checked against the obstacles, the
    links and the workspace guards as the links are."""

    name: str = Field(min_length=1, description="Name used in sequences and `seqrun ik --tool`.")
    xyz_mm: tuple[Finite, Finite, Finite] = Field(
        description="TCP position in the end-effector frame (kinematics.tool), mm. The "
                    "end-effector frame's z axis points back into the arm: a tool sticking out "
                    "of the flange ends at [0, 0, -length].")
    rpy_deg: tuple[Finite, Finite, Finite] = Field(
        (0.0, 0.0, 0.0), description="TCP orientation in the end-effector frame, roll/pitch/yaw "
                                     "deg (R = Rz Ry Rx). [180, 0, 0] turns the TCP's z axis "
                                     "to point out along the tool.")
    capsules: list[ToolCapsule] | None = Field(
        None, description="The tool's volume. Not given: the line from the end-effector to "
                          "the TCP (no thickness) is checked; [] : the TCP is a point in the "
                          "air with no body (a camera's focus), nothing is checked.")

    @model_validator(mode="after")
    def _part_names(self) -> "Tool":
        names = [c.name for c in self.capsules or []]
        if len(names) > 1 and (None in names or len(set(names)) != len(names)):
            raise ValueError(f"tool {self.name}: a tool of several capsules names each one, "
                             "differently")
        return self


FramePoint = Annotated[str, Field(
    min_length=1, description="A frame origin of the chain: base (the mount), a joint name "
                              "(its axis point, e.g. j2) or end_effector.")]


class Capsule(_Strict):
    """A link volume: the segment between two frame origins, thickened by a radius."""

    name: str = Field(min_length=1)
    start: FramePoint
    end: FramePoint
    radius_mm: Positive


class Plane(_Strict):
    point_mm: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)
    normal: tuple[Finite, Finite, Finite] = Field(
        (0.0, 0.0, 1.0), description="Points out of the obstacle (into free space).")


class Box(_Strict):
    center_mm: tuple[Finite, Finite, Finite]
    size_mm: tuple[Positive, Positive, Positive]
    rpy_deg: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)


class Cylinder(_Strict):
    base_mm: tuple[Finite, Finite, Finite] = Field(description="Centre of one end face.")
    axis: tuple[Finite, Finite, Finite] = (0.0, 0.0, 1.0)
    radius_mm: Positive
    height_mm: Positive


class Obstacle(_Strict):
    """A facility obstacle in the base frame: exactly one of plane, box, cylinder."""

    name: str = Field(min_length=1)
    plane: Plane | None = None
    box: Box | None = None
    cylinder: Cylinder | None = None
    ignore_links: list[str] = Field(
        default_factory=_no_items, description="Capsules (or tools, by name) that touch it by "
                                               "design (the column standing on the desk).")

    @model_validator(mode="after")
    def _one(self) -> "Obstacle":
        given = [k for k in ("plane", "box", "cylinder") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"obstacle {self.name}: give exactly one of plane, box, cylinder")
        if self.plane is not None and not any(self.plane.normal):
            raise ValueError(f"obstacle {self.name}: the plane's normal must not be zero")
        if self.cylinder is not None and not any(self.cylinder.axis):
            raise ValueError(f"obstacle {self.name}: the cylinder's axis must not be zero")
        return self

    @property
    def kind(self) -> str:
        return next(k for k in ("plane", "box", "cylinder") if getattr(self, k) is not None)

    @property
    def shape(self) -> Plane | Box | Cylinder:
        return getattr(self, self.kind)


class GeometrySpec(_Strict):
    """Link volumes and facility obstacles, checked along every planned trajectory and
    every control cycle (seqrun/arm/geometry.py)."""

    margin_mm: Annotated[float, Field(ge=0, allow_inf_nan=False)] = Field(
        10.0, description="Smallest clearance allowed between any two checked surfaces, mm.")
    capsules: list[Capsule] = Field(
        default_factory=_no_items, description="Link volumes in chain order; links that are not "
                                          "neighbours in this list are checked against each "
                                          "other (self-collision).")
    obstacles: list[Obstacle] = Field(default_factory=_no_items)
    allowed_pairs: list[tuple[str, str]] = Field(
        default_factory=_no_items, description="Capsule pairs never checked against each other "
                                               "(a tool by its name: [column, probe]).")


class Cartesian(_Strict):
    """Settings of end-effector targets and straight-line moves."""

    min_manipulability: Annotated[float, Field(ge=0, allow_inf_nan=False)] = Field(
        0.05, description="Smallest Yoshikawa manipulability sqrt(det(J Jᵀ)) allowed along a "
                          "straight-line move (linear rows of J in units of 200 mm, so the "
                          "number has no unit; the LWA 3 has 3.6 at Op-safe, 0 at Totem, "
                          "0.09 with the elbow 2° from straight).")
    ik_agreement_deg: Positive = Field(
        1.0, description="At run time an end-effector target is solved again from the measured "
                         "joints; a solution further than this (any joint, deg) from the "
                         "validated one is a fault.")
    linear_command_mode: Literal["ramp", "step"] = Field(
        "step", description="How straight-line moves are streamed. step (FSTEP to the next "
                            "sample every cycle) keeps the tool on the line (0.03 mm off over "
                            "300 mm on the simulator); ramp's lookahead and minimum speed let "
                            "slow joints run ahead of the others (2.8 mm).")
    linear_sample_s: Annotated[float, Field(gt=0, le=0.1, allow_inf_nan=False)] = Field(
        0.01, description="Sampling period of straight-line moves (s): every sample is solved "
                          "and checked before the move runs.")
class PowerOffPose(_Strict):
    """A pose the arm may be powered off in: the modules take it as their encoder zero."""

    description: str = ""
    offsets_deg: dict[str, Finite] = Field(
        description="module position minus user position of every joint, degrees, while the "
                    "modules were powered off in this pose (the pose itself is user = -offset).")


class ArmDescription(_Strict):
    name: str
    description: str = ""
    driver: str = Field(
        "powercube", description="How seqrun speaks to the arm's modules: the name of an arm "
                                 "driver (powercube: Schunk PowerCube modules over CAN).")
    can: CanSettings = CanSettings()
    control: Control = Control()
    joints: list[Joint] = Field(min_length=1)
    kinematics: Kinematics
    workspace: Workspace = Workspace()
    tools: list[Tool] = Field(
        default_factory=_no_items,
        description="The tools on the flange: tip frames and volumes. Cartesian targets and "
                    "checkpoints (seqrun ik, move to a pose in mm) mean the tool; without a "
                    "tool they mean the end-effector frame. Every tool's volume is checked on "
                    "every move, whichever tool a step names: list what is mounted.")
    cartesian: Cartesian = Cartesian()
    geometry: GeometrySpec = GeometrySpec()
    default_tool: str | None = Field(
        None, description="Tool used when a command or step names none (default: the "
                          "end-effector frame itself).")
    power_off_poses: dict[str, PowerOffPose] = Field(
        {}, description="The poses the arm may be powered off in (its zero references), each "
                        "with its offsets. The joints' offset_deg are those of "
                        "default_power_off.")
    default_power_off: str | None = Field(
        None, description="The power-off pose whose offsets the joints' offset_deg are.")
    gripper: GripperSpec | None = Field(
        None, description="A PowerCube gripper module on the same bus (e.g. Schunk PG 70), "
                          "for the grip/release/check_gripper steps; none when absent.")
    hazards: Hazards = Field(
        Hazards(), description="The hazard classes of motion steps (caution, hazardous): "
                               "each one's speed cap, the clearance that makes a move one "
                               "(within_mm) and who signs a hazardous step "
                               "(docs/safety.md, 'Hazard classes').")
    # SHA-256 of the file it was loaded from (recorded in run folders); not a file key.
    _sha256: str = PrivateAttr("")
    _file: str = PrivateAttr("")
    _source: bytes = PrivateAttr(b"")
    _notes: list = PrivateAttr(default_factory=_no_items)

    @property
    def sha256(self) -> str:
        return self._sha256

    @property
    def source_bytes(self) -> bytes:
        """The bytes of the file it was loaded from, as read (b"" if built in code)."""
        return self._source

    @property
    def source_file(self) -> str:
        """The file it was loaded from, as messages name it ("" if built in code)."""
        return self._file

    @property
    def notes(self) -> list[SourceError]:
        """What is worth knowing about the file, not wrong in it (keys no longer used),
        ``file:line:col``; ``seqrun validate`` lists them with the sequence's notes."""
        return list(self._notes)

    @field_validator("joints")
    @classmethod
    def _unique(cls, joints: list[Joint]) -> list[Joint]:
        for attr in ("name", "module"):
            seen = [getattr(j, attr) for j in joints]
            dup = {v for v in seen if seen.count(v) > 1}
            if dup:
                raise ValueError(f"duplicate joint {attr}: {sorted(dup)}")
        return joints

    @model_validator(mode="after")
    def _chain_matches_joints(self) -> "ArmDescription":
        if len(self.kinematics.links) != len(self.joints) - 1:
            raise ValueError(f"kinematics.links needs {len(self.joints) - 1} frames "
                             f"(one per joint after the first), has {len(self.kinematics.links)}")
        return self

    @model_validator(mode="after")
    def _gripper_module_free(self) -> "ArmDescription":
        if self.gripper is not None and self.gripper.module in [j.module for j in self.joints]:
            raise ValueError(f"gripper.module {self.gripper.module} is a joint's module id")
        return self

    @model_validator(mode="after")
    def _tools_known(self) -> "ArmDescription":
        names = [t.name for t in self.tools]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"duplicate tool name(s): {', '.join(dup)}")
        if self.default_tool is not None and self.default_tool not in names:
            raise ValueError(f"default_tool '{self.default_tool}' is not among the tools "
                             f"({', '.join(names) or 'none defined'})")
        return self

    @model_validator(mode="after")
    def _geometry_names(self) -> "ArmDescription":
        points = {"base", "end_effector", *self.joint_names}
        capsules = [c.name for c in self.geometry.capsules]
        for capsule in self.geometry.capsules:
            for point in (capsule.start, capsule.end):
                if point not in points:
                    raise ValueError(f"capsule {capsule.name}: unknown frame '{point}' (base, "
                                     f"{', '.join(self.joint_names)} or end_effector)")
        tools = [t.name for t in self.tools]
        names = capsules + [o.name for o in self.geometry.obstacles] + tools
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"duplicate capsule/obstacle/tool name(s): {', '.join(dup)}")
        for obstacle in self.geometry.obstacles:
            unknown = [n for n in obstacle.ignore_links if n not in capsules + tools]
            if unknown:
                raise ValueError(f"obstacle {obstacle.name}: unknown capsule(s) or tool(s) in "
                                 f"ignore_links: {', '.join(unknown)}")
        return self

    def tool(self, name: str | None) -> Tool | None:
        """The named tool, the default tool for ``None``; None means the end-effector frame.
        Raises ``KeyError`` for an unknown name."""
        name = self.default_tool if name is None else name
        if name is None:
            return None
        for tool in self.tools:
            if tool.name == name:
                return tool
        raise KeyError(name)

    @model_validator(mode="after")
    def _power_off_poses_match_joints(self) -> "ArmDescription":
        names = self.joint_names
        for pose, entry in self.power_off_poses.items():
            missing = [n for n in names if n not in entry.offsets_deg]
            unknown = [n for n in entry.offsets_deg if n not in names]
            if missing or unknown:
                raise ValueError(f"power_off_poses.{pose}.offsets_deg needs exactly the joints "
                                 f"{', '.join(names)}" + (f"; missing {', '.join(missing)}"
                                                          if missing else "")
                                 + (f"; unknown {', '.join(unknown)}" if unknown else ""))
        if self.default_power_off is not None:
            default = self.power_off_poses.get(self.default_power_off)
            if default is None:
                raise ValueError(f"default_power_off '{self.default_power_off}' is not one of "
                                 f"power_off_poses ({', '.join(self.power_off_poses) or 'none'})")
            differ = [j.name for j in self.joints
                      if not math.isclose(j.offset_deg, default.offsets_deg[j.name],
                                          abs_tol=1e-9)]
            if differ:
                raise ValueError(f"the joints' offset_deg must be those of default_power_off "
                                 f"'{self.default_power_off}'; {', '.join(differ)} differ")
        return self

    # Zero references: which offsets are in force depends on where the arm was powered off.
    def power_off_pose(self, name: str) -> PowerOffPose:
        """The power-off pose ``name`` (case-insensitive); UserInputError naming the known ones."""
        from seqrun.errors import UserInputError

        entry = self.power_off_poses.get(name) or self.power_off_poses.get(name.lower())
        if entry is None:
            known = ", ".join(self.power_off_poses) or "none"
            raise UserInputError(f"'{name}' is not a power-off pose of arm '{self.name}' "
                                 f"(its power-off poses: {known})")
        return entry

    def power_off_joints_deg(self, name: str) -> dict[str, float]:
        """Where the arm stands (user degrees) when it is in power-off pose ``name``: every
        module reads zero there, so user = -offset."""
        return {n: -v + 0.0 for n, v in self.power_off_pose(name).offsets_deg.items()}

    def with_zero_reference(self, name: str | None) -> "ArmDescription":
        """This arm with the offsets of power-off pose ``name`` (None: unchanged). The arm's
        driver, opened with it (or told with ``use_arm``), converts with them."""
        if name is None:
            return self
        offsets = self.power_off_pose(name).offsets_deg
        joints = [j.model_copy(update={"offset_deg": float(offsets[j.name])})
                  for j in self.joints]
        key = name if name in self.power_off_poses else name.lower()
        return self.model_copy(update={"joints": joints, "default_power_off": key})

    def at_loop_priority(self, realtime: bool) -> "ArmDescription":
        """This arm as a control loop at real-time priority (``realtime``) or not drives it:
        with ``can.watchdog.with_rt_priority`` the watchdog is armed for whole runs at
        real-time priority (as ``enabled``), never at normal priority."""
        wd = self.can.watchdog
        if not realtime or wd.enabled or not wd.with_rt_priority:
            return self
        can = self.can.model_copy(update={"watchdog": wd.model_copy(update={"enabled": True})})
        return self.model_copy(update={"can": can})

    def with_power_off_joints(self, joints_deg: Mapping[str, float]) -> "ArmDescription":
        """This arm with its modules' zeros at ``joints_deg`` (user degrees by joint name):
        where it was powered off when that was none of its power-off poses (a power loss
        mid-move). Every module reads zero there, so offset = -angle."""
        joints = [j.model_copy(update={"offset_deg": -float(joints_deg[j.name]) + 0.0})
                  for j in self.joints]
        return self.model_copy(update={"joints": joints, "default_power_off": None})

    # Convenience views used everywhere.
    @property
    def dof(self) -> int:
        return len(self.joints)

    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def module_ids(self) -> list[int]:
        return [j.module for j in self.joints]

    @property
    def present_module_ids(self) -> list[int]:
        """The modules on the bus: those of the joints not declared absent."""
        return [j.module for j in self.joints if j.present]

    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    def index(self, name: str) -> int:
        return self.joint_names.index(name)


#: Arm file used when a sequence names none (relative to the project root / cwd).


def load_arm(path: str | Path) -> ArmDescription:
    """Load and validate an arm file; raises :class:`seqrun.errors.SequenceInvalid`
    with ``file:line:col`` errors."""
    from seqrun.yamlsource import load_document  # local import: a sibling layer

    document = load_document(Path(path))
    arm = document.validate(ArmDescription)
    arm._sha256, arm._file, arm._source = document.sha256, document.file, document.source
    if arm.control.dry_run_cycle_hz is not None:
        arm._notes.append(document.error(
            ("control", "dry_run_cycle_hz"), "control.dry_run_cycle_hz is no longer used and "
            f"is ignored: the dry run streams at control.cycle_hz ({arm.control.cycle_hz:g} "
            "Hz) like a run, so that its figures are the run's; delete this line",
            key=True))
    return arm
