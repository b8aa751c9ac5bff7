"""The sequence file format: pydantic models (the single source of truth) and the loader.

A sequence file is a mapping with ``name``, ``description``, an optional ``arm`` and
``steps``, a list whose items each name their step type by their single key::

    # yaml-language-server: $schema=../docs/schema/sequence.schema.json
    name: Op-safe
    description: From a freshly powered-on arm in Park to the Op-safe pre-grasp pose.
    steps:
      - include: startup.yaml              # reset, home, set_limits
      - move: totem                        # shorthand for {pose: totem}
      - move: {pose: opsafe, velocity_scale: 0.5, label: Pre-grasp}
      - wait: 2                            # shorthand for {seconds: 2}
      - checkpoint:
          position_mm: [-136.305, 510.761, 389.804]
          rpy_deg: [-22.318, -27.505, 124.351]
          position_tolerance_mm: 2
          angle_tolerance_deg: 1

Shorthand forms (each is in the JSON Schema exactly as accepted here):

- ``- reset``, ``- home``, ``- halt``, ``- set_limits``: the step with its defaults;
- ``reset``/``home``/``halt``: ``all`` or a list of joint names (``- halt: [j1, j2]``);
- ``- move: totem`` / ``- checkpoint: opsafe``: a pose name;
- ``- wait: 2``: seconds; ``- confirm: Is the desk clear?``: the prompt;
- ``- include: startup.yaml``: the file.

The models only check what a file says on its own (types, ranges, which keys go together);
what depends on the arm (joint names, limits, velocities, the start-up order) is
:mod:`seqrun.validation`. :func:`load_sequence` reads a file with its includes into a flat
list of :class:`ResolvedStep`, each knowing its own ``file:line:col``.
"""

from __future__ import annotations

import inspect
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, Union

from pydantic import (
    AfterValidator,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    TypeAdapter,
    ValidationError,
    model_validator,
)
from pydantic_core import PydanticCustomError

from seqrun.errors import SequenceInvalid, SourceError, UserInputError
from seqrun.yamlsource import (
    Document,
    FriendlyModel,
    Location,
    display_path,
    load_document,
    sort_errors,
)

__all__ = [
    "BARE_STEPS",
    "DEFAULT_ARM",
    "FrozenPose",
    "MAX_INCLUDE_DEPTH",
    "MAX_STEPS",
    "PARAMS_MODELS",
    "STEP_KINDS",
    "CheckpointParams",
    "ConfirmParams",
    "HaltParams",
    "HomeParams",
    "IncludeParams",
    "LoadedSequence",
    "MoveLinearParams",
    "MoveParams",
    "PowerOffParams",
    "ResetParams",
    "ResolvedStep",
    "Sequence",
    "SetLimitsParams",
    "StepParams",
    "WaitParams",
    "find_project_root",
    "load_sequence",
    "load_sequence_partial",
    "sequence_json_schema",
]

#: Arm file of a sequence that names none, relative to the project root.
DEFAULT_ARM = "arms/lwa3.yaml"
#: Deepest chain of includes (a includes b includes c ...).
MAX_INCLUDE_DEPTH = 16
#: Most steps a sequence may expand to with its includes.
MAX_STEPS = 10_000

# --------------------------------------------------------------------------- value types
Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
# At least 1 %: below that a move takes hours and the planner's numbers degenerate.
Scale = Annotated[float, Field(ge=0.01, le=1, allow_inf_nan=False)]

_POSE_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]*$")


def _pose_name(value: str) -> str:
    if not _POSE_NAME_RE.match(value):
        raise PydanticCustomError(
            "pose_name", "'{value}' is not a pose name (the name of a file in poses/ without "
                         ".yaml: letters, digits, _ and -)", {"value": value})
    return value


_YAML_FILE_RE = re.compile(r"\.ya?ml$")


def _yaml_file(value: str) -> str:
    if not _YAML_FILE_RE.search(value):
        raise PydanticCustomError("include_file", "an include names a sequence file ending in "
                                                  ".yaml, got '{value}'", {"value": value})
    return value


IncludeFile = Annotated[str, Field(min_length=1), AfterValidator(_yaml_file), Field(
    json_schema_extra={"pattern": _YAML_FILE_RE.pattern},
    description="Path of the sequence to include, relative to this file; it must stay "
                "inside the sequences folder.")]
JointName = Annotated[str, Field(min_length=1, description="A joint name of the arm file, "
                                                           "e.g. j1.")]
PoseName = Annotated[str, AfterValidator(_pose_name), Field(
    json_schema_extra={"pattern": _POSE_NAME_RE.pattern},
    description="Name of a pose file in the project's poses/ folder, without .yaml "
                "(e.g. totem, park, opsafe).")]
Vector3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
LimitPair = Annotated[list[Finite], Field(min_length=2, max_length=2,
                                          description="[min, max] in degrees.")]


def _doc(model: type) -> str:
    """A model's docstring as one line (for field descriptions)."""
    return " ".join(inspect.cleandoc(model.__doc__ or "").split())


def _either(pick, **choices: Any) -> Any:
    """A union whose branch is chosen by ``pick(value)`` (a tag in ``choices``), so that a
    wrong value gets the errors of one branch only. Tags contain ':' so they never look
    like YAML keys when errors are located."""
    members = tuple(Annotated[tp, Tag(tag)] for tag, tp in choices.items())
    return Annotated[Union[members], Discriminator(pick)]  # type: ignore[valid-type]  # noqa: UP007


def _joints_pick(value: Any) -> str:
    return "joints:all" if isinstance(value, str) else "joints:list"


def _all_only(value: str) -> str:
    if value != "all":
        raise PydanticCustomError("all_or_joints", "expected 'all' or a list of joint names, "
                                                   "got '{value}'", {"value": value})
    return value


AllWord = Annotated[str, AfterValidator(_all_only), Field(json_schema_extra={"const": "all"})]
AllOrJoints = _either(_joints_pick, **{"joints:all": AllWord,
                                       "joints:list": Annotated[list[JointName],
                                                                Field(min_length=1)]})


