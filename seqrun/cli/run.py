"""``seqrun run FILE``: run a sequence on the arm (or the built-in simulator).

Exit codes: 0 success, 1 invalid sequence (no motion), 2 usage error, 3 aborted by a fault,
timeout or failed checkpoint (arm halted), or by SIGHUP / SIGQUIT (Halt), 130 operator abort
(controlled stop; a second Ctrl-C or SIGTERM halts instead). Signals: cli/interrupts.py.
"""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Callable, Optional

import typer

from seqrun.sequence.checks import static_validation
from seqrun.cli.app import app
from seqrun.cli.common import (BitrateOption, BusKwargsOption, ChannelOption, InterfaceOption,
                               SimOption, fail, load_arm_file, user_errors)
from seqrun.defaults import EXIT_FAULT, EXIT_INVALID, EXIT_OPERATOR_ABORT
from seqrun.errors import BusError, SequenceInvalid

if TYPE_CHECKING:
    from rich.console import Console



def _ask(console: Console, question: str, assume_yes: bool,
         read: Callable[[], str | None] | None = None) -> bool:
    """Ask the operator; EOF on stdin (no operator) is a no. ``read`` returns None when
    a signal interrupted the question (a no as well)."""
    if assume_yes:
        console.print(f"{question} yes (--yes)", highlight=False, markup=False, soft_wrap=True)
        return True
    console.print(f"{question} [y/N] ", end="", highlight=False, markup=False, soft_wrap=True)
    if read is None:
        try:
            answer = sys.stdin.readline()
        except KeyboardInterrupt:
            return False
    else:
        answer = read()
    return answer is not None and answer.strip().lower() in ("y", "yes")


def _ask_shown(console: Console, displays: list, question: str, assume_yes: bool, *,
               read: Callable[[], str | None] | None = None,
               context: str | None = None) -> bool:
    """:func:`_ask` where the operator looks: the live view (if any) is off meanwhile, so
    its redraw cannot erase the question."""
    if not displays or not hasattr(displays[0], "asking"):
        for display in displays:  # the plain lines so far come before the question
            getattr(display, "flush", lambda: None)()
        return _ask(console, question, assume_yes, read)
    with displays[0].asking(context):
        return _ask(console, question, assume_yes, read)


def _all_errors(file: Path, load_errors: list, **check) -> list:
    """The errors `seqrun validate --static` reports for ``file`` (load errors and the
    checks of the steps that loaded), else ``load_errors``."""
    from seqrun.sequence.checks import static_check
    from seqrun.errors import UserInputError

    try:
        return static_check(file, **check).errors or load_errors
    except UserInputError:
        return load_errors


