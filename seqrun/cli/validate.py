"""``seqrun validate FILE`` and ``seqrun schema``.

    seqrun validate sequences/opsafe.yaml            # exit 0 valid, 1 invalid, 2 bad input
    seqrun validate opsafe.yaml --sim-fault 4:tow_error@3   # exit 3: the rehearsed fault halted it
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
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from seqrun.cli.app import app
from seqrun.cli.common import EXIT_FAULT, EXIT_USAGE, OneArmOption, fail
from seqrun.cli.common import validate_exit_code as exit_code
from seqrun.defaults import START_POSE
from seqrun.errors import UserInputError


def print_report(check, file: Path, *, as_json: bool) -> None:
    if as_json:
        typer.echo(json.dumps({"valid": check.valid,
                               "errors": [e.as_dict() for e in check.errors],
                               "notes": [n.as_dict() for n in check.notes],
                               "clearances": [c.as_dict() for c in check.clearances],
                               "proximities": [p.as_dict() for p in check.proximities],
                               **_hazards(check)},
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
        print_clearances(check)
    else:
        count = len(check.errors)
        typer.echo(f"{name}: invalid ({count} error{'s' * (count != 1)}{notes})")


def _hazards(check) -> dict:
    """The steps of class caution or hazardous, only when there are any (a sequence without
    them reports exactly as before)."""
    found = getattr(check, "hazards", None)
    return {"hazards": [h.as_dict() for h in found]} if found else {}


def print_clearances(check) -> None:
    """Per move: the smallest guard clearance along its planned trajectory, and where."""
    for c in check.clearances:
        typer.echo(f"  step {c.step}: lowest {c.point.replace('_', '-')} z = {c.z_mm:.1f} mm, "
                   f"{c.margin_mm:+.1f} mm from the '{c.guard}' guard, at {c.t_s:.2f} s of "
                   f"{c.duration_s:.2f} s (planned trajectory)")
    for p in check.proximities:
        a, b = p.pair.split("~", 1)
        typer.echo(f"  step {p.step}: closest {a} - {b} {p.distance_mm:.1f} mm (link volumes), "
                   f"at {p.t_s:.2f} s of {p.duration_s:.2f} s")
    for h in getattr(check, "hazards", ()):  # the steps of class caution or hazardous
        typer.echo(f"  {h.line()}")


def print_dry_run(run, loaded, arm) -> None:
    """Human report of a dry run: per step planned vs simulated, peaks, heights, checks."""
    r = run.result
    verdict = "passed" if run.passed else f"FAILED ({r.status})"
    rehearsed = f", rehearsing {', '.join(run.faults)}" if run.faults else ""
    typer.echo(f"dry run from {run.start_pose} (simulator, virtual time, {run.cycle_hz:g} Hz "
               f"loop{rehearsed}): {verdict} - {run.simulated_s:.2f} s simulated in "
               f"{run.wall_s:.2f} s ({run.speedup:.0f}x real time)")
    arm_limits = {j.name: j.max_velocity_deg_s for j in arm.joints}
    includes: tuple[str, ...] = ()
    for s in r.steps:
        resolved = loaded.steps[s.number - 1] if 0 < s.number <= len(loaded.steps) else None
        chain = resolved.include_labels if resolved is not None else ()
        for depth, title in enumerate(chain):
            if includes[:depth + 1] != chain[:depth + 1]:
                typer.echo(f"     {'  ' * depth}{_cut(title, 60)}")
        includes = chain
        planned = "" if s.planned_duration_s is None else f"planned {s.planned_duration_s:6.2f} s, "
        took = "not run" if s.duration_s is None else f"simulated {s.duration_s:6.2f} s"
        label = ("  " * len(chain) + s.label)
        typer.echo(f"  {s.number:2d} {s.status:7s} {_cut(label, 44):44s} {planned}{took}")
        if s.detail.get("hazard"):
            scale = s.detail.get("hazard_speed_scale", 1.0)
            capped = f"; speed capped at {scale * 100:g} %" if scale < 1 else ""
            typer.echo(f"       hazard: {s.detail['hazard']} — {s.detail.get('hazard_reason')}"
                       f"{capped}")
        in_force = s.detail.get("limits_in_force") or {}
        peak = s.detail.get("peak_measured_velocity_deg_s")
        if peak:
            limits = {n: in_force.get(n, {}).get("max_velocity_deg_s", arm_limits[n])
                      for n in arm_limits}
            moving = [f"{n} {v:.1f}/{limits[n]:g}"
                      for n, v in zip(arm.joint_names, peak) if v > 0.05]
            typer.echo(f"       peak joint velocity (deg/s, of limit): {', '.join(moving)}")
        if "ik_solution_deg" in s.detail:
            solved = ", ".join(f"{n} {v:.3f}" for n, v in zip(arm.joint_names,
                                                              s.detail["ik_solution_deg"]))
            typer.echo(f"       joint solution (deg): {solved}")
        if "moved_mm" in s.detail:
            d = s.detail
            typer.echo(f"       relative checkpoint: the tool moved {d['moved_mm']} mm "
                       f"({d['frame']} frame), expected {d['expected_moved_mm']}: "
                       f"{d['displacement_error_mm']} mm off (tolerance "
                       f"{d['position_tolerance_mm']} mm)")
        if "max_deviation_mm" in s.detail:
            typer.echo(f"       straight line: {s.detail['length_mm']} mm, largest deviation "
                       f"{s.detail['max_deviation_mm']} mm")
        for name, bound in in_force.items():
            typer.echo(f"       limits in force for {name}: {bound['max_velocity_deg_s']:g} deg/s "
                       f"({bound['velocity_from']}), {bound['max_acceleration_deg_s2']:g} "
                       f"deg/s^2 ({bound['acceleration_from']})")
        if "position_error_mm" in s.detail:
            d = s.detail
            typer.echo(f"       checkpoint: expected {d['expected_position_mm']} mm, reached "
                       f"{d['reached_position_mm']} mm: {d['position_error_mm']} mm / "
                       f"{d['angle_error_deg']} deg (tolerance {d['position_tolerance_mm']} mm / "
                       f"{d['angle_tolerance_deg']} deg)")
    guards = {g.name: g.min_z_mm for g in arm.workspace.guards}
    for key, z in r.min_heights_mm.items():
        guard, point = key.split(":", 1)
        typer.echo(f"  lowest {point}: {z:.1f} mm above the base plane (guard '{guard}': "
                   f"{guards.get(guard, float('nan')):g} mm)")
    for b in r.extra.get("blocks", []):
        failed = f" (step {b['failed_step']} failed)" if "failed_step" in b else ""
        shown = f" ({b['label']})" if b["label"] != "block" else ""
        typer.echo(f"  block {b['block']}{shown} at {b['location']}: {b['status']}{failed}")
    if r.fault:
        typer.echo(f"  fault: {r.fault['message']}")
    for error in r.extra.get("errors", []):
        typer.echo(f"{error['file']}:{error['line']}:{error['column']}: {error['message']}")
    unverified = run.as_dict()["not_verified"]
    if unverified:
        # what this one path of the dry run could not show: the branches it did not take
        # among them
        typer.echo("  not verified:")
    for item in unverified:
        typer.echo(f"    - {item}")


def _is_dir(path: Path) -> bool:
    try:
        return path.is_dir()
    except OSError:  # a name the system refuses: reported when the file is read
        return False
def _unusable(message: str, as_json: bool) -> None:
    """Input that cannot be used at all: exit 2, with --json as a JSON object too."""
    if as_json:
        typer.echo(json.dumps({"valid": False, "errors": [{"message": message}], "notes": [],
                               "dry_run": None}, indent=2, ensure_ascii=False))
        raise typer.Exit(EXIT_USAGE)
    fail(message)


def _faults(specs: list[str]) -> list:
    """``--sim-fault`` specs as faults (one line, exit 2, for a bad one)."""
    from seqrun.service.connection import parse_faults

    try:
        return parse_faults(specs)
    except UserInputError as exc:
        fail(str(exc))


def _arm_file_of(arm_id: str | None, arm_file: Path | None, file: Path,
                 project_dir: Path | None, as_json: bool) -> Path | None:
    """The arm file a sequence of one arm is checked against: ``--arm``, else in a
    campaign with several arms, arm ``arm_id``'s (none named: the one they share)."""
    from seqrun.service.arm_context import one_arm_file
    from seqrun.service.campaigns import campaign_of

    if arm_file is not None:
        if arm_id is not None:
            fail("--arm-id names the arm file (seqrun.toml's [arms.ID]): leave out --arm")
        return arm_file
    try:
        if not file.is_file():
            return None  # (said where the file is read)
        return one_arm_file(campaign_of(file.resolve(), project_dir), arm_id)
    except UserInputError as exc:
        _unusable(str(exc), as_json)
    except OSError:  # a name the system refuses: said where the file is read, too
        pass
    return None


