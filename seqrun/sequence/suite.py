"""A test suite file: a campaign's sequences in order, with setup, teardown, an on-error
policy and a loop count (docs/suites.md).

A YAML file whose top level is the one key ``suite:`` is a suite; a sequence file never
has that key (its top level is ``name``, ``steps``, ...), so :func:`is_suite_file` tells
the two apart by reading the file, whatever it is called::

    suite:
      name: Qualification
      setup: sequences/startup.yaml
      sequences:
        - sequences/opsafe.yaml
        - {file: sequences/reach.yaml, params: {speed: 0.3}}
      teardown: sequences/park.yaml
      on_error: stop          # or continue, or pause (ask the operator)
      loop: 3                 # the sequences three times (setup and teardown once)

Paths are relative to the suite file. Every problem is an error at its file:line:col,
as a sequence file's are (:mod:`seqrun.yamlsource`). Pure file reading, no arm.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, Union

from pydantic import BeforeValidator, ConfigDict, Field, StrictBool, StrictFloat, StrictInt, \
    StrictStr, ValidationError

from seqrun.errors import SequenceInvalid, SourceError, UserInputError
from seqrun.yamlsource import Document, FriendlyModel, load_document, sort_errors

__all__ = ["OnError", "Suite", "SuiteItem", "is_suite_file", "load_suite", "param_texts",
           "suite_json_schema"]

OnError = Literal["stop", "continue", "pause"]
ParamValue = Union[StrictBool, StrictInt, StrictFloat, StrictStr]
#: The most often a suite may loop (an endurance run of days stays well below).
MAX_LOOP = 100_000


class _SuiteModel(FriendlyModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


def _entry_shorthand(value: Any) -> Any:
    """``- sequences/a.yaml`` is ``- {file: sequences/a.yaml}``."""
    return {"file": value} if isinstance(value, str) else value


class SuiteEntry(_SuiteModel):
    """One sequence of the suite, with values for the parameters it declares."""

    yaml_name: ClassVar[str] = "a suite entry"
    file: str = Field(min_length=1, pattern=r"\.ya?ml$",
                      description="The sequence file, relative to the suite file.")
    params: dict[str, ParamValue] = Field(
        default_factory=dict, description="Values of the sequence's declared params "
        "(typed as in the sequence: 0.3 for a float, true for a bool), over their defaults.")


Entry = Annotated[SuiteEntry, BeforeValidator(_entry_shorthand,
                                              json_schema_input_type=Union[str, SuiteEntry])]


class SuiteBody(_SuiteModel):
    """What the suite runs, in order, and what it does when a sequence fails."""

    yaml_name: ClassVar[str] = "the suite"
    name: str = Field(min_length=1, description="Short name, shown and in the reports.")
    description: str = Field("", description="What the suite qualifies (optional).")
    setup: Entry | None = Field(None, description="Run once before the sequences; when it "
                                                  "fails no sequence runs.")
    sequences: list[Entry] = Field(min_length=1, description="The sequences, in order.")
    teardown: Entry | None = Field(
        None, description="Run once at the end, also after a failed sequence, unless the "
        "arm faulted in a way that needs the operator (docs/suites.md).")
    on_error: OnError = Field("stop", description="When a sequence fails: stop the suite, "
                              "continue with the next, or pause and ask the operator "
                              "(--yes never answers that).")
    loop: StrictInt = Field(1, ge=1, le=MAX_LOOP, description="Run the sequences this many "
                                                              "times (endurance).")


class SuiteFile(_SuiteModel):
    """A seqrun suite file."""

    yaml_name: ClassVar[str] = "the suite file"
    model_config = ConfigDict(title="seqrun suite")
    suite: SuiteBody


@dataclass(frozen=True)
class SuiteItem:
    """One run of a suite: which sequence, as what, where the suite names it."""

    role: Literal["setup", "sequence", "teardown"]
    path: Path
    #: The path as the suite file writes it.
    shown: str
    params: dict[str, Any]
    #: ``file:line:col`` of the entry in the suite file.
    location: str
    #: 1-based position among the suite's sequences (0: setup or teardown).
    index: int = 0
    #: 1-based loop (0: setup or teardown).
    loop: int = 0

    @property
    def key(self) -> tuple[str, int]:
        """The same entry in every loop (its checks are the same)."""
        return (self.role, self.index)


@dataclass(frozen=True)
class Suite:
    path: Path
    file: str
    name: str
    description: str
    sequences: tuple[SuiteItem, ...]
    setup: SuiteItem | None = None
    teardown: SuiteItem | None = None
    on_error: OnError = "stop"
    loop: int = 1
    sha256: str = ""
    source: bytes = field(default=b"", repr=False)

    def plan(self) -> list[SuiteItem]:
        """Every run in order: setup, the sequences ``loop`` times, teardown."""
        from dataclasses import replace

        runs = [self.setup] if self.setup is not None else []
        runs += [replace(item, loop=n) for n in range(1, self.loop + 1)
                 for item in self.sequences]
        return runs + ([self.teardown] if self.teardown is not None else [])

    def entries(self) -> list[SuiteItem]:
        """Each entry once (setup, sequences, teardown): what validation checks."""
        return [i for i in (self.setup, *self.sequences, self.teardown) if i is not None]


def is_suite_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a suite (top level ``suite:``). A file that cannot be read or
    parsed is not: the sequence path reports its problems as it always did."""
    path = Path(path)
    try:
        if not path.is_file() or path.suffix not in (".yaml", ".yml"):
            return False
        data = load_document(path).data
    except (SequenceInvalid, UserInputError, OSError):
        return False
    return isinstance(data, dict) and "suite" in data


