"""Checking a sequence before anything moves, the one way every face asks for it.

:func:`check_sequence` is ``seqrun validate`` of one file: the static checks (every
problem in one pass, ``file:line:col``), the campaign's pose overrides as notes, then the
dry run on the simulator at virtual time. The console's check of a listed sequence is the
same call, from where the arm stands now. :func:`errors_before_bus` and
:func:`check_for_run` are what ``seqrun run`` checks before it opens the bus. Nothing here
prints or exits; nothing reaches a real bus.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from seqrun.defaults import START_POSE
from seqrun.errors import UserInputError

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.results import UntakenBranch
    from seqrun.sequence.checks import StaticCheck
    from seqrun.sequence.loader import LoadedSequence
    from seqrun.sequence.validation import ValidationResult
    from seqrun.service.dryrun import DryRun
    from seqrun.sim.faults import Fault

__all__ = ["RangeProblem", "SequenceCheck", "check_for_run", "check_parameter_ranges",
           "param_options", "check_sequence", "errors_before_bus",
           "override_notes"]


@dataclass
class SequenceCheck:
    """What ``seqrun validate`` found for one sequence: the static checks and, when they
    passed and a dry run was asked for, the dry run."""

    static: StaticCheck
    dry_run: DryRun | None = None

    @property
    def valid(self) -> bool:
        return self.static.valid and (self.dry_run is None or self.dry_run.passed)

    @property
    def loaded(self) -> LoadedSequence | None:
        return self.static.loaded

    @property
    def arm(self) -> ArmDescription | None:
        return self.static.arm

    @property
    def errors(self) -> list:
        return self.static.errors

    @property
    def notes(self) -> list:
        return self.static.notes


def check_sequence(file: Path, *, start: str | None = None,
                   start_deg: Mapping[str, float] | None = None,
                   start_label: str | None = None, arm_file: Path | None = None,
                   started: bool = False, speed: float = 1.0, project_dir: Path | None = None,
                   dry_run: bool = True, faults: Sequence[Fault] = (),
                   report_html: Path | None = None,
                   params: Mapping[str, str] | None = None) -> SequenceCheck:
    """Validate ``file`` (with its includes) against its arm from the start pose ``start``
    (default Park: freshly powered on) or from ``start_deg`` (user degrees: where the arm
    stands), then dry-run it when valid and ``dry_run``, rehearsing the simulator ``faults``. ``start_label`` names the start
    in the dry run's report. Invalid files are findings; input that cannot be used at all
    raises :class:`~seqrun.errors.UserInputError`."""
    from seqrun.sequence.checks import static_check

    static = static_check(file, start=start, start_deg=start_deg, arm_file=arm_file,
                          started=started, speed=speed, project_dir=project_dir,
                          params=params)
    if static.loaded is not None:
        static.notes = list(static.notes) + override_notes(static.loaded, arm_file)
    check = SequenceCheck(static)
    if static.valid and dry_run:
        from seqrun.service.dryrun import dry_run as run_dry

        assert static.loaded is not None and static.arm is not None
        assert static.start_deg is not None
        for fault in faults:  # the simulated arm has the arm file's modules (as run checks)
            if fault.module is not None and fault.module not in static.arm.module_ids:
                raise UserInputError(
                    f"--sim-fault '{fault.spec}': the arm has no module {fault.module} "
                    f"(modules {', '.join(map(str, static.arm.module_ids))})")
        check.dry_run = run_dry(static.loaded, static.arm, static.start_deg,
                                start_pose=start_label or start or START_POSE,
                                started=started, speed=speed, faults=faults,
                                report_html=report_html)
    return check


@dataclass(frozen=True)
class RangeProblem:
    """A parameter at one end of its declared range with which the sequence fails."""

    name: str
    value: Any
    end: str          # "min" or "max"
    message: str      # the first error, or the dry run's verdict

    def __str__(self) -> str:
        from seqrun.steps.sequence_parameters import show_value

        return f"params: {self.name} = {show_value(self.value)} (its {self.end}): {self.message}"


def param_options(options: Sequence[str]) -> dict[str, str]:
    """``--param NAME=VALUE`` options as ``{name: text}`` (their values are parsed by the
    declared types when the sequence is loaded). Raises UserInputError for a bad one."""
    from seqrun.steps.sequence_parameters import parse_options

    return parse_options(options)


def check_parameter_ranges(file: Path, loaded: LoadedSequence, *,
                           untaken: list[UntakenBranch] | None = None,
                           **check: Any) -> list[RangeProblem]:
    """``file`` checked (static and, with ``dry_run``, the dry run) with each numeric
    parameter at its min and at its max in turn, the others at their defaults: at most
    two checks per parameter. ``check``: :func:`check_sequence`'s other arguments.
    ``untaken``: the flow branches the dry run with the defaults did not take; those a
    passing dry run at a range's end took are removed from it (they were run)."""
    from seqrun.steps.sequence_parameters import extremes, show_value

    problems = []
    for name, value, end in extremes(loaded.parameters):
        checked = check_sequence(file, params={name: show_value(value)}, **check)
        run = checked.dry_run
        if untaken and not checked.errors and run is not None and run.passed:
            still = run.result.branches_not_taken
            untaken[:] = [b for b in untaken if any(b.same_branch(s) for s in still)]
        if checked.errors:
            message = str(checked.errors[0])
        elif checked.dry_run is not None and not checked.dry_run.passed:
            result = checked.dry_run.result
            message = (f"the dry run {result.status}"
                       + (f": {result.fault['message']}" if result.fault else ""))
        else:
            continue
        problems.append(RangeProblem(name, value, end, message))
    return problems