def _cut(text: str, width: int) -> str:
    """``text`` in at most ``width`` characters; a cut one ends in "…"."""
    return text if len(text) <= width else text[:width - 1] + "…"


@app.command("validate")
def validate_command(
    files: Annotated[list[Path], typer.Argument(
        metavar="FILE|DIR...", help="Sequence file(s), pose files, or campaign folder(s): "
                                    "several give one summary table.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    start: Annotated[str | None, typer.Option(
        "--start", metavar="POSE",
        help=f"Pose the arm starts in (default {START_POSE}: a freshly powered-on arm).")] = None,
    arm_file: Annotated[Path | None, typer.Option(
        "--arm", metavar="FILE",
        help="Arm description file (default: the sequence's 'arm', else arms/lwa3.yaml under "
             "the project root).")] = None,
    static: Annotated[bool, typer.Option(
        "--static", help="Only the static checks, no dry run.")] = False,
    started: Annotated[bool, typer.Option(
        "--started", help="The modules are already reset, homed and limited (for sequences "
                          "that do not include the start-up).")] = False,
    speed: Annotated[float, typer.Option("--speed", help="Speed override of the dry run, "
                                                         "0 < F <= 1.")] = 1.0,
    sim_fault: Annotated[list[str] | None, typer.Option(
        "--sim-fault", metavar="SPEC", help="Rehearse a simulator fault in the dry run, as "
        "seqrun run --sim-fault injects it: MODULE:KIND@SECONDS from the start (e.g. "
        "4:tow_error@2.5, all:halt@3, 3:drop_acks=0.3@0); with several arms ARM/SPEC (B/4:tow_error@2); repeatable.")] = None,
    junit_file: Annotated[Path | None, typer.Option(
        "--junit", metavar="FILE", help="Also write a JUnit report (one test per file; "
                                        "gives the summary table).")] = None,
    project_dir: Annotated[Path | None, typer.Option(
        "--project", metavar="DIR", help="Campaign folder (default: the nearest seqrun.toml "
                                         "above each file).")] = None,
    report_file: Annotated[Path | None, typer.Option(
        "--report", metavar="FILE", help="Write the dry run's report (HTML, plots, "
                                         "self-contained) to FILE.")] = None,
    arm_id: OneArmOption = None,
    param: Annotated[list[str] | None, typer.Option(
        "--param", metavar="NAME=VALUE", help="Check with this value of one of the "
        "sequence's params (over its default); repeatable. Without any, the declared range "
        "of every numeric parameter is checked too (at its min and at its max).")] = None,
) -> None:
    """Check a sequence file and its includes against the arm, then dry-run it on the
    simulator at virtual time. Nothing is sent to a real bus.

    Exit 0 if valid, 1 if not, 2 if the input cannot be used, 3 if a rehearsed
    --sim-fault aborted the dry run (as it aborts seqrun run).
    """
    if not 0 < speed <= 1:
        fail(f"--speed must lie in (0, 1], got {speed:g}")
    if len(files) == 1:
        from seqrun.service.suites import is_suite_file

        if is_suite_file(files[0]) and junit_file is not None:
            fail(f"--junit: {files[0]} is a suite; its junit.xml is written by seqrun run "
                 "(validate --junit reports sequence files and campaign folders)")
        if is_suite_file(files[0]):   # a suite (top level suite:): each entry in turn
            from seqrun.cli.suite import validate_suite

            validate_suite(files[0], as_json=as_json, start=start, arm_file=arm_file,
                           static=static, started=started, speed=speed,
                           project_dir=project_dir,
                           refused={"--sim-fault": bool(sim_fault),
                                    "--report": report_file is not None,
                                    "--param": bool(param), "--arm-id": arm_id is not None})
    given = _given_params(param or [], files, junit_file)
    if len(files) == 1 and not _is_dir(files[0]) and junit_file is None:
        file = files[0]
        try:
            from seqrun.service.arms_check import campaign_has_arms

            arms_project = campaign_has_arms(file, project_dir)
        except UserInputError as exc:
            _unusable(str(exc), as_json)
            return
        except OSError:
            arms_project = None  # said below, where the file is read
        if arms_project is not None and arm_id is not None and file.is_file():
            fail(f"--arm-id {arm_id}: {file} names the arms it moves and is checked for "
                 "each; --arm-id is for a sequence of one arm")
        if arms_project is not None and given:
            fail(f"--param: not for a sequence of several arms yet ({file})")
        if arms_project is not None:
            from seqrun.cli.validate_arms import validate_arms

            validate_arms(file, arms_project, as_json=as_json, start=start, arm_file=arm_file,
                          static=static, started=started, speed=speed, faults=sim_fault or [],
                          report_file=report_file)
    if len(files) == 1 and not _is_dir(files[0]):  # one arm of several: its arm file
        arm_file = _arm_file_of(arm_id, arm_file, files[0], project_dir, as_json)
    faults = _faults(sim_fault or [])
    if faults and static:
        fail("--sim-fault rehearses a fault in the dry run: leave out --static")
    if report_file is not None and (static or not report_file.parent.is_dir()
                                    or len(files) != 1 or _is_dir(files[0])):
        fail("--report draws the dry run: leave out --static" if static
             else "--report draws one sequence's dry run: give one sequence file"
             if len(files) != 1 or _is_dir(files[0])
             else f"--report {report_file}: no directory {report_file.parent}")
    if len(files) != 1 or _is_dir(files[0]) or junit_file is not None:
        from seqrun.cli.campaign_validate import report
        from seqrun.service.campaign_checks import validate_files

        import time

        began = time.time()
        try:
            results = validate_files(files, start=start, arm_file=arm_file, started=started,
                                     static=static, speed=speed, faults=faults,
                                     project_dir=project_dir)
            valid = report(results, as_json=as_json, junit_file=junit_file, began_s=began)
        except UserInputError as exc:
            fail(str(exc))
        except OSError as exc:
            fail(f"{exc.filename}: {exc.strerror or exc}")
        faulted = [r for r in results if r.rehearsed_fault]
        raise typer.Exit(exit_code(all(r.valid or r.rehearsed_fault for r in results),
                                   EXIT_FAULT if faulted else None, True))
    from seqrun.service.checking import check_sequence

    file = files[0]
    try:
        checked = check_sequence(file, start=start, arm_file=arm_file, started=started,
                                 speed=speed, project_dir=project_dir, dry_run=not static,
                                 faults=faults, report_html=report_file, params=given)
        ranges = _range_problems(file, checked, given, start=start, arm_file=arm_file,
                                 started=started, speed=speed, project_dir=project_dir,
                                 dry_run=not static)
    except UserInputError as exc:
        _unusable(str(exc), as_json)
        return
    except OSError as exc:  # a path the system refuses (name too long, permission, ...)
        _unusable(f"{exc.filename}: {exc.strerror or exc}", as_json)
        return
    check, run = checked.static, checked.dry_run
    if run is not None and run.report_error:
        fail(f"cannot write the report: {run.report_error}")
    valid = checked.valid and not ranges
    if as_json:
        typer.echo(json.dumps({"valid": valid,
                               "errors": [e.as_dict() for e in check.errors]
                               + [{"message": str(p)} for p in ranges],
                               "notes": [n.as_dict() for n in check.notes],
                               "clearances": [c.as_dict() for c in check.clearances],
                               "proximities": [p.as_dict() for p in check.proximities],
                               **_hazards(check),
                               "dry_run": run.as_dict() if run is not None else None,
                               **_values(check.loaded)},
                              indent=2, ensure_ascii=False))
    else:
        print_report(check, file, as_json=False)
        if run is not None:
            print_dry_run(run, check.loaded, check.arm)
        if run is not None and report_file is not None:
            typer.echo(f"report: {report_file}")
        for problem in ranges:
            typer.echo(str(problem))
        if ranges:
            count = len(ranges)
            typer.echo(f"{file}: invalid over its declared params ({count} value"
                       f"{'s' * (count != 1)} failed)")
    raise typer.Exit(exit_code(check.valid and not ranges,
                               None if run is None else run.result.exit_code, bool(faults)))


