"""``seqrun validate FILE`` in a campaign with several arms (docs/two-arms.md).

Same exit codes and line format as one arm's: the errors (``file:line:col``), the notes,
a summary line, then per arm its guard and link-volume clearances, the smallest clearance
between the arms along their planned paths, and the dry run of every arm at one virtual
time. ``--json`` prints one object (``between_arms``, ``dry_run.arms``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, NoReturn

import typer

from seqrun.cli.common import EXIT_INVALID, EXIT_USAGE, fail, validate_exit_code
from seqrun.errors import UserInputError


def _arm_faults(specs: list[str], arm_ids: tuple[str, ...]) -> list[tuple[str, Any]]:
    """``--sim-fault ARM/SPEC`` as ``(arm, Fault)``; one line, exit 2, for a bad one."""
    from seqrun.service.connection import parse_faults

    faults = []
    for spec in specs:
        arm, sep, rest = spec.partition("/")
        if not sep or arm not in arm_ids:
            fail(f"--sim-fault '{spec}': with several arms name the arm first, ARM/SPEC "
                 f"(arms {', '.join(arm_ids)}), e.g. {arm_ids[-1]}/4:tow_error@2")
        try:
            faults.append((arm, parse_faults([rest])[0]))
        except UserInputError as exc:
            fail(str(exc))
    return faults


def validate_arms(file: Path, project: Any, *, as_json: bool, start: str | None,
                  arm_file: Path | None, static: bool, started: bool, speed: float,
                  faults: list[str], report_file: Path | None) -> NoReturn:
    from seqrun.service.arms_check import check_arms_sequence

    ids = project.config.arm_ids
    if arm_file is not None:
        fail("--arm: each arm of this campaign has its arm file in seqrun.toml ([arms.ID])")
    if report_file is not None:
        fail("--report draws one arm's dry run; a campaign with several arms has none yet "
             "(use --json)")
    parsed = _arm_faults(faults, ids)
    if parsed and static:
        fail("--sim-fault rehearses a fault in the dry run: leave out --static")
    try:
        check = check_arms_sequence(file, project, start=start, started=started, speed=speed,
                                    dry_run=not static, faults=parsed)
    except UserInputError as exc:
        if as_json:
            typer.echo(json.dumps({"valid": False, "errors": [{"message": str(exc)}],
                                   "notes": [], "dry_run": None}, indent=2))
            raise typer.Exit(EXIT_USAGE)
        fail(str(exc))
    except OSError as exc:
        fail(f"{exc.filename}: {exc.strerror or exc}")
    if as_json:
        typer.echo(json.dumps(check.as_dict(), indent=2, ensure_ascii=False))
        raise typer.Exit(_exit_code(check, bool(parsed)))
    for error in check.errors:
        typer.echo(str(error))
    for note in check.notes:
        typer.echo(f"{note.file}:{note.line}:{note.column}: note: {note.message}")
    notes = (f", {len(check.notes)} note{'s' * (len(check.notes) != 1)}"
             if check.notes else "")
    arms = ", ".join(check.arm_ids)
    if check.errors:
        count = len(check.errors)
        typer.echo(f"{check.file}: invalid ({count} error{'s' * (count != 1)}{notes}; "
                   f"arms {arms})")
        raise typer.Exit(EXIT_INVALID)
    tracks = check.tracks.tracks
    counts = ", ".join(f"arm {a} {len(t.steps)} steps" for a, t in tracks.items())
    typer.echo(f"{check.file}: valid ({counts}{notes})")
    for arm_id in tracks:
        for c in check.clearances.get(arm_id, []):
            typer.echo(f"  arm {arm_id} step {c.step}: lowest {c.point.replace('_', '-')} "
                       f"z = {c.z_mm:.1f} mm, {c.margin_mm:+.1f} mm from the '{c.guard}' "
                       f"guard, at {c.t_s:.2f} s of {c.duration_s:.2f} s (planned trajectory)")
        for p in check.proximities.get(arm_id, []):
            a, b = p.pair.split("~", 1)
            typer.echo(f"  arm {arm_id} step {p.step}: closest {a} - {b} "
                       f"{p.distance_mm:.1f} mm (link volumes), at {p.t_s:.2f} s of "
                       f"{p.duration_s:.2f} s")
    for between in check.between:
        typer.echo(f"  {between.text()}")
    run = check.dry_run
    if run is not None:
        verdict = "passed" if run.passed else "FAILED"
        typer.echo(f"dry run from {run.start_pose} (every arm on a simulator of its own, one "
                   f"virtual time): {verdict} - {run.simulated_s:.2f} s simulated in "
                   f"{run.wall_s:.2f} s")
        for arm_id, arm in run.outcome.arms.items():
            r = arm.result
            why = f" (halted because arm {arm.halted_for} faulted)" if arm.halted_for else ""
            typer.echo(f"  arm {arm_id}: {r.status} - {r.message}{why}")
            for s in r.steps:
                took = "not run" if s.duration_s is None else f"{s.duration_s:6.2f} s"
                start_s = "" if s.started is None else f"at {s.started:6.2f} s "
                typer.echo(f"    {s.number:2d} {s.status:7s} {s.label[:46]:46s} {start_s}{took}")
        for note in run.outcome.notes:
            typer.echo(f"  {note}")
    raise typer.Exit(_exit_code(check, bool(parsed)))


def _exit_code(check, rehearsed: bool) -> int:
    run = check.dry_run
    worst = None if run is None else max(
        (a.result.exit_code for a in run.outcome.arms.values()), default=0)
    return validate_exit_code(not check.errors, worst, rehearsed)
