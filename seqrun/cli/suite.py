"""``seqrun validate SUITE`` and ``seqrun run SUITE``: a test suite (docs/suites.md).

A suite is a YAML file whose top level is ``suite:`` (seqrun/sequence/suite.py); ``seqrun
validate`` and ``seqrun run`` take one in place of a sequence file. The order, the
on-error policy and the reports are the service's (seqrun/service/suites.py); this face
gives the terminal: its lines, its questions, its signals, and runs each sequence as
``seqrun run FILE`` does (the same preparation, the same session run, the same gate).
"""

from __future__ import annotations

import json
from pathlib import Path
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import typer

from seqrun.cli.common import fail
from seqrun.defaults import EXIT_INVALID, EXIT_OK
from seqrun.errors import SequenceInvalid, UserInputError

if TYPE_CHECKING:
    from rich.console import Console

    from seqrun.service.suites import Suite, SuiteCheck, SuiteItem, SuiteRun


def load_or_exit(file: Path, project_dir: Path | None) -> Suite:
    """The suite, or its errors at file:line:col and exit 1 (unreadable: one line, exit 2;
    a campaign of several arms: one line, exit 2)."""
    from seqrun.service.suites import load_suite, several_arms

    try:
        suite = load_suite(file)
    except SequenceInvalid as exc:
        for error in exc.errors:
            typer.echo(str(error), err=True)
        typer.echo(f"{file}: invalid suite ({len(exc.errors)} error"
                   f"{'s' * (len(exc.errors) != 1)}); nothing was sent", err=True)
        raise typer.Exit(EXIT_INVALID) from None
    except UserInputError as exc:
        fail(str(exc))
    try:
        why = several_arms(suite, project_dir)
    except UserInputError as exc:
        fail(str(exc))
    if why is not None:
        fail(why)
    return suite


# --------------------------------------------------------------------------- validate
def validate_suite(file: Path, *, as_json: bool, start: str | None, arm_file: Path | None,
                   static: bool, started: bool, speed: float,
                   project_dir: Path | None, refused: dict[str, bool]) -> None:
    """Check every entry of the suite, each from where the one before leaves the arm; one
    line per entry and the suite's verdict. Exit as ``seqrun validate``: 0 valid, 1 not."""
    from seqrun.service.suites import check_suite

    given = [option for option, used in refused.items() if used]
    if given:
        fail(f"{', '.join(given)}: not for a suite (its entries say their params)")
    suite = load_or_exit(file, project_dir)

    def each(check: SuiteCheck) -> None:
        if as_json:
            return
        for error in (check.check.errors if check.check is not None else []):
            typer.echo(str(error))
        typer.echo(_check_line(check))

    if not as_json:
        typer.echo(f"{suite.file}: suite '{suite.name}': {_shape(suite)}")
    try:
        checks = check_suite(suite, start=start, started=started, arm_file=arm_file,
                             speed=speed, project_dir=project_dir, dry_run=not static,
                             each=each)
    except UserInputError as exc:
        fail(str(exc))
    valid = all(c.valid for c in checks)
    unchecked = _not_checked(suite, static)
    if as_json:
        typer.echo(json.dumps({"valid": valid, "suite": suite.name, "file": suite.file,
                               "entries": [_check_dict(c) for c in checks],
                               "not_checked": unchecked}, indent=2, ensure_ascii=False))
    else:
        for line in unchecked:
            typer.echo(f"  not checked: {line}")
        bad = sum(not c.valid for c in checks)
        typer.echo(f"{suite.file}: " + ("valid" if valid else "invalid") +
                   f" ({len(checks)} check{'s' * (len(checks) != 1)}"
                   + (f", {bad} not valid)" if bad else ")"))
    raise typer.Exit(EXIT_OK if valid else EXIT_INVALID)


def _shape(suite: Suite) -> str:
    parts = [f"{len(suite.sequences)} sequence{'s' * (len(suite.sequences) != 1)}"]
    parts += [f"{role} {item.shown}" for role, item in (("setup", suite.setup),
                                                         ("teardown", suite.teardown)) if item]
    parts += [f"loop {suite.loop}", f"on_error {suite.on_error}"]
    return ", ".join(parts)


def _role(item: SuiteItem) -> str:
    return f"#{item.index}" if item.role == "sequence" else item.role


def _check_line(check: SuiteCheck) -> str:
    verdict = "valid" if check.valid else "INVALID"
    run = check.check.dry_run if check.check is not None else None
    dry = "" if run is None else (f", dry run {'passed' if run.passed else 'FAILED'} "
                                  f"{run.simulated_s:.2f} s"
                                  + ("" if run.passed else f": {run.result.message}"))
    errors = len(check.check.errors) if check.check is not None else 0
    found = f", {errors} error{'s' * (errors != 1)}" if errors else ""
    return f"  {_role(check.item):9s} {check.item.shown}: {verdict} from {check.start}{dry}{found}"


