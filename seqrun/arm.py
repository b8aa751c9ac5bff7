"""The arm description (``arms/*.yaml``): the single source of every number about the arm.

Joint limits, offsets, velocity/acceleration/jerk maxima, the locked joint, the kinematic
chain, CAN defaults, control-loop settings and workspace guards all come from this file;
nothing about the arm is hard-coded elsewhere. Angles are degrees in user coordinates
(Totem = zeros); ``module_position = user_position + offset``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, field_validator, model_validator

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]

#: Points of the arm a workspace guard can watch (see :func:`seqrun.kinematics.point_positions`).
GuardPoint = Literal["shoulder", "elbow", "wrist", "flange", "end_effector"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Joint(_Strict):
    name: str = Field(description="Joint name used in sequences, e.g. j1.")
    module: int = Field(ge=1, le=31, description="PowerCube module id on the CAN bus.")
    limits_deg: tuple[Finite, Finite] = Field(
        description="User-coordinate limits [min, max] in degrees, written as MinPos/MaxPos.")
    offset_deg: Finite = Field(0.0, description="module position minus user position, degrees.")
    locked: Finite | None = Field(
        None, description="If set, the joint is held at this user angle (deg) and never commanded.")
    max_velocity_deg_s: Positive = Field(description="Velocity limit, deg/s.")
    max_acceleration_deg_s2: Positive = Field(description="Acceleration limit, deg/s^2.")
    max_jerk_deg_s3: Positive = Field(description="Jerk limit for ruckig, deg/s^3.")

    @model_validator(mode="after")
    def _check(self) -> "Joint":
        lo, hi = self.limits_deg
        if not lo < hi:
            raise ValueError(f"limits_deg of {self.name}: min {lo} must be below max {hi}")
        if self.locked is not None and not lo <= self.locked <= hi:
            raise ValueError(f"locked value {self.locked} of {self.name} is outside its limits")
        return self

    # Conversions between the user's degrees and the module's radians.
    def to_module_rad(self, user_deg: float) -> float:
        return math.radians(user_deg + self.offset_deg)

    def to_user_deg(self, module_rad: float) -> float:
        return math.degrees(module_rad) - self.offset_deg


class Frame(_Strict):
    xyz_mm: tuple[Finite, Finite, Finite]
    rpy_deg: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)


class Kinematics(_Strict):
    base: Frame = Field(description="Mount to joint-1 frame.")
    links: list[Frame] = Field(description="F2..Fn: joint i-1 frame to joint i frame.")
    tool: Frame = Field(description="Last joint frame to the end-effector.")


class Watchdog(_Strict):
    enabled: bool = False
    refresh_period_s: Positive = 0.03


class CanSettings(_Strict):
    bitrate: Literal[125000, 250000, 500000, 1000000] = 1000000
    response_timeout_s: Positive = 0.05
    watchdog: Watchdog = Watchdog()


class Control(_Strict):
    cycle_hz: Annotated[float, Field(ge=10, le=500)] = 100
    dry_run_cycle_hz: Annotated[float, Field(ge=5, le=500)] = Field(
        10, description="Control-loop rate of dry runs (seqrun validate). The modules' ramps "
                        "interpolate between setpoints, so a slower stream changes simulated "
                        "durations by about a cycle and makes dry runs far faster.")
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
    points: list[GuardPoint] = Field(min_length=1)


class Workspace(_Strict):
    guards: list[Guard] = []


class ArmDescription(_Strict):
    name: str
    description: str = ""
    can: CanSettings = CanSettings()
    control: Control = Control()
    joints: list[Joint] = Field(min_length=1)
    kinematics: Kinematics
    workspace: Workspace = Workspace()
    # SHA-256 of the file it was loaded from (recorded in run folders); not a file key.
    _sha256: str = PrivateAttr("")
    _file: str = PrivateAttr("")

    @property
    def sha256(self) -> str:
        return self._sha256

    @property
    def source_file(self) -> str:
        """The file it was loaded from, as messages name it ("" if built in code)."""
        return self._file

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

    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    def index(self, name: str) -> int:
        return self.joint_names.index(name)


#: Arm file used when a sequence names none (relative to the project root / cwd).
DEFAULT_ARM = Path("arms/lwa3.yaml")


def load_arm(path: str | Path) -> ArmDescription:
    """Load and validate an arm file; raises :class:`seqrun.errors.SequenceInvalid`
    with ``file:line:col`` errors."""
    from seqrun.yamlsource import load_document  # local import: a sibling layer

    document = load_document(Path(path))
    arm = document.validate(ArmDescription)
    arm._sha256, arm._file = document.sha256, document.file
    return arm
