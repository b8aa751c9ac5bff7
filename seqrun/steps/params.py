"""What every step kind's parameters are built from: value types, the base model, shorthand.

A step kind's module (``seqrun/steps/<kind>.py``) defines its parameter model on
:class:`StepParams` with these value types, and the value its one key takes in a file
(:func:`one_key_value`: the full parameters, or a shorthand such as ``move: totem``).
:mod:`seqrun.schema` assembles the kinds of :mod:`seqrun.steps.registry` into the sequence
file's union and JSON Schema. Only pydantic here: the schema and the loader import it.
"""

from __future__ import annotations

import inspect
import re
from collections.abc import Sequence
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Literal, Protocol, Union

from pydantic import (AfterValidator, ConfigDict, Discriminator, Field, Tag, ValidationInfo,
                      model_validator)
from pydantic_core import PydanticCustomError

from seqrun.yamlsource import FriendlyModel

__all__ = [
    "AllOrJoints",
    "AllWord",
    "Finite",
    "JointName",
    "JointsList",
    "LimitPair",
    "ModulesParams",
    "MonitorSpec",
    "RepeatSpec",
    "RetrySpec",
    "PoseName",
    "RequirementId",
    "Positive",
    "Scale",
    "StepParams",
    "StrictModel",
    "ToolParams",
    "ToolTargetParams",
    "Vector3",
    "check_pose_target",
    "doc",
    "either",
    "exactly_one",
    "ExpressionText",
    "HazardKey",
    "modules_value",
    "one_key_value",
]

# --------------------------------------------------------------------------- value types
Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
# At least 1 %: below that a move takes hours and the planner's numbers degenerate.
Scale = Annotated[float, Field(ge=0.01, le=1, allow_inf_nan=False)]

POSE_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]*$")


def _pose_name(value: str) -> str:
    if not POSE_NAME_RE.match(value):
        raise PydanticCustomError(
            "pose_name", "'{value}' is not a pose name (the name of a file in poses/ without "
                         ".yaml: letters, digits, _ and -)", {"value": value})
    return value


JointName = Annotated[str, Field(min_length=1, description="A joint name of the arm file, "
                                                           "e.g. j1.")]
JointsList = Annotated[list[JointName], Field(min_length=1)]
PoseName = Annotated[str, AfterValidator(_pose_name), Field(
    json_schema_extra={"pattern": POSE_NAME_RE.pattern},
    description="Name of a pose file in the project's poses/ folder, without .yaml "
                "(e.g. totem, park, opsafe).")]
Vector3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
LimitPair = Annotated[list[Finite], Field(min_length=2, max_length=2,
                                          description="[min, max] in degrees.")]


def doc(model: type) -> str:
    """A model's docstring as one line (for field descriptions)."""
    return " ".join(inspect.cleandoc(model.__doc__ or "").split())


def either(pick, **choices: Any) -> Any:
    """A union whose branch is chosen by ``pick(value)`` (a tag in ``choices``), so that a
    wrong value gets the errors of one branch only. Tags contain ':' so they never look
    like YAML keys when errors are located."""
    members = tuple(Annotated[tp, Tag(tag)] for tag, tp in choices.items())
    return Annotated[Union[members], Discriminator(pick)]  # noqa: UP007


def _joints_pick(value: Any) -> str:
    return "joints:all" if isinstance(value, str) else "joints:list"


def _all_only(value: str) -> str:
    if value != "all":
        raise PydanticCustomError("all_or_joints", "expected 'all' or a list of joint names, "
                                                   "got '{value}'", {"value": value})
    return value


AllWord = Annotated[str, AfterValidator(_all_only), Field(json_schema_extra={"const": "all"})]
if TYPE_CHECKING:
    # What either() builds, spelled so that mypy (and the pydantic plugin's generated
    # __init__ of every ModulesParams subclass) sees a real type rather than Any.
    AllOrJoints = Union[AllWord, JointsList]  # noqa: UP007
else:
    AllOrJoints = either(_joints_pick, **{"joints:all": AllWord, "joints:list": JointsList})


def _expression(value: str, info: ValidationInfo) -> str:
    from seqrun.steps.expressions import ExpressionError, parse

    # the sequence's parameters (params.NAME), which the loader gives as context; a
    # model made in code (a shorthand's, after the loader's check) has none: its
    # expression is checked again against the arm, with the parameters, by the step's check
    context = info.context if isinstance(info.context, dict) else None
    if context is None:
        if "params." in value:
            return value.strip()
        context = {}
    try:
        parse(value, params=context.get("params"))
    except ExpressionError as exc:
        raise PydanticCustomError(
            "expression", "{message} (at column {column} of '{text}')",
            {"message": exc.message, "column": exc.column, "text": value.strip()}) from None
    return value.strip()


