"""The sequence file format: the pydantic models of a file (the single source of truth).

A sequence file is a mapping with ``name``, an optional ``description`` and ``arm``, and
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

Each step kind's parameter model and shorthand live with the rest of that kind in
``seqrun/steps/<kind>.py`` (:mod:`seqrun.steps.registry` lists them); this module
assembles them, with ``include``, into the one-key step mappings, the step union and the
JSON Schema. The models only check what a file says on its own (types, ranges, which keys
go together); what depends on the arm (joint names, limits, velocities, the start-up
order) is :mod:`seqrun.sequence.validation`. Reading a file with its includes is
:mod:`seqrun.sequence.loader`, the Markdown reference :mod:`seqrun.sequence.reference`.
"""

from __future__ import annotations

import functools
import re
from typing import Annotated, Any, ClassVar, Literal, Union

from pydantic import (
    AfterValidator,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    TypeAdapter,
    model_validator,
)
from pydantic_core import PydanticCustomError

from seqrun.steps.checkpoint import CheckpointParams
from seqrun.steps.confirm import ConfirmParams
from seqrun.steps.halt import HaltParams
from seqrun.steps.home import HomeParams
from seqrun.steps.kind import StepKind
from seqrun.steps.move import MoveParams
from seqrun.steps.move_linear import MoveLinearParams
from seqrun.steps.params import (  # noqa: F401  (the value types, re-exported)
    AllOrJoints,
    AllWord,
    Finite,
    JointName,
    LimitPair,
    MonitorSpec,
    PoseName,
    Positive,
    Scale,
    StepParams,
    StrictModel,
    Vector3,
    doc,
    one_key_value,
)
from seqrun.steps.power_off import PowerOffParams
from seqrun.steps.registry import KINDS
from seqrun.steps.reset import ResetParams
from seqrun.steps.sequence_parameters import ParameterSpec
from seqrun.steps.set_limits import SetLimitsParams
from seqrun.steps.wait import WaitParams

__all__ = [
    "BARE_STEPS",
    "DEFAULT_ARM",
    "MAX_INCLUDE_DEPTH",
    "MAX_STEPS",
    "PARAMS_MODELS",
    "STEP_KINDS",
    "CheckpointParams",
    "ConfirmParams",
    "HaltParams",
    "HomeParams",
    "BlockParams",
    "IncludeParams",
    "MoveLinearParams",
    "MoveParams",
    "PowerOffParams",
    "ResetParams",
    "Sequence",
    "SetLimitsParams",
    "StepParams",
    "WaitParams",
    "describe",
    "sequence_json_schema",
]

#: Arm file of a sequence that names none, relative to the project root.
DEFAULT_ARM = "arms/lwa3.yaml"
#: Deepest chain of includes (a includes b includes c ...).
MAX_INCLUDE_DEPTH = 16
#: Most steps a sequence may expand to with its includes.
MAX_STEPS = 10_000

_Model = StrictModel

# --------------------------------------------------------------------------- include
_YAML_FILE_RE = re.compile(r"\.ya?ml$")


def _yaml_file(value: str) -> str:
    if not _YAML_FILE_RE.search(value):
        raise PydanticCustomError("include_file", "an include names a sequence file ending in "
                                                  ".yaml, got '{value}'", {"value": value})
    return value


#: Where an include may reach (seqrun.sequence.project.Project.include_tree), as the
#: docs and the README say it.
INCLUDE_REACH = ("Path of the sequence to include, relative to this file. In a campaign "
                 "(a folder with seqrun.toml) it may be anywhere inside the campaign folder; "
                 "without one it must stay inside the project's sequences/ folder (else the "
                 "folder of the file given to seqrun).")

IncludeFile = Annotated[str, Field(min_length=1), AfterValidator(_yaml_file), Field(
    json_schema_extra={"pattern": _YAML_FILE_RE.pattern},
    description=INCLUDE_REACH)]


