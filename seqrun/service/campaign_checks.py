"""Checking many files at once: every sequence of a campaign (``seqrun validate DIR`` or
several files), each pose file against the arm, each arm file, one result per file.

A sequence gets :func:`seqrun.service.checking.check_sequence` (the static checks and,
unless ``static``, the dry run); a pose file the pose checks against the campaign's arm;
an arm file its own validation. The face prints the results (a table, JSON, JUnit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from seqrun.defaults import EXIT_FAULT
from seqrun.errors import SequenceInvalid, UserInputError

__all__ = ["FileResult", "collect", "validate_files"]

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
    #: The dry run was aborted by a rehearsed ``--sim-fault`` (exit 3, as ``seqrun run``),
    #: the file itself being valid.
    rehearsed_fault: bool = False
    #: The requirement ids the sequence's steps verify (for the campaign's coverage).
    verifies: list[str] = field(default_factory=list)

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


def _sequence(path: Path, options: dict) -> FileResult:
    result = FileResult(str(path), "sequence")
    try:
        from seqrun.service.arms_check import campaign_has_arms

        arms = campaign_has_arms(path, options["project_dir"])
    except (UserInputError, OSError) as exc:
        result.result = "error"
        result.errors.append(str(exc))
        return result
    if arms is not None:
        return _arms_sequence(path, arms, options, result)
    try:
        files = _arm_files(path, options)
    except (UserInputError, OSError) as exc:
        result.result = "error"
        result.errors.append(str(exc))
        return result
    if len(files) > 1:
        return _for_each_arm_file(path, options, files, result)
    return _one_arm_sequence(path, options, result)


def _arm_files(path: Path, options: dict) -> dict[str, Path]:
    """A sequence of one arm in a campaign with several whose arm files differ (no --arm):
    each arm file, by the arms that have it ("A, C"); else {} (the sequence's arm)."""
    from seqrun.service.arm_context import arms_by_arm_file
    from seqrun.service.campaigns import campaign_of

    if options["arm_file"] is not None:
        return {}
    by_file = arms_by_arm_file(campaign_of(path.resolve(), options["project_dir"]))
    return {", ".join(ids): file for file, ids in by_file.items()} if len(by_file) > 1 else {}


def _for_each_arm_file(path: Path, options: dict, files: dict[str, Path],
                       result: FileResult) -> FileResult:
    """Checked against each arm file: valid only when valid for every arm; each finding
    says which arms; the longest dry run and the lowest clearance of all."""
    for arms, file in files.items():
        one = _one_arm_sequence(path, options | {"arm_file": file},
                                FileResult(result.file, result.kind))
        named = f"arm{'s' * (',' in arms)} {arms}"
        if result.valid and not one.valid:
            result.result = one.result
        result.errors += [f"{named}: {e}" for e in one.errors]
        result.notes += [f"{named}: {n}" for n in one.notes]
        result.verifies += one.verifies
        if one.simulated_s is not None:
            result.simulated_s = max(result.simulated_s or 0.0, one.simulated_s)
        if one.clearance_mm is not None and (result.clearance_mm is None
                                             or one.clearance_mm < result.clearance_mm):
            result.clearance_mm, result.clearance_at = (one.clearance_mm,
                                                        f"{one.clearance_at} ({named})")
    return result


def _one_arm_sequence(path: Path, options: dict, result: FileResult) -> FileResult:
    from seqrun.service.checking import check_sequence

    try:
        check = check_sequence(path, start=options["start"], arm_file=options["arm_file"],
                               started=options["started"], project_dir=options["project_dir"],
                               dry_run=not options["static"], speed=options["speed"],
                               faults=options.get("faults") or ())
    except (UserInputError, OSError) as exc:
        result.result = "error"
        result.errors.append(str(exc))
        return result
    result.errors = [str(e) for e in check.errors]
    result.notes = [f"{n.file}:{n.line}:{n.column}: note: {n.message}" for n in check.notes]
    if check.static.loaded is not None:
        result.verifies = [rid for step in check.static.loaded.steps
                           for rid in getattr(step.params, "verifies", None) or ()]
    if not check.static.valid:
        result.result = "invalid"
        return result
    run = check.dry_run
    if run is None:
        return result
    assert check.arm is not None
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
        result.rehearsed_fault = bool(options.get("faults")) and run.result.exit_code == EXIT_FAULT
    return result


def _arms_sequence(path: Path, project: Any, options: dict, result: FileResult) -> FileResult:
    """A sequence of a campaign with several arms (docs/two-arms.md), checked as
    ``seqrun validate FILE`` checks it; the clearance column is the smallest between
    the arms."""
    from seqrun.service.arms_check import check_arms_sequence

    try:
        faults = options.get("faults") or ()
        if faults:
            raise UserInputError("--sim-fault with several arms: validate one file "
                                 "(ARM/SPEC)")
        check = check_arms_sequence(path, project, start=options["start"],
                                    started=options["started"], speed=options["speed"],
                                    dry_run=not options["static"])
    except (UserInputError, OSError) as exc:
        result.result = "error"
        result.errors.append(str(exc))
        return result
    result.errors = [str(e) for e in check.errors]
    result.notes = [f"{n.file}:{n.line}:{n.column}: note: {n.message}" for n in check.notes]
    if check.tracks is not None:
        result.verifies = [rid for track in check.tracks.tracks.values() for step in track.steps
                           for rid in getattr(step.params, "verifies", None) or ()]
    if check.errors:
        result.result = "invalid"
        return result
    if check.between:
        closest = min(check.between, key=lambda b: b.distance_mm)
        result.clearance_mm = round(closest.distance_mm, 1)
        result.clearance_at = f"{closest.pair} (between arms)"
    run = check.dry_run
    if run is not None:
        result.simulated_s = round(run.simulated_s, 2)
        if not run.passed:
            result.result = "dry run failed"
            result.errors += [f"dry run arm {a}: {o.result.status}: {o.result.message}"
                              for a, o in run.outcome.arms.items() if o.result.exit_code]
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


def _requirements(root: Path, results: list[FileResult]) -> FileResult | None:
    """The campaign's requirements.csv as one more result: a note per malformed row and
    per requirement that no sequence of ``results`` verifies (notes: the sequences stay
    valid); None when the campaign has none."""
    from seqrun.runfolder.requirements import (campaign_requirements, read_requirements,
                                               row_error_line)

    path = campaign_requirements(root)
    if path is None:
        return None
    result = FileResult(str(path), "requirements")
    listed, bad_rows = read_requirements(path)
    result.notes = [row_error_line(path, e) for e in bad_rows]
    verified = {rid for r in results for rid in r.verifies}
    result.notes += [f"{path}:{r.line}: requirement '{r.id}' is verified by no sequence"
                     for r in listed if r.id not in verified]
    return result


def _suites_of(folder: Path) -> list[Path]:
    """A campaign folder's suites (docs/suites.md): ``suite.yaml`` and ``suites/*.yaml``."""
    from seqrun.service.suites import is_suite_file

    found = [folder / "suite.yaml"] + (sorted((folder / "suites").glob("*.yaml"))
                                       if (folder / "suites").is_dir() else [])
    return [p for p in found if is_suite_file(p)]


def _suite(path: Path, options: dict) -> tuple[FileResult, set[Path]]:
    """A suite checked as ``seqrun validate SUITE`` checks it (each entry from where the
    one before leaves the arm), and the sequence files it checked that way."""
    from seqrun.service.suites import check_suite, load_suite, several_arms

    result = FileResult(str(path), "suite")
    try:
        suite = load_suite(path)
        why = several_arms(suite, options["project_dir"])
        if why is not None:
            raise UserInputError(why)
        checks = check_suite(suite, start=options["start"], started=options["started"],
                             arm_file=options["arm_file"], speed=options["speed"],
                             project_dir=options["project_dir"],
                             dry_run=not options["static"])
    except SequenceInvalid as exc:
        result.result, result.errors = "invalid", [str(e) for e in exc.errors]
        return result, set()
    except (UserInputError, OSError) as exc:
        result.result, result.errors = "error", [str(exc)]
        return result, set()
    members = {item.path.resolve() for item in suite.entries()}
    simulated = 0.0
    for check in checks:
        found = check.check
        result.errors += [str(e) for e in found.errors] if found is not None else []
        run = found.dry_run if found is not None else None
        if run is not None:
            simulated += run.simulated_s
            if not run.passed:
                result.errors.append(f"{check.item.shown} from {check.start}: dry run "
                                     f"{run.result.status}: {run.result.message}")
        if found is not None and found.loaded is not None:
            result.verifies += [rid for step in found.loaded.steps
                                for rid in getattr(step.params, "verifies", None) or ()]
    result.simulated_s = None if options["static"] else round(simulated, 2)
    result.notes.append(f"{path}: note: its {len(members)} sequence files are checked in "
                        "its order, each from where the one before leaves the arm, not alone")
    if options.get("faults"):
        result.notes.append(f"{path}: note: --sim-fault is not rehearsed in a suite")
    result.result = "valid" if all(c.valid for c in checks) else "invalid"
    return result, members


def validate_files(paths: list[Path], **options: Any) -> list[FileResult]:
    from seqrun.sequence.project import CONFIG_NAME
    from seqrun.service.suites import is_suite_file

    files = collect(paths)
    suites = [p for p in paths if p.is_dir() for p in _suites_of(p)]
    suites += [p for p in files if p not in suites and is_suite_file(p)]
    results = []
    checked: set[Path] = set()   # the sequences a suite checked in its order
    for path in dict.fromkeys(suites):
        result, members = _suite(path, options)
        results.append(result)
        checked |= members
    for path in files:
        if path in suites or path.resolve() in checked:
            continue
        kind = _kind(path)
        results.append(_pose(path, options) if kind == "pose" else
                       _arm(path) if kind == "arm" else _sequence(path, options))
    for folder in dict.fromkeys(p.resolve() for p in paths if p.is_dir()):
        if (folder / CONFIG_NAME).is_file():   # a campaign folder: its requirements' coverage
            found = _requirements(folder, results)
            if found is not None:
                results.append(found)
    return results