# --------------------------------------------------------------------------- models
class _Model(FriendlyModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class StepParams(_Model):
    """Parameters every step has."""

    kind: ClassVar[str] = ""
    label: str | None = Field(
        None, min_length=1,
        description="Text shown to the operator for this step (default: a description "
                    "generated from the step).")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        """The full parameters of a shorthand value (overridden where there is one)."""
        return value if isinstance(value, cls) else cls()


class _ModulesParams(StepParams):
    joints: AllOrJoints = Field(  # type: ignore[valid-type]
        "all", description="'all' (one broadcast to every module) or a list of joint names "
                           "(one command per module).")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        if isinstance(value, cls):
            return value
        return cls() if value is None else cls(joints=value)


class ResetParams(_ModulesParams):
    """Reset: clears the modules' error state (and a Halt). Parameters can be written after it;
    the first step of every start-up."""

    kind: ClassVar[str] = "reset"
    yaml_name: ClassVar[str] = "reset"


class HomeParams(_ModulesParams):
    """Home: enables the motors (audible click) without moving. The modules refuse motion
    until Home; it needs Reset first."""

    kind: ClassVar[str] = "home"
    yaml_name: ClassVar[str] = "home"


class HaltParams(_ModulesParams):
    """Halt: stops at once; the modules then refuse motion until Reset."""

    kind: ClassVar[str] = "halt"
    yaml_name: ClassVar[str] = "halt"


class SetLimitsParams(StepParams):
    """Write the position limits (MinPos/MaxPos) into every joint's module, and the velocity
    and acceleration limits (MaxVel/MaxAcc) of the joints named here. Values default to the
    arm file's; overrides may only narrow them."""

    kind: ClassVar[str] = "set_limits"
    yaml_name: ClassVar[str] = "set_limits"
    limits_deg: dict[JointName, LimitPair] = Field(
        default_factory=dict,
        description="Per-joint [min, max] in user degrees, e.g. {j1: [-170, 170]}; inside the "
                    "arm file's limits. Joints not named get the arm file's limits.")
    max_velocity_deg_s: dict[JointName, Positive] = Field(
        default_factory=dict,
        description="Per-joint MaxVel in deg/s, at most the arm file's maximum; written only "
                    "for the joints named.")
    max_acceleration_deg_s2: dict[JointName, Positive] = Field(
        default_factory=dict,
        description="Per-joint MaxAcc in deg/s^2, at most the arm file's maximum; written "
                    "only for the joints named.")

    @model_validator(mode="after")
    def _ordered(self) -> SetLimitsParams:
        bad = [f"{name}: min {lo:g} is not below max {hi:g}"
               for name, (lo, hi) in self.limits_deg.items() if not lo < hi]
        if bad:
            raise ValueError("limits_deg " + "; ".join(bad))
        return self

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls()


def _exactly_one(*alternatives: str) -> dict:
    return {"oneOf": [{"required": [name]} for name in alternatives]}


def _check_pose_target(params: Any, what: str) -> None:
    """End-effector targets: position_mm alone with the pose keys (rpy_deg, frame, tool)."""
    cartesian = [k for k in ("rpy_deg", "tool") if getattr(params, k) is not None]
    if params.frame != "base":
        cartesian.append("frame")
    if params.position_mm is None:
        if cartesian:
            raise PydanticCustomError("move_target", "{keys} belong to an end-effector target: "
                                      "give position_mm too", {"keys": ", ".join(cartesian)})
        return
    others = [k for k in ("pose", "joints") if getattr(params, k, None) is not None]
    if others:
        raise PydanticCustomError("move_target", "{what} takes either position_mm or {others}, "
                                  "not both", {"what": what, "others": " or ".join(others)})
    if not params.relative and params.rpy_deg is None:
        raise PydanticCustomError("move_target", "an absolute end-effector target needs rpy_deg "
                                                 "with position_mm")
    if not params.relative and params.frame != "base":
        raise PydanticCustomError("move_target", "frame: tool is for relative targets "
                                                 "(relative: true)")


class MoveParams(StepParams):
    """Move the arm to a pose or to joint angles: one synchronized, jerk-limited motion in
    which all commanded joints arrive together. Joints not named do not move."""

    kind: ClassVar[str] = "move"
    yaml_name: ClassVar[str] = "move"
    model_config = ConfigDict(json_schema_extra=_exactly_one("pose", "joints", "position_mm"))

    pose: PoseName | None = Field(  # type: ignore[valid-type]
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

    @model_validator(mode="after")
    def _target(self) -> MoveParams:
        _check_pose_target(self, "a move")
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


class MoveLinearParams(StepParams):
    """Move the tool in a straight line to an end-effector pose at a given speed (mm/s, and
    deg/s for the rotation), as a densely sampled, jerk-limited joint trajectory. Every
    sample is solved and checked before anything moves (reachable, joint and velocity
    limits, away from singularities, the guards); during the run the tool's distance from
    the line is measured and a fault beyond max_deviation_mm."""

    kind: ClassVar[str] = "move_linear"
    yaml_name: ClassVar[str] = "move_linear"

    position_mm: Vector3 = Field(
        description="Tool position at the end of the line [x, y, z] in mm (base frame); with "
                    "relative: true, the displacement in the base or the tool frame (frame).")
    rpy_deg: Vector3 | None = Field(
        None, description="Tool orientation at the end [roll, pitch, yaw] in degrees; required "
                          "unless relative (then a rotation, default none).")
    relative: bool = Field(False, description="true: position_mm/rpy_deg are offsets from "
                                              "where the tool is.")
    frame: Literal["base", "tool"] = Field(
        "base", description="With relative: the frame of the displacement (tool: [0, 0, 50] is "
                            "50 mm along the tool's z axis).")
    tool: str | None = Field(None, min_length=1, description="The arm file's tool that moves "
                                                             "on the line (default: the arm's "
                                                             "default_tool, else the "
                                                             "end-effector frame).")
    speed_mm_s: Positive = Field(description="Speed along the line, mm/s.")
    rotation_speed_deg_s: Positive = Field(
        10.0, description="Largest turning speed of the tool, deg/s.")
    acceleration_mm_s2: Positive = Field(
        50.0, description="Acceleration along the line, mm/s^2 (the rotation's scales alike).")
    jerk_mm_s3: Positive = Field(500.0, description="Jerk along the line, mm/s^3.")
    max_deviation_mm: Positive = Field(
        1.0, description="Largest distance of the tool from the line during the run, mm; "
                         "beyond it the arm is halted.")
    tolerance_deg: Positive | None = Field(
        None, description="In-position tolerance per joint at the end, degrees (default: the "
                          "arm file's control.position_tolerance_deg).")
    timeout_s: Positive | None = Field(
        None, description="Time allowed for the whole move in seconds (default: the planned "
                          "duration plus the arm file's control.settle_timeout_s).")

    @model_validator(mode="after")
    def _target(self) -> MoveLinearParams:
        _check_pose_target(self, "a linear move")
        return self


class WaitParams(StepParams):
    """Wait a fixed time, or until every joint is in position."""

    kind: ClassVar[str] = "wait"
    yaml_name: ClassVar[str] = "wait"
    model_config = ConfigDict(json_schema_extra=_exactly_one("seconds", "until"))

    seconds: Positive | None = Field(None, description="Time to wait in seconds.")
    until: Literal["in_position"] | None = Field(
        None, description="in_position: wait until every joint is within tolerance_deg of its "
                          "last target.")
    tolerance_deg: Positive | None = Field(
        None, description="For until: in_position; default the arm file's "
                          "control.position_tolerance_deg.")
    timeout_s: Positive | None = Field(
        None, description="For until: in_position; default the arm file's "
                          "control.settle_timeout_s.")

    @model_validator(mode="after")
    def _one(self) -> WaitParams:
        if (self.seconds is None) == (self.until is None):
            raise PydanticCustomError(
                "wait_what", "a wait needs either 'seconds' or 'until'" if self.seconds is None
                else "a wait takes either 'seconds' or 'until', not both")
        if self.seconds is not None and (self.tolerance_deg is not None
                                         or self.timeout_s is not None):
            raise PydanticCustomError("wait_what", "tolerance_deg and timeout_s belong to "
                                                   "'until: in_position', not to 'seconds'")
        return self

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(seconds=value)


class CheckpointParams(StepParams):
    """Check the measured end-effector pose (forward kinematics of the joints) against an
    expected one; the run stops if it is off by more than the tolerances."""

    kind: ClassVar[str] = "checkpoint"
    yaml_name: ClassVar[str] = "checkpoint"
    model_config = ConfigDict(json_schema_extra={"oneOf": [
        {"required": ["pose"]}, {"required": ["position_mm", "rpy_deg"]},
        {"required": ["moved_mm"]}]})

    pose: PoseName | None = Field(  # type: ignore[valid-type]
        None, description="Expect the end-effector pose of this pose file.")
    moved_mm: Vector3 | None = Field(
        None, description="Relative checkpoint: the tool moved by this [x, y, z] in mm during "
                          "the last move before it (from where that move started), in the "
                          "base or the tool frame (frame; tool: the tool's frame where the "
                          "move started), e.g. [0, 0, -300] with frame: tool.")
    frame: Literal["base", "tool"] = Field(
        "base", description="With moved_mm: the frame the displacement is given in.")
    tool: str | None = Field(None, min_length=1, description="With moved_mm: the arm file's "
                                                             "tool (default: the arm's "
                                                             "default_tool, else the "
                                                             "end-effector frame).")
    position_mm: Vector3 | None = Field(
        None, description="Expected end-effector position [x, y, z] in mm (base frame).")
    rpy_deg: Vector3 | None = Field(
        None, description="Expected orientation [roll, pitch, yaw] in degrees, "
                          "R = Rz(yaw) Ry(pitch) Rx(roll).")
    position_tolerance_mm: Positive = Field(
        7.0, description="Largest allowed distance from the expected position, mm. The "
                         "default covers the worst case of a 0.2° in-position error on every "
                         "joint of the LWA 3 at Op-safe (6.2 mm).")
    angle_tolerance_deg: Positive = Field(
        1.5, description="Largest allowed rotation angle between expected and measured "
                         "orientation, degrees (default: covers 0.2° per joint, 1.2°).")

    @model_validator(mode="after")
    def _one(self) -> CheckpointParams:
        if self.moved_mm is not None:
            others = [k for k in ("pose", "position_mm", "rpy_deg") if getattr(self, k) is not None]
            if others:
                raise PydanticCustomError("checkpoint_what", "a relative checkpoint (moved_mm) "
                                          "takes no {others}", {"others": ", ".join(others)})
            return self
        if self.frame != "base" or self.tool is not None:
            raise PydanticCustomError("checkpoint_what", "frame and tool belong to a relative "
                                                         "checkpoint (moved_mm)")
        explicit = self.position_mm is not None or self.rpy_deg is not None
        if self.pose is not None and explicit:
            raise PydanticCustomError("checkpoint_what", "a checkpoint takes either 'pose' or "
                                                         "'position_mm' with 'rpy_deg', not both")
        if self.pose is None and (self.position_mm is None or self.rpy_deg is None):
            missing = "rpy_deg" if self.position_mm is not None else (
                "position_mm" if self.rpy_deg is not None else "")
            raise PydanticCustomError(
                "checkpoint_what", "a checkpoint with position_mm needs rpy_deg too"
                if missing == "rpy_deg" else "a checkpoint with rpy_deg needs position_mm too"
                if missing else "a checkpoint needs either 'pose' or 'position_mm' and 'rpy_deg'")
        return self

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(pose=value)


class ConfirmParams(StepParams):
    """Stop until the operator confirms (or declines, which ends the run)."""

    kind: ClassVar[str] = "confirm"
    yaml_name: ClassVar[str] = "confirm"
    prompt: str = Field(min_length=1, description="The question or instruction shown to the "
                                                  "operator, e.g. 'Is the desk clear?'.")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(prompt=value)


class PowerOffParams(StepParams):
    """End of a shutdown: check the arm stands in a power-off pose of the arm file, then
    record that it is powered off there (its modules take their zero there)."""

    kind: ClassVar[str] = "power_off"
    yaml_name: ClassVar[str] = "power_off"
    pose: PoseName = Field(description="A power-off pose of the arm file (power_off_poses), "
                                       "e.g. totem.")
    tolerance_deg: Positive | None = Field(
        None, description="How far each joint may be from the pose, degrees (default the arm "
                          "file's control.position_tolerance_deg).")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(pose=value)


class IncludeParams(StepParams):
    """Run the steps of another sequence file here."""

    kind: ClassVar[str] = "include"
    yaml_name: ClassVar[str] = "include"
    file: IncludeFile = Field(  # type: ignore[valid-type]
        description="Path of the sequence to include, relative to this file; it must stay "
                    "inside the sequences folder (the project's sequences/, else the folder "
                    "of the file given to seqrun).")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(file=value)


#: Parameter model of each step type, in the order the docs list them.
PARAMS_MODELS: dict[str, type[StepParams]] = {m.kind: m for m in (
    ResetParams, HomeParams, HaltParams, SetLimitsParams, MoveParams, MoveLinearParams,
    WaitParams, CheckpointParams, ConfirmParams, PowerOffParams, IncludeParams)}
STEP_KINDS: tuple[str, ...] = tuple(PARAMS_MODELS)
#: Step types that may be written as a bare word (``- reset``).
BARE_STEPS: tuple[str, ...] = ("reset", "home", "halt", "set_limits")


# -- the one-key step mappings
def _kind_pick(*, none: str | None = None, text: str | None = None, number: str | None = None,
               items: str | None = None, params: str) -> Any:
    """Choose the branch of a step's value: a mapping is the full parameters; anything else
    goes to the shorthand that fits it, else to the first shorthand there is (so that
    ``confirm: 42`` says "expected text", not "expected a mapping")."""
    shorthand = text or number or items

    def pick(value: Any) -> str:
        if isinstance(value, (dict, StepParams)):
            return params
        if value is None and none:
            return none
        if isinstance(value, str) and text:
            return text
        if isinstance(value, (int, float)) and not isinstance(value, bool) and number:
            return number
        if isinstance(value, list) and items:
            return items
        return shorthand or none or params
    return pick


def _modules_spec(model: type[StepParams]) -> Any:
    k = model.kind
    return _either(_kind_pick(none=f"{k}:default", text=f"{k}:all", items=f"{k}:list",
                              params=f"{k}:params"),
                   **{f"{k}:default": None, f"{k}:all": AllWord,
                      f"{k}:list": Annotated[list[JointName], Field(min_length=1)],
                      f"{k}:params": model})


class _Step(_Model):
    """One-key mapping ``{<kind>: <parameters or shorthand>}``."""

    kind: ClassVar[str] = ""

    def params(self) -> StepParams:
        return PARAMS_MODELS[self.kind].from_shorthand(getattr(self, self.kind))


class ResetStep(_Step):
    """A reset step."""

    kind: ClassVar[str] = "reset"
    reset: _modules_spec(ResetParams) = Field(  # type: ignore[valid-type]
        description=_doc(ResetParams) + " Shorthand: '- reset', 'reset: all', "
                                          "'reset: [j1, j2]'.")


class HomeStep(_Step):
    """A home step."""

    kind: ClassVar[str] = "home"
    home: _modules_spec(HomeParams) = Field(  # type: ignore[valid-type]
        description=_doc(HomeParams) + " Shorthand: '- home', 'home: all', "
                                         "'home: [j1, j2]'.")


class HaltStep(_Step):
    """A halt step."""

    kind: ClassVar[str] = "halt"
    halt: _modules_spec(HaltParams) = Field(  # type: ignore[valid-type]
        description=_doc(HaltParams) + " Shorthand: '- halt', 'halt: all', "
                                         "'halt: [j1, j2]'.")


class SetLimitsStep(_Step):
    """A set_limits step."""

    kind: ClassVar[str] = "set_limits"
    set_limits: _either(_kind_pick(none="set_limits:default", params="set_limits:params"),
                        **{"set_limits:default": None,
                           "set_limits:params": SetLimitsParams}) = Field(
        description=_doc(SetLimitsParams) + " Shorthand: '- set_limits' (the arm file's "
                                              "values).")


class MoveStep(_Step):
    """A move step."""

    kind: ClassVar[str] = "move"
    move: _either(_kind_pick(text="move:pose", params="move:params"),
                  **{"move:pose": PoseName, "move:params": MoveParams}) = Field(
        description=_doc(MoveParams) + " Shorthand: 'move: totem' (a pose name).")


class MoveLinearStep(_Step):
    """A move_linear step."""

    kind: ClassVar[str] = "move_linear"
    move_linear: MoveLinearParams = Field(description=_doc(MoveLinearParams))


class WaitStep(_Step):
    """A wait step."""

    kind: ClassVar[str] = "wait"
    wait: _either(_kind_pick(number="wait:seconds", params="wait:params"),
                  **{"wait:seconds": Positive, "wait:params": WaitParams}) = Field(
        description=_doc(WaitParams) + " Shorthand: 'wait: 2' (seconds).")


class CheckpointStep(_Step):
    """A checkpoint step."""

    kind: ClassVar[str] = "checkpoint"
    checkpoint: _either(_kind_pick(text="checkpoint:pose", params="checkpoint:params"),
                        **{"checkpoint:pose": PoseName,
                           "checkpoint:params": CheckpointParams}) = Field(
        description=_doc(CheckpointParams) + " Shorthand: 'checkpoint: opsafe' (a pose).")


class ConfirmStep(_Step):
    """A confirm step."""

    kind: ClassVar[str] = "confirm"
    confirm: _either(_kind_pick(text="confirm:prompt", params="confirm:params"),
                     **{"confirm:prompt": Annotated[str, Field(min_length=1)],
                        "confirm:params": ConfirmParams}) = Field(
        description=_doc(ConfirmParams) + " Shorthand: 'confirm: Is the desk clear?'.")


class PowerOffStep(_Step):
    """A power_off step."""

    kind: ClassVar[str] = "power_off"
    power_off: _either(_kind_pick(text="power_off:pose", params="power_off:params"),
                       **{"power_off:pose": PoseName,
                          "power_off:params": PowerOffParams}) = Field(
        description=_doc(PowerOffParams) + " Shorthand: 'power_off: totem'.")


class IncludeStep(_Step):
    """An include step."""

    kind: ClassVar[str] = "include"
    include: _either(_kind_pick(text="include:file", params="include:params"),
                     **{"include:file": IncludeFile,
                        "include:params": IncludeParams}) = Field(
        description=_doc(IncludeParams) + " Shorthand: 'include: startup.yaml'.")


_STEP_MODELS: dict[str, type[_Step]] = {m.kind: m for m in (
    ResetStep, HomeStep, HaltStep, SetLimitsStep, MoveStep, MoveLinearStep, WaitStep,
    CheckpointStep, ConfirmStep, PowerOffStep, IncludeStep)}
assert tuple(_STEP_MODELS) == STEP_KINDS, "one step model per parameter model"

BareStep = Annotated[Literal[BARE_STEPS], Field(  # type: ignore[valid-type]
    description="A step with its default parameters: reset, home, halt or set_limits.")]


def _closest(word: str, options: tuple[str, ...]) -> str:
    import difflib

    close = difflib.get_close_matches(word, options, n=1, cutoff=0.6)
    return f"did you mean '{close[0]}'? " if close else ""


def _check_step(value: Any) -> Any:
    """Explain a step that is not a one-key mapping of a known type (before the union)."""
    kinds = ", ".join(STEP_KINDS)
    if isinstance(value, str):
        if value in BARE_STEPS:
            return value
        if value in STEP_KINDS:
            raise PydanticCustomError(
                "step_needs_params", "step '{kind}' needs parameters, e.g. '- {example}'",
                {"kind": value, "example": _EXAMPLES[value]})
        raise PydanticCustomError(
            "unknown_step", "unknown step type '{kind}' ({hint}expected one of: {kinds})",
            {"kind": value, "hint": _closest(value, STEP_KINDS), "kinds": kinds})
    if not isinstance(value, dict):
        raise PydanticCustomError(
            "step_shape", "a step is a mapping with one key naming its type, e.g. "
                          "'- move: totem' (expected one of: {kinds})", {"kinds": kinds})
    if len(value) != 1:
        keys = ", ".join(str(k) for k in value)
        hint = ""
        if "label" in value:
            hint = "; put label inside the step, e.g. '- move: {pose: totem, label: Up}'"
        raise PydanticCustomError(
            "step_shape", "a step has exactly one key, its type; this one has {n}: {keys}{hint}",
            {"n": len(value), "keys": keys or "none", "hint": hint})
    kind = next(iter(value))
    if kind not in STEP_KINDS:
        kind_text = str(kind)
        raise PydanticCustomError(
            "unknown_step", "unknown step type '{kind}' ({hint}expected one of: {kinds})",
            {"kind": kind_text, "hint": _closest(kind_text, STEP_KINDS), "kinds": kinds})
    return value


_EXAMPLES = {"move": "move: totem",
             "move_linear": "move_linear: {position_mm: [0, 0, 50], relative: true, "
                            "frame: tool, speed_mm_s: 10}",
             "wait": "wait: 2", "checkpoint": "checkpoint: opsafe",
             "confirm": "confirm: Is the desk clear?", "include": "include: startup.yaml",
             "power_off": "power_off: totem"}


def _step_pick(value: Any) -> str | None:
    if isinstance(value, str):
        return "step:bare"
    if isinstance(value, dict) and len(value) == 1:
        return f"step:{next(iter(value))}"
    if isinstance(value, _Step):
        return f"step:{value.kind}"
    return None


Step = Annotated[
    Union[(Annotated[BareStep, Tag("step:bare")],  # type: ignore[valid-type]
           *(Annotated[m, Tag(f"step:{k}")] for k, m in _STEP_MODELS.items()))],
    Discriminator(_step_pick),
    BeforeValidator(_check_step),
    Field(description="One step: a mapping with one key naming the step type "
                      f"({', '.join(STEP_KINDS)}), or a bare {', '.join(BARE_STEPS)}."),
]


class Sequence(_Model):
    """A seqrun sequence file: what the arm does, step by step."""

    yaml_name: ClassVar[str] = "the sequence"
    model_config = ConfigDict(title="seqrun sequence")

    name: str = Field(min_length=1, description="Short name of the sequence, shown to the "
                                                "operator and in run reports.")
    description: str = Field(description="What the sequence does and when to use it.")
    arm: str | None = Field(
        None, min_length=1,
        description=f"Arm file, relative to the project root (default: the campaign's arm, "
                    f"else {DEFAULT_ARM}), or the name of an arm (lwa3: the campaign's "
                    "arms/lwa3.yaml, else the shipped one). An included sequence must name "
                    "the same arm or none.")
    steps: list[Step] = Field(min_length=1, description="The steps, in order.")


_STEP_ADAPTER: TypeAdapter[Any] = TypeAdapter(Step)


def sequence_json_schema() -> dict:
    """JSON Schema (2020-12) of sequence files, for editors (yaml-language-server)."""
    schema = Sequence.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": "https://seqrun.local/schema/sequence.schema.json", **schema}


# --------------------------------------------------------------------------- loading
@dataclass(frozen=True, eq=False)
class ResolvedStep:
    """One step of the flattened sequence (includes expanded).

    ``number`` is 1-based in the flat list; ``location`` is where the step is written;
    ``include_chain`` the include steps that led to it, outermost first.
    """

    number: int
    kind: str
    params: StepParams
    location: Location
    label: str | None = None
    include_chain: tuple[Location, ...] = ()
    document: Document | None = field(default=None, repr=False)
    node: Any = field(default=None, repr=False)  # the parameters' YAML node
    #: What the operator sees of each include in ``include_chain`` (its label, else
    #: "include FILE"), outermost first.
    include_labels: tuple[str, ...] = ()

    def where(self, *path: Any, key: bool = False) -> Location:
        """Location of a parameter, e.g. ``where("joints", "j4")``; without a path, the step's
        own location. Where the path is not written out (shorthand), the nearest enclosing
        value."""
        if not path or self.document is None or self.node is None:
            return self.location
        return self.document.locate(path, start=self.node, key=key)

    def error(self, message: str, *path: Any, key: bool = False) -> SourceError:
        return self.where(*path, key=key).error(message)

    @property
    def title(self) -> str:
        """What the operator sees: the label, or a short description of the step."""
        return self.label or describe(self.kind, self.params)


def describe(kind: str, params: StepParams) -> str:
    """A one-line description of a step for people, e.g. ``move to pose totem``."""
    if isinstance(params, (ResetParams, HomeParams, HaltParams)):
        who = "all modules" if params.joints == "all" else ", ".join(params.joints)
        return f"{kind} {who}"
    if isinstance(params, (MoveParams, MoveLinearParams)) and params.position_mm is not None:
        verb = "move in a line" if isinstance(params, MoveLinearParams) else "move the tool"
        xyz = ", ".join(f"{v:g}" for v in params.position_mm)
        if params.relative:
            return f"{verb} by [{xyz}] mm ({params.frame} frame)"
        return f"{verb} to [{xyz}] mm"
    if isinstance(params, MoveParams):
        if params.pose is not None:
            return f"move to pose {params.pose}"
        sign = "by" if params.relative else "to"
        return "move " + ", ".join(f"{j} {sign} {v:g}°" for j, v in (params.joints or {}).items())
    if isinstance(params, WaitParams):
        return (f"wait {params.seconds:g} s" if params.seconds is not None
                else "wait until in position")
    if isinstance(params, CheckpointParams) and params.moved_mm is not None:
        xyz = ", ".join(f"{v:g}" for v in params.moved_mm)
        return f"checkpoint: the tool moved [{xyz}] mm ({params.frame} frame)"
    if isinstance(params, CheckpointParams):
        return (f"checkpoint: pose {params.pose}" if params.pose is not None
                else "checkpoint: end-effector pose")
    if isinstance(params, ConfirmParams):
        return f"confirm: {params.prompt}"
    if isinstance(params, SetLimitsParams):
        return "write joint limits"
    if isinstance(params, IncludeParams):
        return f"include {params.file}"
    if isinstance(params, PowerOffParams):
        return f"power off in {params.pose}"
    return kind


@dataclass(frozen=True, eq=False)
class LoadedSequence:
    """A sequence file with its includes expanded into :attr:`steps`."""

    path: Path
    file: str
    name: str
    description: str
    project_root: Path
    poses_dir: Path
    arm_path: Path
    steps: tuple[ResolvedStep, ...]
    files: tuple[Path, ...] = ()  # every file read, the top one first
    #: Where poses are looked up, first match wins (the campaign's, then the shipped).
    pose_path: tuple[Path, ...] = ()
    #: The campaign or project the sequence belongs to (seqrun.project.Project).
    project: Any = None
    #: Every pose the steps name, read once at load time: the run uses these, never the
    #: files again (a pose file edited during a run changes nothing).
    poses: Mapping[str, FrozenPose] = field(default_factory=dict)
    #: SHA-256 of every sequence file read (same order as ``files``).
    digests: tuple[str, ...] = ()

    @property
    def location(self) -> Location:
        return Location(self.file, 1, 1)

    def inputs(self) -> list[dict[str, str]]:
        """The files this sequence was validated from: ``{kind, file, sha256}`` each, for the
        run folder (the arm file is added by whoever loaded the arm)."""
        items = [{"kind": "sequence", "file": display_path(p), "sha256": d}
                 for p, d in zip(self.files, self.digests)]
        items += [{"kind": "pose", "file": pose.document.file, "sha256": pose.document.sha256}
                  for pose in self.poses.values()]
        return items


@dataclass(frozen=True, eq=False)
class FrozenPose:
    """A pose file as it was read and validated (see :attr:`LoadedSequence.poses`)."""

    name: str
    pose: Any  # seqrun.poses.PoseFile
    document: Document = field(repr=False)

    @property
    def joints_deg(self) -> dict[str, float]:
        return dict(self.pose.joints_deg)


def find_project_root(path: str | os.PathLike[str]) -> Path:
    """Nearest ancestor of ``path`` holding an ``arms/`` or ``poses/`` folder; else the cwd."""
    start = Path(path).resolve()
    for folder in (start if start.is_dir() else start.parent, *start.parents):
        if (folder / "arms").is_dir() or (folder / "poses").is_dir():
            return folder
    return Path.cwd().resolve()


class _Loader:
    def __init__(self, top: Path, project: Any) -> None:
        self.project = project  # seqrun.project.Project: lookups of poses, arm, includes
        self.root = project.root
        self.poses_dir = project.poses_dir
        self.pose_path = project.pose_path
        self.tree = project.include_tree(top)
        self.errors: list[SourceError] = []
        self.steps: list[ResolvedStep] = []
        self.files: list[Path] = []
        self.arm_path: Path | None = None
        self.pose_problems: dict[str, str | None] = {}
        self.poses: dict[str, FrozenPose] = {}
        self.digests: list[str] = []
        self.include_titles: dict[Location, str] = {}
        self.top: Any = None  # the top file's data, when it could be read

    def load(self, path: Path, *, chain: tuple[Path, ...] = (),
             include_chain: tuple[Location, ...] = (), include_step: Any = None) -> Any:
        try:
            doc = load_document(path, file=display_path(path))
        except SequenceInvalid as exc:
            self.errors.extend(exc.errors)
            return None
        except UserInputError as exc:
            if include_step is None:
                raise  # the file named on the command line
            self.errors.append(include_step.error(str(exc)))
            return None
        self.files.append(path)
        self.digests.append(doc.sha256)
        if not chain:
            self.top = doc.data
        try:
            seq = doc.validate(Sequence)
        except SequenceInvalid as exc:
            # Report every problem at once: go on with the steps that are valid on their own
            # (their includes and poses are checked too); the file's errors are known.
            self.errors.extend(exc.errors)
            self._partial(doc, path, chain, include_chain)
            return None
        self._check_arm(doc, seq, top=not chain)
        self._steps(doc, path, seq.steps, doc.items(doc.child(doc.root, "steps")), chain,
                    include_chain)
        return seq

    def _partial(self, doc: Document, path: Path, chain: tuple[Path, ...],
                 include_chain: tuple[Location, ...]) -> None:
        if not chain:
            self.arm_path = self._arm(None)
        data = doc.data.get("steps") if isinstance(doc.data, dict) else None
        if not isinstance(data, list):
            return
        good, nodes = [], []
        for item, node in zip(data, doc.items(doc.child(doc.root, "steps"))):
            try:
                good.append(_STEP_ADAPTER.validate_python(item))
                nodes.append(node)
            except ValidationError:
                continue  # already reported by the whole-file validation
        self._steps(doc, path, good, nodes, chain, include_chain)

    def _steps(self, doc: Document, path: Path, steps: list, items: list,
               chain: tuple[Path, ...], include_chain: tuple[Location, ...]) -> None:
        for raw, node in zip(steps, items):
            if len(self.steps) >= MAX_STEPS:
                self.errors.append(doc.location(node).error(
                    f"the sequence expands to more than {MAX_STEPS} steps with its includes"))
                return
            if isinstance(raw, str):
                kind, params, params_node = raw, PARAMS_MODELS[raw](), node
            else:
                kind = raw.kind
                params, params_node = raw.params(), doc.child(node, kind)
            here = doc.location(node)
            if isinstance(params, IncludeParams):
                self.include_titles[here] = params.label or describe(kind, params)
                self._include(doc, path, params, params_node, here, chain + (path,),
                              include_chain)
                continue
            step = ResolvedStep(number=len(self.steps) + 1, kind=kind, params=params,
                                location=here, label=params.label, include_chain=include_chain,
                                document=doc, node=params_node,
                                include_labels=tuple(self.include_titles.get(loc, "include")
                                                     for loc in include_chain))
            if isinstance(params, (MoveParams, CheckpointParams)) and params.pose is not None:
                self._check_pose(step, params.pose)
            self.steps.append(step)

    def _check_arm(self, doc: Document, seq: Sequence, *, top: bool) -> None:
        if top:
            if seq.arm is None:  # the campaign's arm: not found is bad input, one line
                self.arm_path = self.project.arm_path(None)
                return
            try:
                self.arm_path = self.project.arm_path(seq.arm)
            except UserInputError:
                self.arm_path = self._arm(None)
                looked = ", ".join(str(p) for p in self.project.arm_candidates(seq.arm))
                self.errors.append(doc.error(("arm",), f"arm file '{seq.arm}' not found "
                                                      f"(looked for {looked})"))
            return
        if seq.arm is not None and self._arm(seq.arm) != self.arm_path:
            self.errors.append(doc.error(("arm",), f"this file names arm '{seq.arm}' but the "
                                                  "sequence including it runs on "
                                                  f"{self.arm_path}; remove 'arm' here or "
                                                  "make it the same"))

    def _arm(self, name: str | None) -> Path:
        """The arm file ``name`` means (the first candidate when none exists: the run
        then says it is missing)."""
        try:
            return self.project.arm_path(name)
        except UserInputError:
            return self.project.arm_candidates(name)[0].resolve()

    def _include(self, doc: Document, path: Path, params: IncludeParams, node: Any,
                 here: Location, chain: tuple[Path, ...],
                 include_chain: tuple[Location, ...]) -> None:
        def error(message: str) -> None:
            self.errors.append(doc.error(("file",), message, start=node))

        try:
            target = (path.parent / params.file).resolve()
        except (OSError, RuntimeError, ValueError) as exc:  # symlink loop, NUL byte, ...
            shown = params.file if params.file.isprintable() else ascii(params.file)[1:-1]
            error(f"include '{shown}': cannot resolve the path ({exc})")
            return
        if not target.is_relative_to(self.tree):
            what = "campaign folder" if self.project.is_campaign else "sequences folder"
            error(f"include '{params.file}' is outside the {what} "
                  f"{display_path(self.tree)}; included files must stay inside it")
            return
        if target in chain:
            names = " -> ".join(p.name for p in (*chain[chain.index(target):], target))
            error(f"include loop: {names}")
            return
        if len(chain) >= MAX_INCLUDE_DEPTH:
            error(f"includes nested more than {MAX_INCLUDE_DEPTH} deep")
            return
        try:
            is_file = target.is_file()
        except OSError as exc:  # name too long, permission denied, ...
            error(f"include '{params.file}': cannot use the path ({exc.strerror or exc})")
            return
        if not is_file:
            error(f"include '{params.file}': no such file ({target})")
            return
        self.load(target, chain=chain, include_chain=include_chain + (here,),
                  include_step=doc.locate(("file",), start=node))

    def _check_pose(self, step: ResolvedStep, name: str) -> None:
        from seqrun.poses import PoseFile, find_pose

        if name not in self.pose_problems:
            problem = None
            try:
                document = load_document(find_pose(name, self.pose_path))
                self.poses[name] = FrozenPose(name, document.validate(PoseFile), document)
            except UserInputError as exc:
                problem = str(exc)
            except SequenceInvalid as exc:
                self.errors.extend(exc.errors)
                problem = f"pose '{name}' cannot be used: its file has errors"
            self.pose_problems[name] = problem
        if self.pose_problems[name] is not None:
            self.errors.append(step.error(self.pose_problems[name], "pose"))


def load_sequence(path: str | os.PathLike[str], *,
                  project_root: str | os.PathLike[str] | None = None) -> LoadedSequence:
    """Read a sequence file with its includes; every step keeps its own ``file:line:col``.

    Poses come from ``<project root>/poses/``, then the shipped poses; the project is the
    nearest campaign (``seqrun.toml``) above the file, or ``project_root`` (``--project``),
    else the nearest folder with ``arms/`` or ``poses/`` (see :mod:`seqrun.project`); an
    unknown pose is a located error listing the available ones. Raises
    :class:`SequenceInvalid` with every error found, :class:`UserInputError` if the file
    cannot be read.
    """
    loaded, errors = load_sequence_partial(path, project_root=project_root)
    if errors:
        raise SequenceInvalid(errors)
    assert loaded is not None
    return loaded


def load_sequence_partial(path: str | os.PathLike[str], *,
                          project_root: str | os.PathLike[str] | None = None
                          ) -> tuple[LoadedSequence | None, list[SourceError]]:
    """:func:`load_sequence` that keeps going: ``(loaded, errors)``, where ``loaded`` holds
    the steps that are valid on their own (a step that fails its schema is left out) so
    that the checks against the arm can still report on them; None if nothing of the top
    file could be read. Raises :class:`UserInputError` if the file cannot be read."""
    from seqrun.project import project_for

    path = Path(path)
    try:
        top = path.resolve()
        project = project_for(top, Path(project_root) if project_root is not None else None)
    except (OSError, RuntimeError, ValueError) as exc:  # symlink loop, NUL byte, ...
        raise UserInputError(f"{path}: cannot resolve the path ({exc})") from None
    root = project.root
    loader = _Loader(top, project)
    seq = loader.load(top)
    errors = sort_errors(loader.errors)
    if seq is not None:
        name, description = seq.name, seq.description
    elif isinstance(loader.top, dict):
        name = loader.top.get("name") if isinstance(loader.top.get("name"), str) else top.stem
        description = loader.top.get("description")
        description = description if isinstance(description, str) else ""
    else:
        return None, errors
    assert loader.arm_path is not None
    return LoadedSequence(path=path, file=display_path(path), name=name or top.stem,
                          description=description, project_root=root,
                          poses_dir=loader.poses_dir, arm_path=loader.arm_path,
                          steps=tuple(loader.steps), files=tuple(loader.files),
                          pose_path=tuple(loader.pose_path), project=project,
                          poses=dict(loader.poses), digests=tuple(loader.digests)), errors


# --------------------------------------------------------------------------- reference docs
_REFERENCE_INTRO = """\
# Sequence files

<!-- Generated from the models in seqrun/schema.py by `seqrun schema --markdown`;
     do not edit by hand (tests/test_schema.py checks it is up to date). -->

A sequence file says what the arm does, step by step. Editors with yaml-language-server
check it as you type when its first line names the schema:

```yaml
# yaml-language-server: $schema=../docs/schema/sequence.schema.json
name: Op-safe
description: From a freshly powered-on arm in Park to the Op-safe pre-grasp pose.
steps:
  - include: startup.yaml                 # reset, home, set_limits
  - confirm: Is the space around the arm clear?
  - move: {pose: totem, velocity_scale: 0.5, label: Up to Totem}
  - move: {pose: opsafe, velocity_scale: 0.5}
  - wait: {until: in_position}
  - checkpoint: {pose: opsafe}
```

`seqrun validate FILE` checks a file and its includes without moving anything:
`file:line:col: message` for each problem, exit 0 (valid), 1 (invalid) or 2 (unusable input).

## The file

| key | | |
|---|---|---|
{top}

Each step is a mapping with one key, the step type; its value holds the step's parameters.
Every step takes an optional `label`, the text the operator sees.

## YAML as seqrun reads it

- YAML 1.2 values: only `true`/`false` are booleans (`yes`, `no`, `on`, `off` stay words, and
  where `true`/`false` is expected they are an error); `010` is ten; `1:30` is text, not 90.
- `.nan`, `.inf` are refused wherever a number is expected.
- A key given twice is an error (plain YAML silently keeps the last one).
- No tags (`!!python/...`, `!custom`, ...), no merge keys (`<<`), one document per file;
  anchors and aliases are fine within limits.

## Rules checked against the arm

- Start-up order: `reset` before `home` and before `set_limits`; `home` and `set_limits`
  before the first `move`; `reset` again after a `halt`.
- Joints must exist; the locked joint (j3) is never commanded.
- Every commanded target lies inside the joint limits in force. A joint that starts outside
  them (Park's j4 at -120.32° against -120…120) may only move back inside (a note).
- Velocities and limit overrides stay within the arm file's maxima.
- Every move is planned within the limits in force: the arm file's, those a `set_limits`
  wrote, and the MaxVel/MaxAcc the modules still hold from before (read back before the
  first motion; they stay stored in a module until written again or powered off). The
  dry-run table and the run report say which limit applied and where it came from.
- A move's `timeout_s` may not be shorter than the move as planned.
- Waits (`seconds`, `timeout_s`) and move timeouts stay within the arm file's
  `control.max_wait_s`; a dry run stops after `control.max_dry_run_s` of simulated time.
- Workspace guards of the arm file hold along each move's planned trajectory (the ruckig plan
  the run streams, sampled at 100 Hz); `seqrun validate` reports the smallest clearance of each move.
- The arm file's link volumes (capsules) keep `geometry.margin_mm` from its obstacles and
  from each other along each move, and the closest pair of each move is reported.
- End-effector targets (`move` with `position_mm`, `move_linear`) are solved by inverse
  kinematics from the joints tracked so far (the solution nearest them); an unreachable
  target is an error at its `position_mm`. The run solves again from the measured joints
  and stops (Halt) if that solution is more than `cartesian.ik_agreement_deg` from the
  validated one. A straight line is sampled every `cartesian.linear_sample_s` and every
  sample must be reachable, inside the limits in force, within the joint velocity limits
  and away from singular configurations (`cartesian.min_manipulability`); during the run
  the tool further than `max_deviation_mm` from the line is a fault.
- A checkpoint must agree with the end-effector of the joints tracked so far; a relative
  one (`moved_mm`) with how far the tool moved during the last move. A checkpoint or a
  wait after a `halt` (and no `reset`) can never pass and is an error.
- Every pose a step names is checked against the arm at the pose file's own lines: it lists
  every joint (the locked one at its locked value), its `end_effector` agrees with forward
  kinematics of its joints, and a pose used as a move target lies inside the joint limits.
- Every problem is reported in one pass: a step that is wrong on its own is left out and
  the others are still checked against the arm.
- A run uses exactly what was validated: the sequence, its includes, the poses and the arm
  file are read once; their SHA-256 is in the run report (`inputs`).
- Validation starts from Park (`--start POSE` to choose another pose).

## Steps
"""


def _type_text(prop: dict, defs: dict) -> str:
    if "$ref" in prop:
        return "mapping"
    if "anyOf" in prop:
        kinds = [_type_text(p, defs) for p in prop["anyOf"] if p.get("type") != "null"]
        return " or ".join(kinds)
    if "oneOf" in prop:
        return " or ".join(_type_text(p, defs) for p in prop["oneOf"])
    if "const" in prop:
        return f"`{prop['const']}`"
    if "enum" in prop:
        return " or ".join(f"`{v}`" for v in prop["enum"])
    kind = prop.get("type")
    if kind == "array":
        items = _type_text(prop.get("items", {}), defs)
        n = prop.get("minItems")
        if n is not None and n == prop.get("maxItems"):
            return f"[{n} × {items}]"
        return f"list of {items}"
    if kind == "object":
        return f"{{joint: {_type_text(prop.get('additionalProperties', {}), defs)}}}"
    bounds = []
    if "exclusiveMinimum" in prop:
        bounds.append(f"> {prop['exclusiveMinimum']}")
    if "maximum" in prop:
        bounds.append(f"≤ {prop['maximum']}")
    text = {"number": "number", "string": "text", "boolean": "true/false",
            "integer": "whole number"}.get(kind, "value")
    return text + (" " + ", ".join(bounds) if bounds else "")


def reference_markdown() -> str:
    """The sequence format reference (docs/sequence-format.md), from the models."""
    schema = sequence_json_schema()
    defs = schema["$defs"]

    def rows(definition: dict) -> str:
        required = set(definition.get("required", []))
        lines = []
        props = definition["properties"]
        for key in sorted(props, key=lambda k: k == "label"):  # label last
            prop = props[key]
            if key == "steps":
                lines.append(f"| `steps` | list of steps (below) — required | "
                             f"{prop.get('description', '')} |")
                continue
            default = ("required" if key in required else
                       "" if prop.get("default") in (None, {}) else
                       f"default `{json_dumps(prop['default'])}`")
            lines.append(f"| `{key}` | {_type_text(prop, defs)}"
                         f"{' — ' + default if default else ''} | "
                         f"{prop.get('description', '')} |")
        return "\n".join(lines)

    from json import dumps as json_dumps

    parts = [_REFERENCE_INTRO.replace("{top}", rows(schema))]
    for kind, model in PARAMS_MODELS.items():
        step = defs[_STEP_MODELS[kind].__name__]["properties"][kind]
        parts.append(f"### `{kind}`\n\n{_doc(model)}\n")
        shorthand = step["description"].split(" Shorthand: ", 1)
        if len(shorthand) == 2:
            parts.append(f"Shorthand: {shorthand[1]}\n")
        definition = defs[model.__name__]
        if "oneOf" in definition:
            choices = [" + ".join(f"`{k}`" for k in alt["required"])
                       for alt in definition["oneOf"]]
            parts.append(f"Give exactly one of: {' or '.join(choices)}.\n")
        parts.append("| key | type | |\n|---|---|---|\n" + rows(definition) + "\n")
    return "\n".join(parts)


def file_reference_markdown(model: type, title: str, intro: str) -> str:
    """A reference of a file format given by a pydantic model (pose files, arm files): one
    row per key, nested mappings as dotted keys, from the model's JSON Schema."""
    schema = model.model_json_schema()
    defs = schema.get("$defs", {})

    def resolve(prop: dict) -> dict:
        if "$ref" in prop:
            return defs[prop["$ref"].rsplit("/", 1)[-1]]
        if "allOf" in prop and len(prop["allOf"]) == 1:
            return {**resolve(prop["allOf"][0]), **{k: v for k, v in prop.items()
                                                   if k != "allOf"}}
        return prop

    def kind(prop: dict) -> str:
        if "anyOf" in prop:
            return " or ".join(kind(p) for p in prop["anyOf"] if p.get("type") != "null")
        if "enum" in prop:
            return " or ".join(f"`{v}`" for v in prop["enum"])
        if "const" in prop:
            return f"`{prop['const']}`"
        if prop.get("type") == "array":
            items = prop.get("prefixItems") or []
            if items:
                return f"[{len(items)} × {kind(items[0])}]"
            return f"list of {kind(resolve(prop.get('items', {})))}"
        if prop.get("type") == "object" and isinstance(prop.get("additionalProperties"), dict):
            return f"{{name: {kind(resolve(prop['additionalProperties']))}}}"
        if prop.get("format") == "date-time":
            return "date and time (ISO 8601)"
        return {"number": "number", "string": "text", "boolean": "true/false",
                "integer": "whole number", "object": "mapping"}.get(prop.get("type", ""),
                                                                     "value")

    rows: list[str] = []

    def walk(definition: dict, prefix: str) -> None:
        required = set(definition.get("required", []))
        for key, raw in definition.get("properties", {}).items():
            prop = resolve(raw)
            name = f"{prefix}{key}"
            default = ("required" if key in required else
                       "" if raw.get("default") in (None, "") or isinstance(
                           raw.get("default"), (dict, list)) and key not in ("rpy_deg",) else
                       f"default `{raw['default']}`")
            description = raw.get("description") or prop.get("description") or ""
            if prop.get("properties"):
                rows.append(f"| `{name}` | mapping{' — ' + default if default else ''} | "
                            f"{description} |")
                walk(prop, name + ".")
                continue
            rows.append(f"| `{name}` | {kind(prop)}{' — ' + default if default else ''} | "
                        f"{description} |")

    walk(schema, "")
    return (f"# {title}\n\n{intro}\n\n| key | type | |\n|---|---|---|\n" + "\n".join(rows)
            + "\n")


def pose_reference_markdown() -> str:
    """The pose file reference (``seqrun schema pose --markdown``)."""
    from seqrun.poses import PoseFile

    return file_reference_markdown(
        PoseFile, "Pose files",
        "`poses/<name>.yaml`: a named joint configuration in user degrees (Totem = zeros). "
        "It lists every joint of the arm, the locked one at its locked value; "
        "`end_effector` is what forward kinematics gives for those joints and is checked "
        "against them. `seqrun pose save NAME` writes one from the arm.")


def arm_reference_markdown() -> str:
    """The arm file reference (``seqrun schema arm --markdown``)."""
    from seqrun.arm import ArmDescription

    return file_reference_markdown(
        ArmDescription, "Arm files",
        "`arms/<name>.yaml`: every number about the arm (joints, limits, offsets, "
        "kinematics, CAN and control-loop settings, workspace guards). Angles in degrees, "
        "user coordinates.")