def _given_params(options: list[str], files: list[Path], junit_file: Path | None) -> dict:
    """``--param`` options as {name: text}: for one sequence file (one line, exit 2)."""
    from seqrun.service.checking import param_options

    if options and (len(files) != 1 or _is_dir(files[0]) or junit_file is not None):
        fail("--param gives a value to one sequence's parameter: give one sequence file")
    try:
        return param_options(options)
    except UserInputError as exc:
        fail(str(exc))


def _range_problems(file: Path, checked, given: dict, **check) -> list:
    """Without --param, a sequence that is valid with its defaults is checked at each
    end of every numeric parameter's range too."""
    from seqrun.service.checking import check_parameter_ranges

    if given or not checked.valid or checked.loaded is None:
        return []
    run = checked.dry_run
    if run is None:
        return check_parameter_ranges(file, checked.loaded, **check)
    # the branches the defaults' dry run did not take: a dry run at a range's end may
    # take them; what no dry run took stays listed as not verified
    untaken = list(run.result.branches_not_taken)
    problems = check_parameter_ranges(file, checked.loaded, untaken=untaken, **check)
    taken = {b.line for b in run.result.branches_not_taken} - {b.line for b in untaken}
    run.result.not_verified = [item for item in run.result.not_verified if item not in taken]
    return problems


def _values(loaded) -> dict:
    """``{"params": the values checked}`` of a sequence that declares any, else {}."""
    values = dict(loaded.param_values) if loaded is not None else {}
    return {"params": values} if values else {}


class SchemaKind(str, Enum):
    sequence = "sequence"
    arm = "arm"
    pose = "pose"


@app.command("schema")
def schema_command(
    kind: Annotated[SchemaKind, typer.Argument(
        help="Which file format: sequence (default), arm or pose.")] = SchemaKind.sequence,
    markdown: Annotated[bool, typer.Option(
        "--markdown", help="Print the format's reference in Markdown instead (for sequences: "
                           "docs/sequence-format.md).")] = False,
) -> None:
    """Print the JSON Schema of a file format (sequence files by default)."""
    from seqrun.service.formats import format_reference, format_schema

    if markdown:
        typer.echo(format_reference(kind.value), nl=False)
        return
    typer.echo(json.dumps(format_schema(kind.value), indent=2, ensure_ascii=False))