def override_notes(loaded: LoadedSequence, arm_path: Path | None = None) -> list:
    """A note for every file the sequence uses in place of a shipped one: each pose the
    campaign's poses/ overrides, an arm file that shadows the shipped arm of its name (its
    guards, tools and limits are not the shipped ones) or lies outside the campaign; and
    for every file or folder it uses from outside the campaign's folder (a pose file or a
    whole poses/ symlinked from elsewhere, ``[runs] dir = ../elsewhere``).
    ``arm_path``: the arm file in use (``--arm``), default the sequence's."""
    from seqrun.arm.poses import pose_overrides
    from seqrun.steps.registry import step_kind

    notes = _arm_notes(loaded, Path(arm_path or loaded.arm_path)) + _outside_notes(loaded) \
        + requirement_notes(loaded)
    overrides = pose_overrides(loaded.pose_path or loaded.poses_dir)
    seen = set()
    for step in loaded.steps:
        for name in step_kind(step.kind).poses(step.params):  # the pose files it names
            if name in overrides and name not in seen:
                seen.add(name)
                used, hidden = overrides[name]
                notes.append(step.error(f"pose '{name}' is the campaign's {used}, which "
                                        f"overrides {', '.join(str(h) for h in hidden)}",
                                        "pose"))
    return notes


def requirement_notes(loaded: LoadedSequence) -> list:
    """A note for each requirement id a step verifies that the campaign's requirements.csv
    does not list (one note when the campaign has none), and for each malformed row of
    it (docs/campaigns.md, "Requirements"). Outside a campaign: none."""
    from seqrun.runfolder.requirements import (REQUIREMENTS_NAME, campaign_requirements,
                                               read_requirements)
    from seqrun.yamlsource import Location, display_path

    project = loaded.project
    if not getattr(project, "is_campaign", False):
        return []
    named = [(step, i, rid) for step in loaded.steps
             for i, rid in enumerate(getattr(step.params, "verifies", None) or ())]
    if not named:
        return []
    root = Path(project.root)
    path = campaign_requirements(root)
    if path is None:
        step = named[0][0]
        return [step.error(f"the steps verify requirements, but the campaign has no "
                           f"{REQUIREMENTS_NAME} (at {root}) to list them", "verifies")]
    listed, bad_rows = read_requirements(path)
    shown = display_path(path)
    notes = [Location(shown, line, 1).error(message) for line, message in bad_rows]
    ids = {r.id for r in listed}
    notes += [step.error(f"requirement '{rid}' is not in {shown}", "verifies", i)
              for step, i, rid in named if rid not in ids]
    return notes