def _check_dict(check: SuiteCheck) -> dict[str, Any]:
    run = check.check.dry_run if check.check is not None else None
    return {"role": check.item.role, "index": check.item.index, "file": check.item.shown,
            "params": check.item.params, "valid": check.valid, "start": check.start,
            "errors": [e.as_dict() for e in (check.check.errors if check.check else [])],
            "dry_run": run.as_dict() if run is not None else None}


def _not_checked(suite: Suite, static: bool) -> list[str]:
    """What validation of a suite does not show (said, never implied)."""
    lines = []
    if static:
        lines.append("--static: no dry run; each entry is checked from where the plans of "
                     "the one before leave the arm (not where a simulated run leaves it)")
    if suite.loop > 1:
        lines.append(f"loops 3-{suite.loop} start where loop 2 does (the last sequence's "
                     "end): not checked again" if suite.loop > 2 else
                     "the second loop is checked from the last sequence's end for its first "
                     "sequence only; the rest follow as in the first loop")
    lines.append("a sequence after a failed one (on_error: continue) starts from where "
                 "the failure left the arm: the run checks that from the measured state")
    return lines


# -------------------------------------------------------------------------------- run
def run_suite_file(file: Path, *, yes: bool, log_dir: Path | None,
                   no_report: bool, speed: float, command_mode: str | None,
                   rt_priority: int | None, project_dir: Path | None,
                   zero_confirmed: list[str], request_options: dict[str, Any],
                   refused: dict[str, bool]) -> None:
    """``seqrun run SUITE``: every sequence loaded and checked before the bus is opened,
    then one arm session for the whole suite; each sequence through the same run path
    as ``seqrun run FILE``. Its lines are the plain ones (one per step), whatever the
    terminal: the suite's own lines go between them."""
    from seqrun.cli.common import user_errors, zero_confirmed_of
    from seqrun.cli.output import keep_running_on_broken_pipe, make_console
    from seqrun.cli.run_start import (confirm_start_or_record, refuse_yes_for_attended,
                                      use_realtime, watchdog_at_real_time)
    from seqrun.service.run_preparation import RunInvalid, RunRequest, prepare_run
    from seqrun.service.suites import load_entry, param_texts

    given = [option for option, used in refused.items() if used]
    if given:
        fail(f"{', '.join(given)}: not for a suite yet (run its sequences one by one)")
    suite = load_or_exit(file, project_dir)
    keep_running_on_broken_pipe()
    confirmed = zero_confirmed_of(zero_confirmed, [None]).get(None)
    console = make_console(stderr=False)
    plan = suite.plan()
    loaded: dict[tuple[str, int], Any] = {}
    run = None
    with user_errors():
        # Every entry loads before anything is opened (its errors, exit 1, nothing sent);
        # the first is prepared as seqrun run prepares a file: checked, then the bus opened.
        first = plan[0]
        for item in [i for i in suite.entries() if i.key != first.key] + [first]:
            request = RunRequest(item.path, speed=speed, command_mode=command_mode,
                                 project_dir=project_dir, params=[
                                     f"{k}={v}" for k, v in param_texts(item).items()],
                                 **request_options)
            try:
                if item is first:
                    run = prepare_run(request)
                    loaded[item.key] = run.loaded
                else:
                    loaded[item.key] = load_entry(
                        item, project_dir=project_dir, start=request.start,
                        arm_file=request.arm_file, started=request.started, speed=speed)
            except RunInvalid as exc:
                for error in exc.errors:
                    typer.echo(str(error), err=True)
                typer.echo(f"{suite.file}: {item.shown}: {exc}", err=True)
                _close(run)
                raise typer.Exit(EXIT_INVALID) from None
            except SequenceInvalid as exc:
                for error in exc.errors:
                    typer.echo(f"error: {error}", err=True)
                typer.echo(f"{suite.file}: {item.shown}: invalid; nothing was sent", err=True)
                _close(run)
                raise typer.Exit(EXIT_INVALID) from None
            except BaseException:
                _close(run)
                raise
    assert run is not None
    for sequence in loaded.values():
        refusal = refuse_yes_for_attended(
            sequence, yes, run.hazards if sequence is run.loaded else None)
        if refusal is not None:
            run.connection.close()
            fail(refusal)
    from seqrun.service.run_control import RunControl
    from seqrun.stop_requests import StopRequests

    requests = StopRequests()
    control = RunControl.serve(run.connection, run.arm, requests)
    zero = confirm_start_or_record(console, run, yes, None, confirmed,
                                   what=f"suite '{suite.name}' ({len(plan)} sequence runs)")
    if use_realtime(console, rt_priority, bool(request_options.get("virtual_time"))):
        watchdog_at_real_time(console, run)
    folder = _suite_folder(suite, run, log_dir)
    outcome = _run_in_one_session(console, suite, run, zero, folder, control, requests,
                                  loaded, yes=yes, speed=speed, command_mode=command_mode,
                                  no_report=no_report)
    try:
        _print_suite_outcome(console, outcome, folder)
    except KeyboardInterrupt:
        pass
    raise typer.Exit(outcome.exit_code)


