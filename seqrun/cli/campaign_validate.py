"""``seqrun validate DIR`` (or several files): every sequence of a campaign, one table.

Each sequence gets the static checks and the dry run (``--static``: the checks only), each
pose file the pose checks against the arm; then one summary table: file, result, simulated
duration, lowest guard clearance, findings. ``--json`` prints the same as one object,
``--junit FILE`` writes a JUnit report for CI. Exit 0 only when everything is valid.
The pre-commit hook (``.pre-commit-hooks.yaml``) runs ``seqrun validate --static`` on the
changed sequence and pose files.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import typer

from seqrun.errors import SequenceInvalid, SourceError, UserInputError

#: Folders of a campaign that hold no sequences.
_NOT_SEQUENCES = {"poses", "arms", "runs", ".seqrun", ".git"}


@dataclass
class FileResult:
    file: str
    kind: str  # sequence | pose | arm
    result: str = "valid"  # valid | invalid | dry run failed | error
    simulated_s: float | None = None
    clearance_mm: float | None = None
    clearance_at: str | None = None
    errors: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def valid(self) -> bool:
        return self.result == "valid"

    def as_dict(self) -> dict[str, Any]:
        return {"file": self.file, "kind": self.kind, "result": self.result,
                "valid": self.valid, "simulated_s": self.simulated_s,
                "lowest_guard_clearance_mm": self.clearance_mm,
                "lowest_guard_clearance_at": self.clearance_at,
                "errors": self.errors, "notes": self.notes}


def _kind(path: Path) -> str:
    parts = {p.lower() for p in path.parent.parts}
    if "poses" in parts:
        return "pose"
    if "arms" in parts:
        return "arm"
    return "sequence"


def collect(paths: list[Path]) -> list[Path]:
    """The files to validate: files as given; a folder's sequences (its ``sequences/``, or
    every YAML outside poses/arms/runs) and its ``poses/``."""
    files: list[Path] = []
    for path in paths:
        if path.is_file():
            files.append(path)
            continue
        if not path.is_dir():
            raise UserInputError(f"{path}: no such file or folder")
        sequences = path / "sequences"
        if sequences.is_dir():
            found = sorted(sequences.rglob("*.yaml"))
        else:
            found = sorted(p for p in path.rglob("*.yaml")
                           if not _NOT_SEQUENCES & set(p.relative_to(path).parts[:-1]))
        found += sorted((path / "poses").glob("*.yaml")) if (path / "poses").is_dir() else []
        if not found:
            raise UserInputError(f"{path}: no sequence files (looked in "
                                 f"{sequences if sequences.is_dir() else path})")
        files.extend(found)
    return list(dict.fromkeys(files))


def override_notes(loaded) -> list[SourceError]:
    """A note for every pose the sequence uses that the campaign's poses/ overrides."""
    from seqrun.arm.poses import pose_overrides
    from seqrun.steps.registry import step_kind

    overrides = pose_overrides(loaded.pose_path or loaded.poses_dir)
    notes, seen = [], set()
    for step in loaded.steps:
        for name in step_kind(step.kind).poses(step.params):  # the pose files it names
            if name in overrides and name not in seen:
                seen.add(name)
                used, hidden = overrides[name]
                notes.append(step.error(f"pose '{name}' is the campaign's {used}, which "
                                        f"overrides {', '.join(str(h) for h in hidden)}",
                                        "pose"))
    return notes


def _sequence(path: Path, options: dict) -> FileResult:
    from seqrun.sequence.checks import static_check
    from seqrun.service.dryrun import dry_run
    from seqrun.defaults import START_POSE

    result = FileResult(str(path), "sequence")
    try:
        check = static_check(path, start=options["start"], arm_file=options["arm_file"],
                             started=options["started"], project_dir=options["project_dir"])
    except (UserInputError, OSError) as exc:
        result.result = "error"
        result.errors.append(str(exc))
        return result
    if check.loaded is not None:
        check.notes = list(check.notes) + override_notes(check.loaded)
    result.errors = [str(e) for e in check.errors]
    result.notes = [f"{n.file}:{n.line}:{n.column}: note: {n.message}" for n in check.notes]
    if not check.valid:
        result.result = "invalid"
        return result
    if options["static"]:
        return result
    faults = options.get("faults") or []
    unknown = [f.spec for f in faults if f.module is not None
               and f.module not in check.arm.module_ids]
    if unknown:
        result.result = "error"
        result.errors.append(f"--sim-fault '{unknown[0]}': the arm has no such module "
                             f"(modules {', '.join(map(str, check.arm.module_ids))})")
        return result
    run = dry_run(check.loaded, check.arm, check.start_deg,
                  start_pose=options["start"] or START_POSE, started=options["started"],
                  speed=options["speed"], faults=faults)
    result.simulated_s = round(run.simulated_s, 2)
    guards = {g.name: g.min_z_mm for g in check.arm.workspace.guards}
    best = math.inf
    for key, z in run.result.min_heights_mm.items():
        guard, point = key.split(":", 1)
        clearance = z - guards.get(guard, 0.0)
        if clearance < best:
            best, result.clearance_mm = clearance, round(clearance, 1)
            result.clearance_at = f"{point} above '{guard}'"
    if not run.passed:
        result.result = "dry run failed"
        result.errors.append(f"dry run {run.result.status}: {run.result.message}")
    return result