class IncludeParams(StepParams):
    """Run the steps of another sequence file here."""

    kind: ClassVar[str] = "include"
    yaml_name: ClassVar[str] = "include"
    file: IncludeFile = Field(  # type: ignore[valid-type]
        description=INCLUDE_REACH)
    with_: dict[Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")],
                bool | int | float | str] = Field(
        default_factory=dict, alias="with",
        description="Values of the included file's own params (a template): name -> value, "
                    "each checked against its declaration; the ones not given take their "
                    "defaults. A file that declares no params takes none (it uses the "
                    "including sequence's).")

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(file=value)

    @model_validator(mode="after")
    def _no_monitors(self) -> IncludeParams:
        if self.monitors:
            raise PydanticCustomError("include_monitors", "an include runs other steps: put "
                                                          "the monitors on those steps")
        given = [key for key in ("verifies", "tags") if getattr(self, key)]
        if given:
            raise PydanticCustomError("include_requirements", "an include runs other steps: "
                                      "put {keys} on those steps", {"keys": " and ".join(given)})
        flow = [alias for key, alias in (("if_", "if"), ("skip_if", "skip_if"),
                                         ("repeat", "repeat"), ("retry", "retry"),
                                         ("on_fail", "on_fail"))
                if getattr(self, key) is not None]
        if flow:
            raise PydanticCustomError("include_flow", "an include runs other steps: put "
                                      "{keys} on those steps", {"keys": " and ".join(flow)})
        if self.breakpoint:
            raise PydanticCustomError("include_breakpoint", "an include runs other steps: put "
                                      "breakpoint on the first of them")
        return self


class BlockParams(StepParams):
    """Steps run together, as a test engineer knows from Ansible (block/rescue/always)
    and RAPID (ERROR handlers): when one of them fails in a way that may be recovered
    (a check, a wait_until timing out, a checkpoint or check_gripper out of tolerance),
    the rescue steps run and the block counts as rescued if they pass; the always steps
    run after the block and its rescue, passed or failed. A module fault, a Halt (guard,
    monitor, separation, operator STOP), a lost bus and an operator abort are never
    rescued: the run ends as without a block, and neither rescue nor always moves the arm
    (docs/safety.md, 'What a rescue may follow')."""

    kind: ClassVar[str] = "block"
    yaml_name: ClassVar[str] = "block"
    steps: list[Step] = Field(min_length=1, description="The block's steps, in order.")
    rescue: list[Step] | None = Field(
        None, min_length=1,
        description="Steps run when a step of the block fails in a way that may be "
                    "recovered (e.g. a retreat to a safe pose); the block is then reported "
                    "as rescued if they pass, and the run fails if they fail.")
    always: list[Step] | None = Field(
        None, min_length=1,
        description="Steps run after the block and its rescue, whether they passed or "
                    "failed (e.g. release the gripper, go to Op-safe); not after a fault, a "
                    "Halt or an operator abort.")

    @model_validator(mode="after")
    def _only_label(self) -> BlockParams:
        given = [alias for key, alias in (("monitors", "monitors"), ("verifies", "verifies"),
                                          ("tags", "tags"), ("if_", "if"),
                                          ("skip_if", "skip_if"), ("repeat", "repeat"),
                                          ("retry", "retry"), ("breakpoint", "breakpoint"),
                                          ("on_fail", "on_fail"))
                 if getattr(self, key)]
        if given:
            raise PydanticCustomError("block_keys", "a block takes steps, rescue, always and "
                                      "label: put {keys} on its steps",
                                      {"keys": " and ".join(given)})
        return self


#: Parameter model of each step type, in the order the docs list them: the step kinds
#: (seqrun/steps/registry.py), then include (the loader's: its steps run in its place).
PARAMS_MODELS: dict[str, type[StepParams]] = {
    **{kind.name: kind.params for kind in KINDS}, "include": IncludeParams,
    "block": BlockParams}
STEP_KINDS: tuple[str, ...] = tuple(PARAMS_MODELS)
#: Step types that may be written as a bare word (``- reset``).
BARE_STEPS: tuple[str, ...] = tuple(kind.name for kind in KINDS if kind.bare)


# -- the one-key step mappings
class _Step(_Model):
    """One-key mapping ``{<kind>: <parameters or shorthand>}``."""

    kind: ClassVar[str] = ""

    def params(self) -> StepParams:
        return PARAMS_MODELS[self.kind].from_shorthand(getattr(self, self.kind))


def _step_model(kind: StepKind) -> type[_Step]:
    """``MoveStep``: the mapping ``{move: <parameters or shorthand>}`` of a step kind."""
    name = "".join(part.title() for part in kind.name.split("_")) + "Step"
    article = "An" if kind.name[0] in "aeiou" else "A"
    namespace = {
        "__module__": __name__, "__qualname__": name,
        "__doc__": f"{article} {kind.name} step.",
        "__annotations__": {"kind": ClassVar[str], kind.name: kind.value},
        "kind": kind.name,
        kind.name: Field(description=doc(kind.params) + kind.shorthand),
    }
    return type(_Step)(name, (_Step,), namespace)  # type: ignore[misc]  # a pydantic model class


