"""``seqrun validate FILE`` and ``seqrun schema``.

    seqrun validate sequences/opsafe.yaml            # exit 0 valid, 1 invalid, 2 bad input
    seqrun validate sequences/opsafe.yaml --json
    seqrun validate my.yaml --start totem --arm arms/lwa3.yaml
    seqrun schema > sequence.schema.json
    seqrun schema --markdown > docs/sequence-format.md

Human output: one line per error, ``file:line:col: message``, then the notes
(``file:line:col: note: message``), then a summary line. ``--json`` prints one object
``{"valid": bool, "errors": [...], "notes": [...]}``, each entry ``{file, line, column,
message}``. A file that cannot be read, an unknown ``--start`` pose or a missing arm file is
one ``error:`` line on stderr and exit 2, never a traceback.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from seqrun.arm import ArmDescription
from seqrun.cli.app import app
from seqrun.errors import SequenceInvalid, SourceError, UserInputError
from seqrun.schema import LoadedSequence, load_sequence, sequence_json_schema
from seqrun.validation import START_POSE, ValidationResult, pose_joints_deg, validate_sequence

#: Exit codes of this command.
EXIT_VALID, EXIT_INVALID, EXIT_USAGE = 0, 1, 2


@dataclass
class StaticCheck:
    """What ``seqrun validate`` found before any dry run."""

    loaded: LoadedSequence | None = None
    arm: ArmDescription | None = None
    start_deg: dict[str, float] | None = None
    errors: list[SourceError] = field(default_factory=list)
    notes: list[SourceError] = field(default_factory=list)

    @property
    def valid(self) -> bool:
        return not self.errors


def static_check(file: Path, *, start: str | None = None,
                 arm_file: Path | None = None) -> StaticCheck:
    """Load ``file`` (with includes), its arm and the start pose, and validate statically.

    Invalid files (the sequence, an included one, the arm file, a pose file) end up in
    ``errors``; input that cannot be used at all raises :class:`UserInputError`.
    """
    from seqrun.arm import load_arm

    check = StaticCheck()
    try:
        check.loaded = load_sequence(file)
    except SequenceInvalid as exc:
        check.errors = list(exc.errors)
        return check
    arm_path = arm_file if arm_file is not None else check.loaded.arm_path
    if not Path(arm_path).is_file():
        raise UserInputError(f"arm file {arm_path} not found (give one with --arm FILE)")
    try:
        check.arm = load_arm(arm_path)
    except SequenceInvalid as exc:
        check.errors = list(exc.errors)
        return check
    pose = start or START_POSE
    try:
        check.start_deg = pose_joints_deg(pose, check.loaded.poses_dir)
    except UserInputError as exc:
        raise UserInputError(f"start pose: {exc}"
                             + ("" if start else " (choose one with --start POSE)")) from None
    except SequenceInvalid as exc:
        check.errors = list(exc.errors)
        return check
    result: ValidationResult = validate_sequence(check.loaded, check.arm, check.start_deg)
    check.errors, check.notes = result.errors, result.notes
    return check


def _fail(message: str) -> None:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(EXIT_USAGE)


def print_report(check: StaticCheck, file: Path, *, as_json: bool) -> None:
    if as_json:
        typer.echo(json.dumps({"valid": check.valid,
                               "errors": [e.as_dict() for e in check.errors],
                               "notes": [n.as_dict() for n in check.notes]},
                              indent=2, ensure_ascii=False))
        return
    for error in check.errors:
        typer.echo(str(error))
    for note in check.notes:
        typer.echo(f"{note.file}:{note.line}:{note.column}: note: {note.message}")
    name = check.loaded.file if check.loaded is not None else str(file)
    notes = f", {len(check.notes)} note{'s' * (len(check.notes) != 1)}" if check.notes else ""
    if check.valid:
        steps = len(check.loaded.steps) if check.loaded is not None else 0
        typer.echo(f"{name}: valid ({steps} step{'s' * (steps != 1)}{notes})")
    else:
        count = len(check.errors)
        typer.echo(f"{name}: invalid ({count} error{'s' * (count != 1)}{notes})")


@app.command("validate")
def validate_command(
    file: Annotated[Path, typer.Argument(metavar="FILE", help="Sequence file (YAML).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    start: Annotated[str | None, typer.Option(
        "--start", metavar="POSE",
        help=f"Pose the arm starts in (default {START_POSE}: a freshly powered-on arm).")] = None,
    arm_file: Annotated[Path | None, typer.Option(
        "--arm", metavar="FILE",
        help="Arm description file (default: the sequence's 'arm', else arms/lwa3.yaml under "
             "the project root).")] = None,
) -> None:
    """Check a sequence file and its includes against the arm, without moving anything.

    Exit 0 if valid, 1 if not, 2 if the input cannot be used.
    """
    try:
        check = static_check(file, start=start, arm_file=arm_file)
    except UserInputError as exc:
        _fail(str(exc))
        return
    print_report(check, file, as_json=as_json)
    raise typer.Exit(EXIT_VALID if check.valid else EXIT_INVALID)


class SchemaKind(str, Enum):
    sequence = "sequence"
    arm = "arm"
    pose = "pose"


@app.command("schema")
def schema_command(
    kind: Annotated[SchemaKind, typer.Argument(
        help="Which file format: sequence (default), arm or pose.")] = SchemaKind.sequence,
    markdown: Annotated[bool, typer.Option(
        "--markdown", help="Print the sequence format reference (docs/sequence-format.md) "
                           "instead.")] = False,
) -> None:
    """Print the JSON Schema of a file format (sequence files by default)."""
    if markdown:
        from seqrun.schema import reference_markdown

        typer.echo(reference_markdown(), nl=False)
        return
    if kind is SchemaKind.sequence:
        schema = sequence_json_schema()
    elif kind is SchemaKind.arm:
        from seqrun.arm import ArmDescription as Model

        schema = Model.model_json_schema()
    else:
        from seqrun.poses import PoseFile as Model  # type: ignore[assignment]

        schema = Model.model_json_schema()
    typer.echo(json.dumps(schema, indent=2, ensure_ascii=False))