ExpressionText = Annotated[str, AfterValidator(_expression), Field(
    min_length=1, description="An expression over the run's telemetry (docs/sequence-format.md, "
                              "'Expressions'), e.g. 'tool.z_mm > 40 and not moving'.")]


#: A motion step's hazard class (docs/safety.md, "Hazard classes"): its own key on the
#: kinds that move the arm (any other step refuses it as an unknown key).
HazardKey = Annotated[Literal["normal", "caution", "hazardous"] | None, Field(
    description="The step's hazard class: caution and hazardous moves run at most at "
                "their class's speed cap (the arm file's hazards; on move steps), a "
                "hazardous one starts only after a signed confirm (--yes never answers "
                "it). Default: normal, or what the arm file's hazards.*.within_mm derive "
                "from the move's smallest planned clearance; lower than that is an error "
                "(docs/safety.md, 'Hazard classes').")]


#: What a requirement id or a tag may be (docs/campaigns.md, "Requirements").
REQUIREMENT_ID_RE = r"^[A-Za-z0-9_.:-]+$"
RequirementId = Annotated[str, Field(min_length=1, max_length=64, pattern=REQUIREMENT_ID_RE)]


# --------------------------------------------------------------------------- models
class StrictModel(FriendlyModel):
    """Unknown keys, wrong types and changes after loading are errors."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class MonitorSpec(StrictModel):
    """An invariant watched every control cycle while its step runs: when ``while`` has
    not held for ``persist_cycles`` cycles in a row, the action is taken."""

    yaml_name: ClassVar[str] = "monitor"
    while_: ExpressionText = Field(
        alias="while", description="What must hold every cycle, e.g. "
                                   "'abs(following_error_deg[4]) < 1.0' or 'tool.z_mm > 40'.")
    persist_cycles: int = Field(1, ge=1, le=1000, description="How many cycles in a row it "
                                                              "must fail before the action.")
    action: Literal["halt", "stop", "warn"] = Field(
        "halt", description="halt: the arm halts at once and the run ends as a fault (exit "
                            "3) naming the monitor and the values; stop: a controlled "
                            "(jerk-limited) stop of the motion under way, then the same "
                            "fault; warn: an event and a line in the report, the run goes "
                            "on.")
    message: str | None = Field(None, min_length=1,
                                description="What a trip means, for the operator.")


class RepeatSpec(StrictModel):
    """Run the step several times: ``count`` times, or while a condition holds (checked
    before each iteration) up to ``max`` times; still holding after ``max``, the run ends
    as a fault."""

    yaml_name: ClassVar[str] = "repeat"
    count: int | None = Field(None, ge=1, le=1000, description="How many times to run "
                                                              "the step.")
    while_: ExpressionText | None = Field(
        None, alias="while", description="Run the step again while this holds (checked "
                                         "before each iteration, e.g. 'not gripper.holding').")
    max: int | None = Field(None, ge=1, le=1000, description="With while: at most this many "
                                                            "iterations (required).")

    @model_validator(mode="after")
    def _one_form(self) -> RepeatSpec:
        if (self.count is None) == (self.while_ is None):
            raise PydanticCustomError("repeat", "repeat takes either count or while (with "
                                                "max), not both or neither")
        if self.while_ is not None and self.max is None:
            raise PydanticCustomError("repeat", "repeat with while needs max (the most "
                                                "iterations it may take)")
        if self.count is not None and self.max is not None:
            raise PydanticCustomError("repeat", "max belongs to repeat with while; count "
                                                "says how many times already")
        return self


class RetrySpec(StrictModel):
    """Run the step again when it failed in a way that may be retried (a check that did
    not hold, a wait_until that timed out, a checkpoint outside its tolerance, a gripper
    check that failed); never after a module fault, a Halt, a guard or monitor halt or an
    operator abort (docs/safety.md, 'What may be retried')."""

    yaml_name: ClassVar[str] = "retry"
    times: int = Field(ge=1, le=100, description="How many times to try again at most.")
    delay_s: float = Field(0.0, ge=0, allow_inf_nan=False,
                           description="How long to wait (monitoring the arm) before each "
                                       "retry, seconds.")


class StepParams(StrictModel):
    """Parameters every step has."""

    kind: ClassVar[str] = ""
    label: str | None = Field(
        None, min_length=1,
        description="Text shown to the operator for this step (default: a description "
                    "generated from the step).")
    monitors: list[MonitorSpec] = Field(
        default_factory=list, max_length=32,
        description="Invariants watched every control cycle while this step runs "
                    "(docs/sequence-format.md, 'Expressions').")
    verifies: list[RequirementId] = Field(
        default_factory=list, max_length=64,
        description="The requirements this step verifies (ids of the campaign's "
                    "requirements.csv, kept in report.json, junit.xml and the requirement "
                    "matrix), e.g. [REQ-CAP-012].")
    tags: list[RequirementId] = Field(
        default_factory=list, max_length=64,
        description="Free tags of this step (kept in report.json and junit.xml), e.g. "
                    "[capture, endurance].")
    if_: ExpressionText | None = Field(
        None, alias="if", description="Run the step only if this holds at its start (else "
                                      "it is reported as skipped), e.g. "
                                      "'not gripper.holding'. Not on a step that moves the "
                                      "arm, changes the modules' start-up state or signals "
                                      "the other arms ('Conditions, loops and retries').")
    skip_if: ExpressionText | None = Field(
        None, description="Skip the step (reported as skipped) if this holds at its start. "
                          "Not where if is not.")
    repeat: RepeatSpec | None = Field(
        None, description="Run the step several times: {count: N} or {while: EXPR, max: N} "
                          "('Conditions, loops and retries'). Not where if is not.")
    breakpoint: bool = Field(
        False, description="Stop before this step, the arm at rest, until the operator "
                           "says to go on (a terminal prompt, the console's question); "
                           "--yes never answers it and the dry run passes through it "
                           "(docs/safety.md, 'Who answers what').")
    retry: RetrySpec | None = Field(
        None, description="Try the step again after a failed measurement: {times: N, "
                          "delay_s: S}; check, wait_until, checkpoint and check_gripper only "
                          "(docs/safety.md, 'What may be retried').")
    on_fail: Literal["fail", "pause"] | None = Field(
        None, description="What a failure that may be retried does once the step's own "
                          "retries are spent: fail (the default) ends the run; pause holds "
                          "the arm at rest and asks the operator Retry, Skip or Abort (a "
                          "terminal prompt, the console's question); never after a fault "
                          "or a Halt, never answered by --yes; check, wait_until, "
                          "checkpoint and check_gripper only, not in a block "
                          "(docs/safety.md, 'Who answers what').")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        """The full parameters of a shorthand value (overridden where there is one)."""
        return value if isinstance(value, cls) else cls()


class ModulesParams(StepParams):
    """Parameters of a command to the modules (reset, home, halt): which ones."""

    joints: AllOrJoints = Field(
        "all", description="'all' (one broadcast to every module) or a list of joint names "
                           "(one command per module).")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        if isinstance(value, cls):
            return value
        return cls() if value is None else cls(joints=value)


def exactly_one(*alternatives: str) -> dict:
    """JSON Schema: exactly one of these keys is given."""
    return {"oneOf": [{"required": [name]} for name in alternatives]}


class ToolParams(Protocol):
    """Parameters that name a tool of the arm file (None: the arm's default tool)."""

    @property
    def tool(self) -> str | None: ...


class ToolTargetParams(ToolParams, Protocol):
    """An end-effector target as ``move`` (with ``position_mm``) and ``move_linear`` write
    it: what the tool-target helpers read of either kind's parameters."""

    @property
    def position_mm(self) -> Sequence[float] | None: ...

    @property
    def rpy_deg(self) -> Sequence[float] | None: ...

    @property
    def relative(self) -> bool: ...

    @property
    def frame(self) -> str: ...


def check_pose_target(params: Any, what: str) -> None:
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


# --------------------------------------------------------------------------- one-key values
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


def one_key_value(kind: str, model: type[StepParams], *, none: str | None = None,
                  text: tuple[str, Any] | None = None, number: tuple[str, Any] | None = None,
                  items: tuple[str, Any] | None = None) -> Any:
    """The type of the value under a step's key: the parameters ``model`` (a mapping), or a
    shorthand: ``none`` names the bare step (``- reset``), ``text``/``number``/``items`` are
    ``(name, type)`` of a string/number/list shorthand (``move: totem``). A step without
    shorthand takes its parameters only."""
    if none is None and text is None and number is None and items is None:
        return model
    choices: dict[str, Any] = {}
    tags: dict[str, str] = {}
    if none is not None:
        tags["none"] = f"{kind}:{none}"
        choices[tags["none"]] = None
    for role, given in (("text", text), ("number", number), ("items", items)):
        if given is not None:
            tags[role] = f"{kind}:{given[0]}"
            choices[tags[role]] = given[1]
    tags["params"] = f"{kind}:params"
    choices[tags["params"]] = model
    return either(_kind_pick(**tags), **choices)


def modules_value(kind: str, model: type[ModulesParams]) -> Any:
    """The value of a reset/home/halt step: bare (``- halt``), ``all``, a list of joint
    names (``halt: [j1, j2]``) or the parameters."""
    return one_key_value(kind, model, none="default", text=("all", AllWord),
                         items=("list", JointsList))
