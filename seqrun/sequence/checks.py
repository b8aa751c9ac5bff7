"""The checks before anything moves, as the commands run them (no output, no exit codes).

:func:`static_check` is ``seqrun validate --static`` (and the first part of
``seqrun validate``): a file with its includes, its arm and the start pose, every problem
in one pass. :func:`static_validation` is what ``seqrun run`` checks before it opens the
bus, from the assumed start and, with ``--from N``, from where step N starts. The faces
(the CLI today) print what these return. The executor checks again from the measured arm
with :func:`check_from_arm`, which the service hands every executor it makes.
Imports stay inside the functions: importing this module is cheap.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from seqrun.defaults import START_POSE
from seqrun.errors import SequenceInvalid, SourceError, UserInputError

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.sequence.loader import LoadedSequence
    from seqrun.sequence.validation import ValidationResult

__all__ = ["StaticCheck", "static_check", "static_validation"]


@dataclass
class StaticCheck:
    """What ``seqrun validate`` found before any dry run."""

    loaded: LoadedSequence | None = None
    arm: ArmDescription | None = None
    start_deg: dict[str, float] | None = None
    errors: list[SourceError] = field(default_factory=list)
    notes: list[SourceError] = field(default_factory=list)
    #: Smallest guard clearance of each move along its planned trajectory.
    clearances: list = field(default_factory=list)
    #: Smallest link-volume clearance of each move (arm file geometry).
    proximities: list = field(default_factory=list)
    #: The planned path of each move (step number -> (times s, joints rad)).
    paths: dict = field(default_factory=dict, repr=False)
    #: The steps of class caution or hazardous (HazardFinding), in step order.
    hazards: list = field(default_factory=list)
    #: Where the steps leave the joints (user degrees; empty when not validated).
    final_deg: dict[str, float] = field(default_factory=dict)

    @property
    def valid(self) -> bool:
        return not self.errors


def static_check(file: Path, *, start: str | None = None,
                 start_deg: Mapping[str, float] | None = None,
                 arm_file: Path | None = None, started: bool = False,
                 speed: float = 1.0, project_dir: Path | None = None,
                 params: Mapping[str, str] | None = None) -> StaticCheck:
    """Load ``file`` (with includes), its arm and the start pose (``start_deg``: joints in
    user degrees instead, e.g. where the arm stands), and validate statically
    (``params``: the --param texts over the declared defaults).

    Invalid files (the sequence, an included one, the arm file, a pose file) end up in
    ``errors``; input that cannot be used at all raises :class:`UserInputError`.
    """
    from seqrun.arm.description import load_arm
    from seqrun.sequence.loader import load_sequence_partial
    from seqrun.sequence.validation import validate_sequence
    from seqrun.arm.poses import pose_joints_deg
    from seqrun.yamlsource import sort_errors

    check = StaticCheck()
    # Every problem in one pass: the steps that are valid on their own are still checked
    # against the arm when others are not (the loader leaves the broken ones out).
    check.loaded, load_errors = load_sequence_partial(file, project_root=project_dir,
                                                           params=params)
    check.errors = list(load_errors)
    if check.loaded is None:
        return check
    arm_path = arm_file if arm_file is not None else check.loaded.arm_path
    if check.errors and arm_file is None and not Path(arm_path).is_file():
        return check  # the file's own 'arm' is wrong: already among the errors
    if not Path(arm_path).is_file():
        raise UserInputError(f"arm file {arm_path} not found (give one with --arm FILE)")
    try:
        check.arm = load_arm(arm_path)
    except SequenceInvalid as exc:
        check.errors = sort_errors(check.errors + list(exc.errors))
        return check
    pose = start or START_POSE
    try:
        check.start_deg = (dict(start_deg) if start_deg is not None else
                           pose_joints_deg(pose, check.loaded.pose_path or check.loaded.poses_dir))
    except UserInputError as exc:
        raise UserInputError(f"start pose: {exc}"
                             + ("" if start else " (choose one with --start POSE)")) from None
    except SequenceInvalid as exc:
        check.errors = sort_errors(check.errors + list(exc.errors))
        return check
    # The steps left out (check.loaded.left_out) make the checks that depend on them
    # uncertain from there on; every other check is made.
    result: ValidationResult = validate_sequence(check.loaded, check.arm, check.start_deg,
                                                 started=started, speed=speed)
    check.errors = sort_errors(check.errors + result.errors)
    check.notes = check.arm.notes + result.notes
    check.clearances = [result.clearances[n] for n in sorted(result.clearances)]
    check.proximities = [result.proximities[n] for n in sorted(result.proximities)]
    check.paths = dict(result.paths)
    check.hazards = [result.hazards[n] for n in sorted(result.hazards)]
    check.final_deg = dict(result.final_deg)
    return check


def static_validation(loaded: LoadedSequence, arm: ArmDescription, start: str | None,
                      started: bool, from_step: int) -> ValidationResult:
    """Validation from the assumed start (Park, freshly powered on, unless told otherwise).
    With ``--from N`` the steps before N are only tracked, to know where step N starts."""
    from seqrun.sequence.validation import validate_sequence
    from seqrun.arm.poses import pose_joints_deg

    start_deg = pose_joints_deg(start or START_POSE, loaded.pose_path or loaded.poses_dir)
    if from_step == 1:
        return validate_sequence(loaded, arm, start_deg, started=started)
    before, rest = loaded.split_at(from_step)
    tracked = validate_sequence(before, arm, start_deg, started=started)
    return validate_sequence(rest, arm, tracked.final_deg, started=True)


def check_from_arm(loaded: LoadedSequence, arm: ArmDescription, start_deg: dict[str, float],
                   *, first_step: int = 1, started: bool, speed: float,
                   module_limits: Mapping[str, tuple[float, float]]) -> ValidationResult:
    """The run's own check, from where the arm stands (the executor's preflight): the
    steps from ``first_step`` validated from the measured joints ``start_deg`` with the
    limits the drives hold; with ``--from N`` the arm must also stand where the steps
    before N leave it."""
    from seqrun.sequence.validation import validate_sequence

    steps_before, steps_from = loaded.split_at(first_step)  # as `seqrun run --from`
    result = validate_sequence(steps_from, arm, start_deg, started=started, speed=speed,
                               module_limits=module_limits)
    if first_step > 1:
        before = validate_sequence(steps_before, arm)
        tol = max(1.0, 5 * arm.control.position_tolerance_deg)
        for j in arm.joints:
            expected = before.final_deg.get(j.name)
            if expected is not None and abs(expected - start_deg[j.name]) > tol:
                result.errors.append(loaded.steps[first_step - 1].location.error(
                    f"--from {first_step}: the arm is not where this step expects it: "
                    f"{j.name} at {start_deg[j.name]:.2f}°, expected {expected:.2f}° "
                    f"(after steps 1-{first_step - 1})"))
    return result