def _outside_notes(loaded: LoadedSequence) -> list:
    """A note for each pose file the steps use (symlinks resolved) and for the runs folder
    of the campaign's ``[runs] dir`` that lie outside the campaign's folder: what a run
    reads or writes there is not kept with the campaign (the arm file: :func:`_arm_notes`;
    includes outside are refused by the loader)."""
    import re

    from seqrun.shipped import shipped_dir
    from seqrun.steps.registry import step_kind
    from seqrun.yamlsource import Location, display_path

    project = loaded.project
    root = Path(getattr(project, "root", loaded.project_root)).resolve()
    what = "the campaign's" if getattr(project, "is_campaign", False) else "the project's"
    shipped = [shipped_dir(kind).resolve() for kind in ("poses", "sequences")]

    def outside(path: Path) -> Path | None:
        try:
            used = Path(path).resolve()
        except (OSError, RuntimeError):
            return None
        if used.is_relative_to(root) or any(used.is_relative_to(s) for s in shipped):
            return None
        return used

    notes = []
    seen: set[str] = set()
    for step in loaded.steps:
        for name in step_kind(step.kind).poses(step.params):
            frozen = loaded.poses.get(name)
            if frozen is None or name in seen:
                continue
            seen.add(name)
            used = outside(frozen.document.path)
            if used is not None:
                given = Path(frozen.document.path)
                via = f" (through the link {given})" if given.absolute() != used else ""
                notes.append(step.error(f"pose '{name}' is read from {used}{via}, outside "
                                        f"{what} folder {root}", "pose"))
    config = getattr(project, "config", None)
    config_path = getattr(project, "config_path", None)
    runs = getattr(getattr(config, "runs", None), "dir", None)
    if runs is not None and config_path is not None:
        used = outside(root / runs)
        if used is not None:
            source = getattr(project, "config_source", b"") or b""
            line = next((n for n, raw in enumerate(source.splitlines(), start=1)
                         if re.match(rb"\s*dir\s*=", raw)), 1)
            notes.append(Location(display_path(Path(config_path)), line, 1).error(
                f"[runs] dir = {runs!r}: run folders are written to {used}, outside "
                f"{what} folder {root}"))
    return notes


def _arm_notes(loaded: LoadedSequence, arm_path: Path) -> list:
    """The note on an arm file that is not the shipped one it looks like."""
    from seqrun.shipped import shipped_arm, shipped_dir
    from seqrun.yamlsource import Location

    try:
        used = arm_path.resolve()
    except (OSError, RuntimeError):
        return []
    if used.is_relative_to(shipped_dir("arms").resolve()):
        return []
    project = loaded.project
    root = Path(getattr(project, "root", loaded.project_root)).resolve()
    what = "the campaign's" if getattr(project, "is_campaign", False) else "the project's"
    shipped = shipped_arm(used.stem)
    if not used.is_relative_to(root):
        text = (f"arm file {used} lies outside {what} folder {root}"
                + (f" and shadows the shipped {shipped}" if shipped is not None else "")
                + ": its guards, tools and limits are used")
    elif shipped is not None:
        text = (f"arm file {used} is {what}, which shadows the shipped {shipped}: its "
                "guards, tools and limits are used")
    else:
        return []
    line = 1
    top = loaded.sources[0] if loaded.sources else b""
    for number, raw in enumerate(top.splitlines(), start=1):
        if raw.startswith(b"arm:"):
            line = number
            break
    return [Location(loaded.file, line, 1).error(text)]


def errors_before_bus(file: Path, load_errors: list, **check: Any) -> list:
    """The errors ``seqrun validate --static`` reports for ``file`` that did not load (its
    load errors and the checks of the steps that loaded), else ``load_errors``."""
    from seqrun.sequence.checks import static_check

    try:
        return static_check(file, **check).errors or load_errors
    except UserInputError:
        return load_errors


def check_for_run(loaded: LoadedSequence, arm: ArmDescription, start: str | None,
                  started: bool, from_step: int) -> ValidationResult:
    """What ``seqrun run`` checks before it opens the bus: validation from the assumed
    start (with ``--from N`` from where step N starts); the executor checks again from
    the measured arm."""
    from seqrun.sequence.checks import static_validation

    return static_validation(loaded, arm, start, started, from_step)