def _ctrl_c_outside_the_run_is_an_operator_abort(command):
    """Before the run's own signal handlers are in place (validation, opening the bus, the
    REAL-arm question) and after they are gone, Ctrl-C is a KeyboardInterrupt: one line,
    exit 130 (click would say "Aborted!", exit 1: the code of an invalid sequence)."""
    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except KeyboardInterrupt:
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
                                      "arm; answer yes to confirm steps.")] = False,
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
) -> None:
    """Run a sequence: validate, read the arm, re-validate from where it stands, move."""
    # Imported here, not at the top: `seqrun --help` and the other commands stay light.
    from rich.text import Text

    from seqrun.cli import campaign_records
    from seqrun.cli.display import LiveDisplay, PlainDisplay
    from seqrun.cli.output import keep_running_on_broken_pipe, make_console
    from seqrun.cli.zero import zero_at_run_start
    from seqrun.clock import VirtualClock
    from seqrun.service.connection import open_connection, parse_bus_kwargs, parse_faults
    from seqrun.cli.interrupts import RunSignals
    from seqrun.results import latched_message
    from seqrun.service.runlog import prepare_run_folder
    from seqrun.sequence.loader import load_sequence
    from seqrun.service import ArmSession
    from seqrun.service.run_control import RunControl
    from seqrun.stop_requests import StopRequests

    keep_running_on_broken_pipe()  # a closed stdout never ends a run
    console = make_console(stderr=False)
    with user_errors():
        if not 0 < speed <= 1:
            fail(f"--speed must lie in (0, 1], got {speed:g}")
        if command_mode not in (None, "ramp", "step"):
            fail(f"--command-mode must be ramp or step, got '{command_mode}'")
        if not file.is_file():
            fail(f"sequence file {file} not found")
        faults = parse_faults(sim_fault or [])
        extra = parse_bus_kwargs(bus_kwargs or [])
        try:
            loaded = load_sequence(file, project_root=project_dir)  # invalid -> exit 1, no bus
        except SequenceInvalid as exc:
            # Every problem in one pass, exactly as `seqrun validate` reports them: the
            # steps that are valid on their own are still checked against the arm.
            errors = _all_errors(file, exc.errors, start=start, arm_file=arm_file,
                                 started=started, speed=speed, project_dir=project_dir)
            campaign_records.refuse_unloadable(file, project_dir, errors, log_dir)
            raise SequenceInvalid(errors) from None
        arm = load_arm_file(arm_file or loaded.arm_path)
        if power_on_at is not None:
            arm.power_off_pose(power_on_at)  # one of the arm's power-off poses
        if not (interface or channel or bitrate or extra or sim):  # the campaign's bus
            interface, channel, bitrate, extra = campaign_records.campaign_bus(loaded, extra)
        if not 1 <= from_step <= len(loaded.steps):
            fail(f"--from {from_step}: the sequence has steps 1-{len(loaded.steps)}")
        # Static validation before the bus is even opened; the executor validates again
        # from the measured state before the first motion.
        static = static_validation(loaded, arm, start, started, from_step)
        if static.errors:
            campaign_records.refuse(loaded, arm_file or loaded.arm_path, static.errors, log_dir)
            for error in static.errors:
                typer.echo(str(error), err=True)
            typer.echo(f"{loaded.file}: invalid ({len(static.errors)} error"
                       f"{'s' * (len(static.errors) != 1)}); nothing was sent", err=True)
            raise typer.Exit(EXIT_INVALID)
        if virtual_time and not (sim or faults or not (interface or channel or extra)):
            fail("--virtual-time needs the simulator")
        for fault in faults:  # the simulated arm has the arm file's modules
            if fault.module is not None and fault.module not in arm.module_ids:
                fail(f"--sim-fault '{fault.spec}': the arm has no module {fault.module} "
                     f"(modules {', '.join(map(str, arm.module_ids))})")
        connection = open_connection(interface=interface, channel=channel, bitrate=bitrate,
                                     bus_kwargs=extra, force_sim=sim, faults=faults,
                                     default_bitrate=arm.can.bitrate,
                                     clock=VirtualClock() if virtual_time else None,
                                     power_on_pose=power_on_at.lower() if power_on_at else None)
        if virtual_time and not connection.is_simulator:
            connection.close()
            fail("--virtual-time needs the simulator")
        if power_on_at is not None and not connection.is_simulator:
            connection.close()
            fail("--power-on-at applies to the built-in simulator (seqrun sim serve has its own)")
    # From here `seqrun status` / `seqrun halt` in another terminal ask this run.
    requests = StopRequests()
    control = RunControl.serve(connection, arm, requests)
    style = "bold black on yellow" if connection.is_simulator else "bold white on red"
    console.print(f" {connection.description} ", style=style, highlight=False, markup=False)
    if not connection.is_simulator and not _ask(
            console, f"Run '{loaded.name}' on the REAL arm?", yes):
        console.print("Not started: the operator declined. Nothing was sent.")
        connection.close()
        raise typer.Exit(EXIT_OPERATOR_ABORT)
    # The modules' zeros are where they were powered off: use (and on real hardware after
    # a power-on, confirm) the recorded pose's offsets before anything moves.
    try:
        with user_errors():
            try:
                zero = zero_at_run_start(connection, arm, loaded.project,
                                         lambda question: _ask(console, question, yes),
                                         lambda text: console.print(text, style="bold",
                                                                    highlight=False,
                                                                    markup=False))
            except BusError as exc:  # before user_errors: a timeout is no usage error
                fail(f"cannot read the modules' state: {exc}", EXIT_FAULT)
            arm = arm.with_zero_reference(zero.pose)
    except BaseException:
        connection.close()
        raise

    if rt_priority is not None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt_priority))
            console.print(f"real-time scheduling: SCHED_FIFO priority {rt_priority}",
                          highlight=False)
        except (OSError, AttributeError) as exc:
            console.print(f"warning: real-time scheduling not available ({exc}); running at "
                          "normal priority", style="yellow", highlight=False, markup=False)
    try:  # an unusable --log-dir: exit 2, nothing sent; a used one gets a new folder inside
        folder = prepare_run_folder(log_dir, loaded.name, campaign_records.runs_dir(loaded))
    except OSError as exc:
        connection.close()
        fail(f"cannot create the run folder {log_dir or campaign_records.runs_dir(loaded)}: "
             f"{exc.strerror or exc}")
    if log_dir is not None and folder != log_dir:
        console.print(f"{log_dir} holds an earlier run: this run goes to {folder}",
                      highlight=False, markup=False, soft_wrap=True)

    # From here on signals only post stop requests (seqrun/cli/interrupts.py); the control
    # loop acts on them, a question is answered "no".
    signals = RunSignals(requests)

    campaign_records.record_run(folder, loaded, arm_file or loaded.arm_path,
                                connection.description, zero)
    displays: list = []

    def confirm(prompt: str) -> bool:
        return _ask_shown(console, displays, prompt, yes, read=signals.read_answer)

    def confirm_clear_latched(question: str) -> bool:
        # Asked even with --yes: someone may have pressed the emergency stop for a reason.
        return _ask_shown(console, displays, question, False, read=signals.read_answer)

    def before_step(s) -> bool:
        if not step:
            return True
        mark = "" if s.title.endswith("?") else "?"
        return _ask_shown(console, displays, f"Run step {s.number}/{len(loaded.steps)}: "
                          f"{s.title}{mark}", False, read=signals.read_answer,
                          context=f"step {s.number}/{len(loaded.steps)}: {s.title} (asking)")

    live = console.is_terminal and not plain

    def warn(text: str) -> None:
        console.print(f"  !!  {text}", style="yellow", highlight=False, markup=False,
                      soft_wrap=True)

    # The arm session owns the bus for the run (the same object the console and the other
    # faces use); the terminal's questions stay the terminal's own. The displays are the
    # session's subscribers.
    session = ArmSession(arm, connection, project=loaded.project, zero=zero, status_hz=0,
                         own_connection=False)
    if live:  # its own queue of the session's events, rendered in the loop's slack
        view = LiveDisplay(console, arm, session.subscribe(maxsize=2000, name="live view"),
                           f"seqrun: {loaded.name}", connection.description,
                           len(loaded.steps))
        session.add_idle_hook(view.on_idle)
        displays.append(view.__enter__())
    else:  # its own queue and thread: a blocked stdout never delays the loop
        displays.append(session.events.add_listener(
            PlainDisplay(console, len(loaded.steps)), "plain display", maxsize=100_000))
    signals.install()
    try:
        outcome = session.run_loaded(
            loaded, log_dir=folder, file=str(file), speed=speed, first_step=from_step,
            command_mode=command_mode, confirm=confirm, before_step=before_step,
            run_control=control, requests=requests, warn=warn,
            confirm_clear_latched=(None if connection.is_simulator else confirm_clear_latched),
            meta={"zero": zero.as_dict()}, html_report=not no_report,
            # The built-in simulator keeps no record: its zero is its power-on pose.
            record_zero=(None if connection.is_simulator
                         else campaign_records.zero_recorder(arm, loaded)))
    finally:
        if live and displays:
            session.remove_idle_hook(displays[0].on_idle)
            displays[0].__exit__(None, None, None)
        elif displays:
            displays[0].close(timeout=5.0)  # every line printed before the summary
        signals.restore()
        session.close()
        connection.close()
    result = outcome.result
    try:  # a terminal that is gone (SIGHUP) must not change the exit code
        colour = "green" if result.exit_code == 0 else "red"
        # With a list of errors the message is a summary: each error is printed once, below.
        message = result.extra.get("summary") or result.message
        console.print(Text.assemble((result.status.upper(), colour),
                                    f" (exit {result.exit_code}): {message}"), highlight=False)
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
    raise typer.Exit(result.exit_code)
