"""``seqrun validate`` of a sequence in a campaign with several arms.

The file is split into one track per arm (:mod:`seqrun.sequence.arm_tracks`); each track
is validated against its own arm from the start pose (every check a one-arm sequence
gets); the tracks are put on one planned time line and the arms' volumes checked against
each other along both planned paths in the facility frame
(:mod:`seqrun.sequence.arm_schedule`); then, when all of that passes, the dry run: every
arm's track on a simulated bus of its own, at one virtual time
(:func:`seqrun.service.arms_run.run_tracks` on a :class:`~seqrun.clock.LockstepClock`).
Nothing reaches a real bus. Invalid files are findings; unusable input raises
:class:`~seqrun.errors.UserInputError`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from seqrun.defaults import START_POSE
from seqrun.errors import SequenceInvalid, SourceError

__all__ = ["ArmsCheck", "ArmsDryRun", "addresses_arms", "campaign_has_arms",
           "check_arms_sequence"]


@dataclass
class ArmsDryRun:
    outcome: Any                 # ArmsOutcome
    start_pose: str
    wall_s: float
    faults: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return bool(self.outcome.passed)

    @property
    def simulated_s(self) -> float:
        return max((a.result.duration_s for a in self.outcome.arms.values()), default=0.0)

    def as_dict(self) -> dict[str, Any]:
        return {"passed": self.passed, "start_pose": self.start_pose,
                "simulated_s": round(self.simulated_s, 4), "wall_s": round(self.wall_s, 4),
                "faults": self.faults, "on_fault": self.outcome.on_fault,
                "notes": list(self.outcome.notes),
                "arms": {arm: {"status": a.result.status, "message": a.result.message,
                               "exit_code": a.result.exit_code,
                               "simulated_s": round(a.result.duration_s, 4),
                               "halted_because_arm": a.halted_for,
                               "fault": a.result.fault,
                               "steps": [s.as_dict() for s in a.result.steps]}
                         for arm, a in self.outcome.arms.items()}}


@dataclass
class ArmsCheck:
    """What ``seqrun validate`` found for a sequence of several arms."""

    file: str
    arm_ids: tuple[str, ...] = ()
    tracks: Any = None           # ArmTracks
    arms: dict[str, Any] = field(default_factory=dict)
    errors: list[SourceError] = field(default_factory=list)
    notes: list[SourceError] = field(default_factory=list)
    #: Per arm: the smallest guard clearance / link-volume clearance of each move.
    clearances: dict[str, list] = field(default_factory=dict)
    #: Per arm: its steps of class caution or hazardous (step number -> HazardFinding).
    hazards: dict[str, dict] = field(default_factory=dict)
    proximities: dict[str, list] = field(default_factory=dict)
    #: The smallest clearance between each pair of arms (ArmsClearance).
    between: list = field(default_factory=list)
    dry_run: ArmsDryRun | None = None

    @property
    def valid(self) -> bool:
        return not self.errors and (self.dry_run is None or self.dry_run.passed)

    def as_dict(self) -> dict[str, Any]:
        return {"valid": self.valid, "arms": list(self.arm_ids),
                "errors": [e.as_dict() for e in self.errors],
                "notes": [n.as_dict() for n in self.notes],
                "clearances": {a: [c.as_dict() for c in v] for a, v in self.clearances.items()},
                "proximities": {a: [p.as_dict() for p in v]
                                for a, v in self.proximities.items()},
                "between_arms": [b.as_dict() for b in self.between],
                "dry_run": self.dry_run.as_dict() if self.dry_run is not None else None}


def campaign_has_arms(file: Path, project_dir: Path | None = None) -> Any:
    """The campaign of ``file`` when its ``seqrun.toml`` names arms (``[arms.ID]``) and the
    file addresses them, else None: an ordinary one-arm sequence, or a fragment of a
    campaign with several arms that names no arm (``startup.yaml``, included per arm),
    checked as one arm's sequence against the first arm's arm file."""
    from seqrun.sequence.project import project_for

    project = project_for(Path(file).resolve(), project_dir)
    config = project.config
    if config is None or not config.arm_ids:
        return None
    return project if addresses_arms(Path(file)) else None


def addresses_arms(file: Path) -> bool:
    """Whether a sequence file names arms (``arm:`` in a step, ``parallel:``); one that
    cannot be read is taken as one (its errors come from the arms' loader)."""
    import yaml

    try:
        data = yaml.safe_load(file.read_text(encoding="utf-8"))
    except (OSError, ValueError, yaml.YAMLError):
        return True
    steps = data.get("steps") if isinstance(data, dict) else None
    if not isinstance(steps, list):
        return True
    for item in steps:
        if not isinstance(item, dict):
            continue
        if "arm" in item or "parallel" in item:
            return True
        if any(isinstance(v, dict) and "arm" in v for v in item.values()):
            return True
    return False


def check_arms_sequence(file: Path, project: Any, *, start: str | None = None,
                        started: bool = False, speed: float = 1.0, dry_run: bool = True,
                        faults: Sequence[Any] = ()) -> ArmsCheck:
    """Validate ``file`` for every arm it names, the arms against each other, then dry-run
    them together (see the module doc). ``faults``: simulator faults, ``(arm id, Fault)``
    each (``--sim-fault B/4:tow_error@2``)."""
    from seqrun.arm.poses import pose_joints_deg
    from seqrun.sequence.arm_schedule import ArmPlan, check_arms
    from seqrun.sequence.arm_tracks import load_tracks
    from seqrun.sequence.validation import validate_sequence
    from seqrun.service.arm_context import refuse_shared_buses, resolve_contexts
    from seqrun.service.arms_run import on_fault_of
    from seqrun.service.checking import override_notes
    from seqrun.yamlsource import display_path, sort_errors

    contexts = {str(c.arm_id): c for c in resolve_contexts(project=project)}
    refuse_shared_buses(project, list(contexts.values()))
    check = ArmsCheck(display_path(file), tuple(contexts))
    for arm_id, context in contexts.items():
        try:
            check.arms[arm_id] = context.arm
        except SequenceInvalid as exc:
            check.errors.extend(exc.errors)
    if check.errors:
        return check
    try:
        check.tracks = load_tracks(file, project=project,
                                   arm_paths={a: c.arm_path for a, c in contexts.items()})
    except SequenceInvalid as exc:
        check.errors = list(exc.errors)
        return check
    pose = start or START_POSE
    plans = []
    for arm_id, track in check.tracks.tracks.items():
        arm = check.arms[arm_id]
        start_deg = pose_joints_deg(pose, track.pose_path or track.poses_dir)
        result = validate_sequence(track, arm, start_deg, started=started, speed=speed)
        check.errors += result.errors
        check.notes += [n for n in arm.notes + result.notes  # (files from outside: as one arm's)
                        + override_notes(track, contexts[arm_id].arm_path)
                        if n not in check.notes]
        check.clearances[arm_id] = [result.clearances[n] for n in sorted(result.clearances)]
        check.proximities[arm_id] = [result.proximities[n] for n in sorted(result.proximities)]
        check.hazards[arm_id] = dict(result.hazards)
        plans.append(ArmPlan(arm_id, arm, contexts[arm_id].base_transform(), track, result,
                             start_deg))
    if check.errors:
        check.errors = sort_errors(list(dict.fromkeys(check.errors)))
        return check
    errors, check.between, _ = check_arms(plans)
    check.errors = sort_errors(list(dict.fromkeys(errors)))
    if check.errors or not dry_run:
        return check
    check.dry_run = dry_run_arms(check.tracks.tracks, check.arms,
                                 {p.arm_id: p.start_deg for p in plans}, start_pose=pose,
                                 started=started, speed=speed, faults=faults,
                                 on_fault=on_fault_of(project))
    return check


def dry_run_arms(tracks: dict[str, Any], arms: dict[str, Any],
                 start_deg: dict[str, dict[str, float]], *, start_pose: str = START_POSE,
                 started: bool = False, speed: float = 1.0, faults: Sequence[Any] = (),
                 on_fault: str = "halt_all") -> ArmsDryRun:
    """Every arm's track on a simulated bus of its own, at one virtual time."""
    from seqrun.clock import LockstepClock
    from seqrun.drivers.registry import simulator_positions
    from seqrun.service.arms_run import run_tracks
    from seqrun.service.connection import open_connection
    from seqrun.service.dryrun import prepare_started

    shared = LockstepClock()
    views = {arm_id: shared.view() for arm_id in tracks}
    connections: dict[str, Any] = {}
    try:
        for arm_id in tracks:
            arm = arms[arm_id]
            mine = [f for a, f in faults if a == arm_id]
            connections[arm_id] = open_connection(
                force_sim=True, clock=views[arm_id],
                sim_positions=simulator_positions(arm, start_deg[arm_id]), faults=mine,
                default_bitrate=arm.can.bitrate, python_can=False)
        def start_up(arm_id: str) -> None:
            if started:
                prepare_started(connections[arm_id], arms[arm_id])

        wall = time.perf_counter()

        def bound(arm_id: str, executor: Any) -> None:
            # no sequence makes validation run for ever (as one arm's dry run)
            executor.time_limit_s = arms[arm_id].control.max_dry_run_s

        outcome = run_tracks(tracks, arms, connections, dry_run=True, on_fault=on_fault,
                             on_executor=bound, clock_views=views, before_run=start_up,
                             speed=speed,
                             confirm=None, html_report=False)
        wall = time.perf_counter() - wall
    finally:
        for connection in connections.values():
            connection.close()
    return ArmsDryRun(outcome, start_pose, wall,
                      faults=[f"{a}/{f.spec}" for a, f in faults])