def _close(run) -> None:
    if run is not None:
        run.connection.close()


def _suite_folder(suite: Suite, run, log_dir: Path | None) -> Path:
    from seqrun.service import campaign_records
    from seqrun.service.suites import suite_folder

    try:
        return suite_folder(suite, log_dir, campaign_records.runs_dir(run.loaded))
    except OSError as exc:
        run.connection.close()
        fail(f"cannot create the suite's folder: {exc.strerror or exc}; nothing was sent")


def _run_in_one_session(console: Console, suite: Suite, run, zero, folder: Path, control,
                        requests, loaded: dict, *, yes: bool, speed: float,
                        command_mode: str | None, no_report: bool):
    """One arm session for the whole suite; each sequence through the session's
    ``run_loaded`` (the path of ``seqrun run FILE``), its own run folder and records."""
    from seqrun.cli.display import PlainDisplay
    from seqrun.cli.interrupts import RunSignals
    from seqrun.cli.questions import ask
    from seqrun.cli.run_start import Attended, ask_shown
    from seqrun.service import ArmSession, campaign_records
    from seqrun.service.suites import SuiteRun, run_of, run_suite, write_suite_reports

    connection, arm = run.connection, run.arm
    signals = RunSignals(requests)
    session = ArmSession(arm, connection, project=run.loaded.project, zero=zero,
                         status_hz=0, own_connection=False)

    def say(text: str, end: str = "\n") -> None:
        console.print(text, end=end, highlight=False, markup=False, soft_wrap=True)

    def one(item: SuiteItem, where: Path) -> SuiteRun:
        import time

        sequence = loaded[item.key]
        try:
            where.mkdir(parents=True, exist_ok=False)
            campaign_records.record_run(where, sequence, run.arm_path,
                                        connection.description, zero, arm=arm,
                                        overrides=run.overrides, arm_id=run.arm_id)
        except OSError as exc:
            return SuiteRun(item, "failed", EXIT_INVALID,
                            f"cannot write the run record in {where} "
                            f"({exc.strerror or exc}); nothing was sent")
        # (PlainDisplay reads an event by its keys, as events.jsonl has it)
        lines: Callable[[Any], None] = PlainDisplay(console, len(sequence.steps))
        displays: list = [session.events.add_listener(lines, "plain display",
                                                      maxsize=100_000)]
        began = time.time()
        try:
            outcome = session.run_loaded(
                sequence, log_dir=where, file=str(item.path), speed=speed,
                command_mode=command_mode,
                confirm=lambda prompt: ask_shown(console, displays, prompt, yes,
                                                  read=signals.read_answer),
                attended=Attended(console, displays, signals.read_answer),
                run_control=control, requests=requests,
                warn=lambda text: say(f"  !!  {text}"),
                confirm_clear_latched=(None if connection.is_simulator else
                                       lambda q: ask_shown(console, displays, q, False,
                                                            read=signals.read_answer)),
                meta={"zero": zero.as_dict(), "suite": suite.name,
                      "suite_entry": item.location},
                html_report=not no_report,
                record_zero=(None if connection.is_simulator or zero.store is None
                             else campaign_records.zero_recorder(zero.store, arm, sequence)))
        finally:
            displays[0].close(timeout=5.0)   # every line printed before the next
        return run_of(item, outcome.result, where, began)

    def ask_continue(failed: SuiteRun) -> bool:
        # on_error: pause. Never answered by --yes: a person decides whether to go on.
        return ask(f"{failed.item.shown} failed ({failed.message}). Continue the suite "
                   "with the next sequence?", False, say=say, read=signals.read_answer)

    from seqrun.cli import interrupts

    interrupts.progress.started = True
    signals.install()
    try:
        outcome = run_suite(suite, folder, one, ask_continue=ask_continue,
                            told=lambda text, _o: say(text))
        interrupts.progress.exit_code = outcome.exit_code   # before the handlers go
        error = write_suite_reports(folder, outcome)
        if error:
            say(f"warning: the suite's report was not written ({error})")
        return outcome
    finally:
        try:
            session.close()
            connection.close()
        finally:
            signals.restore()


def _print_suite_outcome(console: Console, outcome, folder: Path) -> None:
    from rich.text import Text

    try:
        colour = "green" if outcome.exit_code == 0 else "red"
        counts = (f"{outcome.passed} passed, {outcome.failed} failed, "
                  f"{outcome.not_run} not run")
        console.print(Text.assemble((f"SUITE {outcome.verdict.upper()}", colour),
                                    f" (exit {outcome.exit_code}): {outcome.suite.name}: "
                                    f"{counts}"), highlight=False)
        console.print(f"suite folder: {folder} (junit.xml, ctrf.json; one folder per run)",
                      highlight=False, markup=False, soft_wrap=True)
    except (OSError, ValueError):
        pass