class IncludeStep(_Step):
    """An include step."""

    kind: ClassVar[str] = "include"
    include: one_key_value("include", IncludeParams,  # type: ignore[valid-type]
                           text=("file", IncludeFile)) = Field(
        description=doc(IncludeParams) + " Shorthand: 'include: startup.yaml'.")


class BlockStep(_Step):
    """A block step: steps, their rescue and the steps always run after them."""

    kind: ClassVar[str] = "block"
    block: BlockParams = Field(description=doc(BlockParams))


#: The one-key mapping model of each step type (MoveStep, ...), as PARAMS_MODELS.
STEP_MODELS: dict[str, type[_Step]] = {
    **{kind.name: _step_model(kind) for kind in KINDS}, "include": IncludeStep,
    "block": BlockStep}
assert tuple(STEP_MODELS) == STEP_KINDS, "one step model per parameter model"

BareStep = Annotated[Literal[BARE_STEPS], Field(  # type: ignore[valid-type]
    description="A step with its default parameters: "
                f"{', '.join(BARE_STEPS[:-1])} or {BARE_STEPS[-1]}.")]


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


#: An example of each step that needs parameters (the error for its bare word).
_EXAMPLES = {**{kind.name: kind.example for kind in KINDS if kind.example},
             "include": "include: startup.yaml",
             "block": "block: {steps: [...], rescue: [...], always: [...]}"}


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
           *(Annotated[m, Tag(f"step:{k}")] for k, m in STEP_MODELS.items()))],
    Discriminator(_step_pick),
    BeforeValidator(_check_step),
    Field(description="One step: a mapping with one key naming the step type "
                      f"({', '.join(STEP_KINDS)}), or a bare {', '.join(BARE_STEPS)}."),
]

# the block's lists hold steps, blocks among them
BlockParams.model_rebuild()
BlockStep.model_rebuild()

ParameterName = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")]


class Sequence(_Model):
    """A seqrun sequence file: what the arm does, step by step."""

    yaml_name: ClassVar[str] = "the sequence"
    model_config = ConfigDict(title="seqrun sequence")

    name: str = Field(min_length=1, description="Short name of the sequence, shown to the "
                                                "operator and in run reports.")
    description: str = Field("", description="What the sequence does and when to use it "
                                             "(optional: without it the report and displays "
                                             "show the name alone).")
    arm: str | None = Field(
        None, min_length=1,
        description=f"Arm file, relative to the project root (default: the campaign's arm, "
                    f"else {DEFAULT_ARM}), or the name of an arm (lwa3: the campaign's "
                    "arms/lwa3.yaml, else the shipped one). An included sequence must name "
                    "the same arm or none.")
    params: dict[ParameterName, ParameterSpec] = Field(  # type: ignore[valid-type]
        default_factory=dict,
        description="Typed parameters, name -> declaration: '${name}' in any value of the "
                    "steps is replaced by the value (the default, or --param name=value); "
                    "expressions read them as params.NAME. An included file without "
                    "params: uses the including file's; one with params: of its own is a "
                    "template: its include gives their values under with:.")
    monitors: list[MonitorSpec] = Field(
        default_factory=list,
        description="Invariants watched every control cycle of every step (as a step's "
                    "monitors, beside them), e.g. 'tool.z_mm > 40' for the whole "
                    "sequence. Only the top file declares them; an included file's steps "
                    "are watched by the including sequence's.")
    steps: list[Step] = Field(min_length=1, description="The steps, in order.")


@functools.cache
def step_adapter() -> TypeAdapter[Any]:
    """Validates one step (a list item of ``steps``) on its own: for the steps of a file
    that is not valid as a whole. Built on first use: it is a second copy of the steps'
    union, which only invalid files need, and every start would pay for it."""
    return TypeAdapter(Step)


def sequence_json_schema() -> dict:
    """JSON Schema (2020-12) of sequence files, for editors (yaml-language-server)."""
    schema = Sequence.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": "https://seqrun.local/schema/sequence.schema.json", **schema}


def describe(kind: str, params: StepParams) -> str:
    """A one-line description of a step for people, e.g. ``move to pose totem``."""
    if isinstance(params, IncludeParams):
        return f"include {params.file}"
    if isinstance(params, BlockParams):
        return "block"
    from seqrun.steps.registry import step_kind

    try:
        return step_kind(kind).describe(params)
    except KeyError:
        return kind