def _pose(path: Path, options: dict) -> FileResult:
    from seqrun.arm.description import load_arm
    from seqrun.arm.poses import NOTE_PREFIX, check_pose, load_pose
    from seqrun.sequence.project import project_for

    result = FileResult(str(path), "pose")
    try:
        pose = load_pose(path)
        project = project_for(path.resolve(), options["project_dir"])
        arm = load_arm(options["arm_file"] or project.arm_path(None))
    except SequenceInvalid as exc:
        result.result = "invalid"
        result.errors = [str(e) for e in exc.errors]
        return result
    except (UserInputError, OSError) as exc:
        result.result = "error"
        result.errors.append(str(exc))
        return result
    for finding in check_pose(pose, arm):
        (result.notes if finding.startswith(NOTE_PREFIX) else result.errors).append(
            f"{path}: {finding}")
    if pose.name != path.stem:
        result.errors.append(f"{path}: name '{pose.name}' differs from the file name "
                             f"'{path.stem}' (sequences find poses by file name)")
    if result.errors:
        result.result = "invalid"
    return result


def _arm(path: Path) -> FileResult:
    from seqrun.arm.description import load_arm

    result = FileResult(str(path), "arm")
    try:
        arm = load_arm(path)
    except SequenceInvalid as exc:
        result.result = "invalid"
        result.errors = [str(e) for e in exc.errors]
    except (UserInputError, OSError) as exc:
        result.result = "error"
        result.errors.append(str(exc))
    else:
        result.notes = [f"{n.file}:{n.line}:{n.column}: note: {n.message}" for n in arm.notes]
    return result


def validate_files(paths: list[Path], **options: Any) -> list[FileResult]:
    results = []
    for path in collect(paths):
        kind = _kind(path)
        results.append(_pose(path, options) if kind == "pose" else
                       _arm(path) if kind == "arm" else _sequence(path, options))
    return results


def table(results: list[FileResult]) -> str:
    rows = [("file", "result", "simulated", "lowest guard clearance", "findings")]
    for r in results:
        clearance = "-" if r.clearance_mm is None else f"{r.clearance_mm:.1f} mm ({r.clearance_at})"
        findings = f"{len(r.errors)} error{'s' * (len(r.errors) != 1)}"
        if r.notes:
            findings += f", {len(r.notes)} note{'s' * (len(r.notes) != 1)}"
        rows.append((r.file, r.result, "-" if r.simulated_s is None else f"{r.simulated_s:.2f} s",
                     clearance, findings))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    bad = sum(not r.valid for r in results)
    lines.append(f"{len(results)} file{'s' * (len(results) != 1)}: "
                 + ("all valid" if not bad else f"{bad} not valid"))
    return "\n".join(lines)


def junit(results: list[FileResult]) -> str:
    # (imported here: xml.sax.saxutils pulls in urllib, http and email, which a single
    # file's validation does not need)
    from xml.sax.saxutils import escape, quoteattr

    failures = sum(not r.valid for r in results)
    total = sum(r.simulated_s or 0.0 for r in results)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<testsuites><testsuite name="seqrun validate" tests="{len(results)}" '
             f'failures="{failures}" time="{total:.3f}">']
    for r in results:
        lines.append(f'  <testcase classname={quoteattr(r.kind)} name={quoteattr(r.file)} '
                     f'file={quoteattr(r.file)} time="{r.simulated_s or 0.0:.3f}">')
        if not r.valid:
            text = "\n".join(r.errors) or r.result
            lines.append(f'    <failure message={quoteattr(r.result)}>{escape(text)}</failure>')
        if r.notes:
            lines.append(f"    <system-out>{escape(chr(10).join(r.notes))}</system-out>")
        lines.append("  </testcase>")
    lines.append("</testsuite></testsuites>")
    return "\n".join(lines) + "\n"


def report(results: list[FileResult], *, as_json: bool, junit_file: Path | None) -> bool:
    """Print the summary (and write the JUnit file); True when every file is valid."""
    valid = all(r.valid for r in results)
    if junit_file is not None:
        junit_file.parent.mkdir(parents=True, exist_ok=True)
        junit_file.write_text(junit(results), encoding="utf-8")
    if as_json:
        typer.echo(json.dumps({"valid": valid, "results": [r.as_dict() for r in results]},
                              indent=2, ensure_ascii=False))
        return valid
    for r in results:
        for line in r.errors:
            typer.echo(line)
        for line in r.notes:
            typer.echo(line)
    typer.echo(table(results))
    return valid
