"""``seqrun run FILE``: run a sequence on the arm (or the built-in simulator).

Exit codes: 0 success, 1 invalid sequence (no motion), 2 usage error, 3 aborted by a fault,
timeout or failed checkpoint (arm halted), or by SIGHUP / SIGQUIT (Halt), 130 operator abort
(controlled stop; a second Ctrl-C or SIGTERM halts instead). Signals: cli/interrupts.py;
before the run starts (its questions) SIGTERM, SIGHUP and SIGQUIT end it with exit 130,
nothing sent (cli/questions.py).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from seqrun.cli import interrupts
from seqrun.cli.app import app
from seqrun.cli.common import (BitrateOption, BusKwargsOption, ChannelOption, InterfaceOption,
                               OneArmOption, SimOption, ZeroConfirmedPerArmOption, fail,
                               user_errors, zero_confirmed_of)
from seqrun.cli.foxglove_option import FoxgloveOption, FoxgloveTypes, FoxgloveTypesOption
from seqrun.cli.run_start import (Attended, ask_shown, confirm_start_or_record,
                                  refuse_yes_for_attended, use_realtime, watchdog_at_real_time)
from seqrun.defaults import EXIT_INVALID, EXIT_OPERATOR_ABORT
from seqrun.errors import SequenceInvalid

if TYPE_CHECKING:
    from rich.console import Console


def _ctrl_c_outside_the_run_is_an_operator_abort(command):
    """Before the run's own signal handlers are in place (validation, opening the bus, the
    REAL-arm question), Ctrl-C is a KeyboardInterrupt: one line, exit 130 (click would say
    "Aborted!", exit 1: the code of an invalid sequence). After they are gone the run's
    verdict stands: its exit code, nothing more said (its lines and run folder tell)."""
    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        progress = interrupts.new_run()
        try:
            return command(*args, **kwargs)
        except KeyboardInterrupt:
            if progress.exit_code is not None:
                raise typer.Exit(progress.exit_code) from None
            if progress.started:
                typer.echo("seqrun run: interrupted (Ctrl-C) after the run started; its run "
                           "folder says what was sent", err=True)
            else:
                typer.echo("seqrun run: interrupted (Ctrl-C) while the arm was not moving; "
                           "nothing was sent", err=True)
            raise typer.Exit(EXIT_OPERATOR_ABORT) from None
    return wrapper


@app.command("run")
@_ctrl_c_outside_the_run_is_an_operator_abort
def run_command(
    file: Annotated[Path, typer.Argument(help="Sequence file (YAML).")],
    interface: InterfaceOption = None,
    channel: ChannelOption = None,
    bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None,
    sim: SimOption = False,
    sim_fault: Annotated[Optional[list[str]], typer.Option(
        "--sim-fault", metavar="SPEC", help="Inject a simulator fault, MODULE:KIND@SECONDS "
        "(e.g. 4:tow_error@2.5, all:halt@3, 3:drop_acks=0.3@0); repeatable.")] = None,
    speed: Annotated[float, typer.Option("--speed", help="Scale velocities and accelerations, "
                                                         "0 < F <= 1.")] = 1.0,
    step: Annotated[bool, typer.Option("--step", help="Ask before each step.")] = False,
    from_step: Annotated[int, typer.Option("--from", metavar="N", help="Start at step N "
                                           "(after checking the arm is where N expects it).")] = 1,
    yes: Annotated[bool, typer.Option("--yes", "-y", help="Do not ask before moving a real "
                                      "arm; answer yes to confirm steps (never to a signed "
                                      "confirm, a breakpoint, an on_fail: pause or a hazardous "
                                      "step: "
                                      "refused).")] = False,
    log_dir: Annotated[Optional[Path], typer.Option("--log-dir", metavar="DIR",
                                                    help="Run folder (default runs/<time>-<name>/).")] = None,
    arm_file: Annotated[Optional[Path], typer.Option("--arm", metavar="FILE",
                                                     help="Arm file (default: the sequence's).")] = None,
    command_mode: Annotated[Optional[str], typer.Option(
        "--command-mode", help="ramp (TargetVel + FRAMP, default) or step (FSTEP).")] = None,
    plain: Annotated[bool, typer.Option("--plain", help="Plain line output instead of the "
                                                        "live view.")] = False,
    start: Annotated[Optional[str], typer.Option(
        "--start", metavar="POSE", help="Pose the static validation assumes the arm starts in "
        "(default park: freshly powered on). The run re-validates from the measured state.")] = None,
    started: Annotated[bool, typer.Option(
        "--started", help="Static validation assumes the modules are already reset, homed "
                          "and limited (sequences without the start-up).")] = False,
    rt_priority: Annotated[Optional[int], typer.Option(
        "--rt-priority", metavar="N", min=1, max=99,
        help="Run the control loop with real-time scheduling (SCHED_FIFO priority N; needs "
             "the right to, e.g. root or CAP_SYS_NICE). Keeps the 100 Hz loop on time on a "
             "busy host.")] = None,
    virtual_time: Annotated[bool, typer.Option(
        "--virtual-time", help="Simulator only: run in virtual time, as fast as possible "
                               "(full run folder; used by CI and the tests).")] = False,
    project_dir: Annotated[Optional[Path], typer.Option(
        "--project", metavar="DIR", help="Campaign folder (default: the nearest seqrun.toml "
                                         "above the sequence).")] = None,
    power_on_at: Annotated[Optional[str], typer.Option(
        "--power-on-at", metavar="POSE", help="Simulator only: the power-off pose the "
        "simulated arm was powered on at (default park); it is the run's zero reference.")]
    = None,
    no_report: Annotated[bool, typer.Option(
        "--no-report", help="Do not draw report.html after the run (bulk runs; "
                            "'seqrun report RUN_DIR' draws it later).")] = False,
    zero_confirmed: ZeroConfirmedPerArmOption = None,
    foxglove: FoxgloveOption = None,
    foxglove_types: FoxgloveTypesOption = None,
    arm_id: OneArmOption = None,
    param: Annotated[Optional[list[str]], typer.Option(
        "--param", metavar="NAME=VALUE", help="A value of one of the sequence's params "
        "(over its default), checked against its type and range; repeatable.")] = None,
) -> None:
    """Run a sequence: validate, read the arm, re-validate from where it stands, move.
    In a campaign with several arms ([arms.ID]): a sequence that names them runs every arm
    its track, together (docs/two-arms.md; --sim-fault ARM/SPEC); a sequence of one arm runs
    on the arm --arm-id names. A suite file (top level ``suite:``, docs/suites.md) runs
    its sequences one after another in one arm session."""
    from seqrun.service.suites import is_suite_file

    if is_suite_file(file):
        from seqrun.cli.suite import run_suite_file

        run_suite_file(file, yes=yes, log_dir=log_dir, no_report=no_report,
                       speed=speed, command_mode=command_mode, rt_priority=rt_priority,
                       project_dir=project_dir, zero_confirmed=zero_confirmed or [],
                       request_options=dict(
                           interface=interface, channel=channel, bitrate=bitrate,
                           bus_kwargs=bus_kwargs or [], sim=sim, sim_faults=sim_fault or [],
                           arm_file=arm_file, start=start, started=started,
                           virtual_time=virtual_time, power_on_at=power_on_at),
                       refused={"--from": from_step != 1, "--step": step,
                                "--foxglove": foxglove is not None,
                                "--foxglove-types": foxglove_types is not None,
                                "--arm-id": arm_id is not None, "--param": bool(param)})
    with user_errors():
        from seqrun.service.arms_check import campaign_has_arms

        arms_project = campaign_has_arms(file, project_dir) if file.exists() else None
    if arms_project is not None and arm_id is not None:
        fail(f"--arm-id {arm_id}: {file} names the arms it moves (arms "
             f"{', '.join(arms_project.config.arm_ids)}) and runs each; --arm-id is for a "
             "sequence of one arm")
    if arms_project is not None:
        from seqrun.cli.run_arms import run_arms

        run_arms(file, arms_project, sim=sim, sim_fault=sim_fault or [], speed=speed,
                 yes=yes, log_dir=log_dir, start=start, started=started,
                 virtual_time=virtual_time, no_report=no_report, command_mode=command_mode,
                 zero_confirmed=zero_confirmed or [], foxglove=foxglove,
                 foxglove_types=foxglove_types, refused={"--arm": arm_file is not None,
                          "-i/-c/-b/--bus-kwargs": bool(interface or channel or bitrate
                                                        or bus_kwargs),
                          "--from": from_step != 1, "--step": step,
                          "--power-on-at": power_on_at is not None,
                          "--rt-priority": rt_priority is not None,
                          "--param": bool(param)}, plain=plain)
    # Imported here, not at the top: `seqrun --help` and the other commands stay light.
    from seqrun.cli.output import keep_running_on_broken_pipe, make_console
    from seqrun.service.run_preparation import RunInvalid, RunRequest, prepare_run

    keep_running_on_broken_pipe()  # a closed stdout never ends a run
    confirmed = zero_confirmed_of(zero_confirmed, [arm_id]).get(arm_id)  # (a bad one: now)
    console = make_console(stderr=False)
    from seqrun.cli.foxglove_option import check_foxglove

    check_foxglove(foxglove, foxglove_types)   # (one line before anything is opened)
    request = RunRequest(file, interface, channel, bitrate, bus_kwargs or [], sim,
                         sim_fault or [], speed, from_step, log_dir, arm_file, command_mode,
                         start, started, virtual_time, project_dir, power_on_at, arm_id,
                         param or [], assume_yes=yes)
    with user_errors():
        try:
            run = prepare_run(request)   # nothing is opened before the checks pass
        except RunInvalid as exc:
            for error in exc.errors:
                typer.echo(str(error), err=True)
            typer.echo(str(exc), err=True)
            raise typer.Exit(EXIT_INVALID) from None
        except SequenceInvalid as exc:  # it does not even load: the same last line
            for error in exc.errors:
                typer.echo(f"error: {error}", err=True)
            typer.echo(str(RunInvalid(str(file), list(exc.errors))), err=True)
            raise typer.Exit(EXIT_INVALID) from None
    refusal = refuse_yes_for_attended(run.loaded, yes, run.hazards)
    if refusal is not None:
        run.connection.close()
        fail(refusal)
    # From here `seqrun status` / `seqrun halt` in another terminal ask this run.
    from seqrun.service.run_control import RunControl
    from seqrun.stop_requests import StopRequests

    requests = StopRequests()
    control = RunControl.serve(run.connection, run.arm, requests)
    zero = confirm_start_or_record(console, run, yes, log_dir, confirmed)
    if use_realtime(console, rt_priority, virtual_time):
        watchdog_at_real_time(console, run)
    folder = _run_folder(console, run, log_dir)
    outcome = _run_in_session(console, run, zero, folder, control, requests, step=step,
                              yes=yes, plain=plain, speed=speed, from_step=from_step,
                              command_mode=command_mode, no_report=no_report,
                              foxglove=foxglove, foxglove_types=foxglove_types)
    try:  # the run has ended: a Ctrl-C now changes neither its exit code nor its story
        _print_outcome(console, outcome, folder)
    except KeyboardInterrupt:
        pass
    raise typer.Exit(outcome.result.exit_code)


def _run_folder(console: Console, run, log_dir: Path | None) -> Path:
    """An unusable --log-dir: exit 2, nothing sent; a used one gets a new folder inside."""
    from seqrun.errors import UserInputError
    from seqrun.service.run_preparation import run_folder

    try:
        folder = run_folder(run.loaded, log_dir)
    except UserInputError as exc:
        run.connection.close()
        fail(str(exc))
    if log_dir is not None and folder != log_dir:
        console.print(f"{log_dir} holds an earlier run: this run goes to {folder}",
                      highlight=False, markup=False, soft_wrap=True)
    return folder


def _run_in_session(console: Console, run, zero, folder: Path, control, requests, *,
                    step: bool, yes: bool, plain: bool, speed: float, from_step: int,
                    command_mode: str | None, no_report: bool, foxglove: int | None = None,
                    foxglove_types: FoxgloveTypes | None = None):
    """The run in an arm session (the same object the console and the other faces use),
    with the terminal's own questions, signals and displays (the session's subscribers)."""
    from seqrun.cli.display import LiveDisplay, PlainDisplay
    from seqrun.cli.interrupts import RunSignals
    from seqrun.service import ArmSession, campaign_records

    loaded, connection, arm = run.loaded, run.connection, run.arm
    # From here on signals only post stop requests (seqrun/cli/interrupts.py); the control
    # loop acts on them, a question is answered "no".
    signals = RunSignals(requests)
    try:  # the bytes validated, not the files again (one may have changed meanwhile)
        campaign_records.record_run(folder, loaded, run.arm_path, connection.description,
                                    zero, arm=arm, overrides=run.overrides,
                                    arm_id=run.arm_id)
    except OSError as exc:
        connection.close()
        fail(f"cannot write the run record in {folder} ({exc.strerror or exc}); "
             "nothing was sent")
    displays: list = []

    def confirm(prompt: str) -> bool:
        return ask_shown(console, displays, prompt, yes, read=signals.read_answer)

    def confirm_clear_latched(question: str) -> bool:
        # Asked even with --yes: someone may have pressed the emergency stop for a reason.
        return ask_shown(console, displays, question, False, read=signals.read_answer)

    def before_step(s) -> bool:
        if not step:
            return True
        mark = "" if s.title.endswith("?") else "?"
        return ask_shown(console, displays, f"Run step {s.number}/{len(loaded.steps)}: "
                         f"{s.title}{mark}", False, read=signals.read_answer,
                         context=f"step {s.number}/{len(loaded.steps)}: {s.title} (asking)")

    live = console.is_terminal and not plain

    def warn(text: str) -> None:
        console.print(f"  !!  {text}", style="yellow", highlight=False, markup=False,
                      soft_wrap=True)

    session = ArmSession(arm, connection, project=loaded.project, zero=zero, status_hz=0,
                         own_connection=False)
    live_foxglove = _start_foxglove(console, run, session, folder, foxglove, foxglove_types)
    if live:  # its own queue of the session's events, rendered in the loop's slack
        view = LiveDisplay(console, arm, session.subscribe(maxsize=2000, name="live view"),
                           f"seqrun: {loaded.name}", connection.description,
                           len(loaded.steps))
        session.add_idle_hook(view.on_idle)
        displays.append(view.__enter__())
    else:  # its own queue and thread: a blocked stdout never delays the loop
        displays.append(session.events.add_listener(
            PlainDisplay(console, len(loaded.steps)), "plain display", maxsize=100_000))
    interrupts.progress.started = True
    signals.install()
    try:
        outcome = session.run_loaded(
            loaded, log_dir=folder, file=str(run.file), speed=speed, first_step=from_step,
            command_mode=command_mode, confirm=confirm, before_step=before_step,
            attended=Attended(console, displays, signals.read_answer),
            run_control=control, requests=requests, warn=warn,
            confirm_clear_latched=(None if connection.is_simulator else confirm_clear_latched),
            meta={"zero": zero.as_dict(),
                  **({"overrides": [str(n) for n in run.overrides]} if run.overrides
                     else {})},
            html_report=not no_report,
            # The built-in simulator keeps no record: its zero is its power-on pose.
            record_zero=(None if connection.is_simulator or zero.store is None
                         else campaign_records.zero_recorder(zero.store, arm, loaded)))
        interrupts.progress.exit_code = outcome.result.exit_code   # before the handlers go
        return outcome
    finally:
        if live and displays:
            session.remove_idle_hook(displays[0].on_idle)
            displays[0].__exit__(None, None, None)
        elif displays:
            displays[0].close(timeout=5.0)  # every line printed before the summary
        try:
            if live_foxglove is not None:
                live_foxglove.close()
            session.close()
            connection.close()
        finally:  # until here a signal is a request: a Ctrl-C never cuts the closing short
            signals.restore()


def _start_foxglove(console: Console, run, session, folder: Path, port: int | None,
                    types: FoxgloveTypes | None = None):
    """``--foxglove``: the session live for Foxglove before anything moves; a server that
    cannot start ends the command in one line (exit 2), nothing sent."""
    from seqrun.cli.foxglove_option import start_foxglove

    try:
        return start_foxglove(session, run.arm, port,
                              lambda text: console.print(text, highlight=False, markup=False,
                                                         soft_wrap=True), types)
    except (OSError, RuntimeError) as exc:
        from seqrun.service import campaign_records

        session.close()
        run.connection.close()
        message = f"the Foxglove server could not start ({exc}); nothing was sent"
        campaign_records.not_started(run.loaded, run.arm_path, folder, f"not started: {message}",
                                     arm=run.arm, bus=run.connection.description, exit_code=2,
                                     arm_id=run.arm_id)
        fail(f"--foxglove: {message}")


def _print_outcome(console: Console, outcome, folder: Path) -> None:
    """The run's verdict, its errors, its duration and where its log is."""
    from rich.text import Text

    from seqrun.results import latched_message

    result = outcome.result
    try:  # a terminal that is gone (SIGHUP) must not change the exit code
        colour = "green" if result.exit_code == 0 else "red"
        # With a list of errors the message is a summary: each error is printed once, below.
        message = result.extra.get("summary") or result.message
        console.print(Text.assemble((result.status.upper(), colour),
                                    f" (exit {result.exit_code}): {message}"), highlight=False)
        host = (result.fault or {}).get("host") or {}
        if host.get("text"):   # the stalls (a busy host) that came before the fault
            console.print(f"host: {host['text']}", style="yellow", highlight=False,
                          markup=False, soft_wrap=True)
        if result.latched_at_start:
            console.print("note: " + latched_message(result.latched_at_start)
                          + (" - cleared by the sequence's Reset" if result.exit_code == 0
                             else ""),
                          style="yellow", highlight=False, markup=False)
        if result.extra.get("errors"):
            for error in result.extra["errors"]:
                console.print(f"  {error['file']}:{error['line']}:{error['column']}: "
                              f"{error['message']}", highlight=False, markup=False)
        console.print(f"duration {result.duration_s:.2f} s, planned motion "
                      f"{result.planned_duration_s:.2f} s; log: {folder}", highlight=False,
                      markup=False)
        if outcome.report_error:
            console.print(f"warning: report.html not written ({outcome.report_error}); "
                          f"try: seqrun report {folder}", style="yellow", highlight=False,
                          markup=False)
        if outcome.report and outcome.report.get("log_errors"):
            console.print(f"the run log is incomplete: {outcome.report['log_errors'][0]}",
                          style="yellow", highlight=False, markup=False, soft_wrap=True)
    except (OSError, ValueError):
        pass