def load_suite(path: str | os.PathLike[str]) -> Suite:
    """Read a suite file: every problem (schema, missing sequence files, parameters the
    sequence does not declare or of the wrong type) as a located error.

    :raises SequenceInvalid: the located errors. :raises UserInputError: unreadable file.
    """
    doc = load_document(path)
    try:
        body = SuiteFile.model_validate(doc.data).suite
    except ValidationError as exc:
        raise SequenceInvalid(doc.validation_errors(exc)) from None
    errors: list[SourceError] = []

    def item(entry: SuiteEntry, where: tuple, role: Any, index: int = 0) -> SuiteItem:
        target = (doc.path.parent / entry.file)
        location = doc.locate(where)
        if not target.is_file():
            errors.append(doc.error((*where, "file") if isinstance(doc.data, dict) else where,
                                    f"no sequence file {entry.file} (relative to {doc.file})"))
        else:
            errors.extend(_param_errors(doc, where, entry, target))
        return SuiteItem(role, target, entry.file, dict(entry.params), str(location),
                         index)

    setup = item(body.setup, ("suite", "setup"), "setup") if body.setup else None
    sequences = tuple(item(e, ("suite", "sequences", i), "sequence", i + 1)
                      for i, e in enumerate(body.sequences))
    teardown = (item(body.teardown, ("suite", "teardown"), "teardown") if body.teardown
                else None)
    if errors:
        raise SequenceInvalid(sort_errors(errors))
    return Suite(doc.path, doc.file, body.name, body.description, sequences, setup,
                 teardown, body.on_error, body.loop, doc.sha256, doc.source)


def _param_errors(doc: Document, where: tuple, entry: SuiteEntry,
                  target: Path) -> list[SourceError]:
    """The entry's ``params`` against what the sequence declares: the names and, strictly,
    the types and ranges (``"12"`` is not 12), each at its place in the suite file. A
    sequence that does not load is left to its own validation."""
    from seqrun.steps.sequence_parameters import ParameterSpec, value_problem

    if not entry.params:
        return []
    try:
        declared = load_document(target).data
    except (SequenceInvalid, UserInputError):
        return []
    specs = declared.get("params") if isinstance(declared, dict) else None
    specs = specs if isinstance(specs, dict) else {}
    errors = []
    node = doc.find(where)
    for name, value in entry.params.items():
        at = ("params", name)
        if name not in specs:
            errors.append(doc.error(at, f"{entry.file} declares no parameter '{name}' "
                                        f"(declared: {', '.join(map(str, specs)) or 'none'})",
                                    start=node, key=True))
            continue
        try:
            spec = ParameterSpec.model_validate(specs[name])
        except ValidationError:
            continue   # the sequence's own validation says what is wrong there
        problem = value_problem(spec, value)
        if problem is not None:
            errors.append(doc.error(at, f"params: {name}: {problem}", start=node))
    return errors


def param_texts(item: SuiteItem) -> dict[str, str]:
    """The entry's values as ``--param`` texts (already checked strictly against their
    declarations by :func:`load_suite`): what the sequence loader takes."""
    from seqrun.steps.sequence_parameters import show_value

    return {name: show_value(value) for name, value in item.params.items()}


def suite_json_schema() -> dict:
    """JSON Schema of a suite file (docs/schema/suite.schema.json)."""
    return SuiteFile.model_json_schema(by_alias=True)
