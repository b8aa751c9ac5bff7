"""``seqrun run FILE`` in a campaign with several arms (docs/two-arms.md).

The same promises as one arm's run: nothing is opened before the sequence passes every
check (each arm's track against its own arm, the arms against each other along the
planned paths); each arm's bus is claimed and its zero reference decided (and on real
hardware after a power-on confirmed) before anything moves; on real hardware the operator
says yes first. Every arm then runs its track on its own executor and thread
(:func:`seqrun.service.arms_run.run_tracks`); one arm's fault halts every arm (each
confirmed by its executor) unless ``on_fault = "halt_faulted"``. Ctrl-C stops every arm
(a controlled stop; a second one halts them), SIGTERM halts them all. ``seqrun halt`` /
``seqrun status`` in another terminal reach each arm's run through its bus claim. The
run folder holds one part per arm (``<run>/A/``, ``<run>/B/``: each a whole run folder),
the run's one run.mcap and arms.json (its one time base). On a terminal a live view with
one status line per arm (seqrun/cli/arms_display.py); into a pipe or file, or with
``--plain``, plain lines: each arm's steps as they start and end, prefixed by the arm.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, NoReturn

import typer

from seqrun.cli.common import fail, user_errors, zero_confirmed_of
from seqrun.defaults import EXIT_FAULT, EXIT_INVALID, EXIT_OPERATOR_ABORT
from seqrun.errors import UserInputError
from seqrun.stop_requests import OPERATOR_HALT, StopRequests


class EveryArm(StopRequests):
    """One inbox the signal handlers post to that hands each request to every arm's
    inbox (lock-free appends, as :class:`StopRequests`)."""

    def __init__(self, inboxes: list[StopRequests]) -> None:
        super().__init__()
        self.inboxes = inboxes

    def abort(self, reason: str) -> None:
        for inbox in self.inboxes:
            inbox.abort(reason)

    def halt(self, reason: str, cause: str = OPERATOR_HALT) -> None:
        for inbox in self.inboxes:
            inbox.halt(reason, cause)


def _arm_faults(specs: list[str], ids: tuple[str, ...]) -> dict[str, list[str]]:
    faults: dict[str, list[str]] = {a: [] for a in ids}
    for spec in specs:
        arm, sep, rest = spec.partition("/")
        if not sep or arm not in ids:
            fail(f"--sim-fault '{spec}': with several arms name the arm first, ARM/SPEC "
                 f"(arms {', '.join(ids)}), e.g. {ids[-1]}/4:tow_error@2")
        faults[arm].append(rest)
    return faults


def run_arms(file: Path, project: Any, *, sim: bool, sim_fault: list[str], speed: float,
             yes: bool, log_dir: Path | None, start: str | None, started: bool,
             virtual_time: bool, no_report: bool, command_mode: str | None,
             refused: dict[str, bool], plain: bool = False,
             zero_confirmed: list[str] | None = None, foxglove: int | None = None,
             foxglove_types: Any = None) -> NoReturn:
    from seqrun.cli.foxglove_option import check_foxglove
    from seqrun.service.arm_context import resolve_context
    from seqrun.service.arms_check import check_arms_sequence

    given = [name for name, used in refused.items() if used]
    if given:
        fail(f"{', '.join(given)}: not for a campaign with several arms (each arm's arm file "
             "and bus are in seqrun.toml)")
    check_foxglove(foxglove, foxglove_types)   # (one line before anything is opened)
    ids = project.config.arm_ids
    faults = _arm_faults(sim_fault, ids)
    confirmed = zero_confirmed_of(zero_confirmed, list(ids))  # a bad value: before anything
    with user_errors():
        check = check_arms_sequence(file, project, start=start, started=started, speed=speed,
                                    dry_run=False)
    if check.errors:  # nothing is opened before the checks pass
        for error in check.errors:
            typer.echo(str(error), err=True)
        count = len(check.errors)
        typer.echo(f"{check.file}: not run: {count} error{'s' * (count != 1)} "
                   "(nothing was sent)", err=True)
        raise typer.Exit(EXIT_INVALID)
    tracks = check.tracks.tracks
    from seqrun.service.attended import first_attended

    for arm_id, track in tracks.items():   # each arm's thread has no one to ask them yet
        found = first_attended(track.steps, check.hazards.get(arm_id))
        if found is not None:
            fail(f"arm {arm_id}: {found}: not in a run of several arms yet (run that arm's "
                 "sequence on its own); nothing was sent")
    for between in check.between:
        typer.echo(f"  {between.text()}")
    with user_errors():
        contexts = {a: resolve_context(project=project, arm_id=a, sim=sim, faults=faults[a])
                    for a in tracks}
        for context in contexts.values():
            context.refuse_private_simulator("run")
    from seqrun.service.checking import override_notes

    for note in dict.fromkeys(n for a, track in tracks.items()   # files used in place of
                              for n in override_notes(track, contexts[a].arm_path)):  # shipped
        typer.echo(f"note: {note}")                               # or from outside: said first
    if virtual_time and not all(c.bus.is_simulator for c in contexts.values()):
        fail("--virtual-time runs on simulators only: every arm's bus must be one")
    clock_views: dict[str, Any] = {}
    connections: dict[str, Any] = {}
    if virtual_time:
        from seqrun.clock import LockstepClock

        shared = LockstepClock()
        clock_views = {a: shared.view() for a in tracks}
    try:
        open_buses(contexts, connections, clock_views)
        arms = _confirm_and_zero(contexts, connections, check, yes, confirmed)
        code = _run_watched(file, check, contexts, connections, arms, clock_views,
                            speed=speed, yes=yes, log_dir=log_dir, no_report=no_report,
                            command_mode=command_mode, plain=plain,
                            foxglove=(foxglove, foxglove_types))
    finally:
        for connection in connections.values():
            connection.close()
    raise typer.Exit(code)


def open_buses(contexts: dict[str, Any], connections: dict[str, Any],
               clock_views: dict[str, Any] | None = None) -> None:
    """Open and claim each arm's bus into ``connections`` (the caller closes what was
    opened, also when one fails). ``seqrun run`` and ``seqrun console`` of several arms."""
    with user_errors():
        for arm_id, context in contexts.items():
            extra = {"clock": clock_views[arm_id]} if clock_views else {}
            connections[arm_id] = context.open_connection(live=True, **extra)


def _confirm_and_zero(contexts, connections, check, yes: bool,
                      confirmed: dict[str | None, str]) -> dict[str, Any]:
    """The banner per arm, the operator's yes on real hardware, each arm's zero
    (``confirmed``: the poses ``--zero-confirmed`` says arms stand in)."""
    from seqrun.cli.questions import ask

    for arm_id, context in contexts.items():
        typer.echo(context.headline(connections[arm_id]))
    real = [a for a, c in connections.items() if not c.is_simulator]
    if real and not ask(f"Run '{check.tracks.name}' on the REAL arms "
                        f"{', '.join(real)}?", yes, say=_say):
        typer.echo("Not started: the operator declined. Nothing was sent.")
        raise typer.Exit(EXIT_OPERATOR_ABORT)
    return decide_zeros(contexts, connections, confirmed)


def decide_zeros(contexts: dict[str, Any], connections: dict[str, Any],
                 confirmed: dict[str | None, str] | None = None
                 ) -> dict[str, tuple[Any, Any]]:
    """Each arm's zero reference, decided as for one arm (after a power-on on real
    hardware the terminal asks per arm, unless ``confirmed`` names the pose that arm
    stands in: ``--zero-confirmed``, checked as for one arm): arm id -> (the arm with it
    applied, the zero). ``seqrun run`` and ``seqrun console`` of several arms."""
    from seqrun.cli.questions import ask
    from seqrun.cli.zero import zero_or_exit

    arms = {}
    for arm_id, context in contexts.items():
        def ask_zero(question: str, arm_id: str = arm_id) -> bool:
            return ask(f"arm {arm_id}: {question}", False, say=_say)

        def show_zero(text: str, arm_id: str = arm_id) -> None:
            typer.echo(f"arm {arm_id}: {text}")

        zero = zero_or_exit(connections[arm_id], context.arm, ask_zero, show_zero,
                            confirmed=(confirmed or {}).get(arm_id), arm_id=arm_id)
        arms[arm_id] = (zero.apply(context.arm), zero)
    return arms


def _say(text: str, end: str = "\n") -> None:
    typer.echo(text, nl=end == "\n")


def _run_watched(file: Path, check, contexts, connections, arms, clock_views, *,
                 foxglove: tuple[int | None, Any], **options: Any) -> int:
    """The run in an arm session per arm, opened first so that ``--foxglove`` serves every
    arm (one server, each arm's topics under its id: seqrun/foxglove/live.py) before
    anything moves; a server that cannot start ends the command in one line (exit 2),
    nothing sent."""
    from seqrun.service.arms_run import open_sessions

    tracks = check.tracks.tracks
    sessions = open_sessions(tracks, {a: arms[a][0] for a in tracks}, connections,
                             {a: arms[a][1] for a in tracks})
    live: list[Any] = []

    def stop_serving() -> None:
        # as soon as every track has ended: no client commands an arm of this run after
        # it (nor between the records' end and the sessions' close)
        while live:
            live.pop().close()

    try:
        port, types = foxglove
        if port is not None:
            live.append(_start_foxglove(sessions, arms, contexts, port, types))
        return _run(file, check, contexts, connections, arms, clock_views,
                    sessions=sessions, tracks_ended=stop_serving, **options)
    finally:
        stop_serving()
        for session in sessions.values():
            session.close()


def _start_foxglove(sessions: dict[str, Any], arms: dict[str, Any],
                    contexts: dict[str, Any], port: int, types: Any) -> Any:
    from seqrun.cli.foxglove_option import start_foxglove
    from seqrun.foxglove.live import LiveArm

    try:
        return start_foxglove(None, None, port, _say, types, arms={
            a: LiveArm(session, arms[a][0], contexts[a].base_transform())
            for a, session in sessions.items()})
    except (OSError, RuntimeError) as exc:
        fail(f"--foxglove: the Foxglove server could not start ({exc}); nothing was sent")


def _run(file: Path, check, contexts, connections, arms, clock_views, *, speed: float,
         yes: bool, log_dir: Path | None, no_report: bool, command_mode: str | None,
         plain: bool = False, sessions: dict[str, Any] | None = None,
         tracks_ended: Callable[[], None] | None = None) -> int:
    from seqrun.cli import interrupts
    from seqrun.cli.interrupts import RunSignals
    from seqrun.cli.questions import ask
    from seqrun.service.arms_records import ArmOfRun, ArmsRunRecords
    from seqrun.service.arms_run import on_fault_of, run_arms_live
    from seqrun.service.run_control import RunControl
    from seqrun.service.run_preparation import run_folder

    tracks = check.tracks.tracks
    first = next(iter(tracks.values()))
    try:
        folder = run_folder(replace(first, name=check.tracks.name), log_dir)
    except UserInputError as exc:
        fail(str(exc))
    inboxes = {a: StopRequests() for a in tracks}
    controls = {a: RunControl.serve(connections[a], arms[a][0], inboxes[a]) for a in tracks}
    # each arm's part, one time base for every arm (their events and traces on one time
    # line) and one run.mcap at the top of the run folder: seqrun/service/arms_records.py
    try:
        records = ArmsRunRecords.start(
            folder, tracks, {a: ArmOfRun(arms[a][0], arms[a][1], contexts[a].arm_path,
                                         connections[a].description,
                                         connections[a].is_simulator, contexts[a].base)
                             for a in tracks},
            connections[next(iter(tracks))].clock, project=check.tracks.project,
            warn=_warn)
    except OSError as exc:
        fail(f"cannot write the run record in {folder} ({exc.strerror or exc}); nothing "
             "was sent")
    lock = threading.Lock()
    view = _live_view(check, {a: arms[a][0] for a in tracks}, plain)

    def confirm(prompt: str) -> bool:
        with lock:  # one question at a time
            if view is None:
                return ask(prompt, yes, say=_say)
            with view.asking():
                return ask(prompt, yes, say=_say)

    printers = {a: _printer(a) if view is None else
                (lambda event, a=a: view(a, event)) for a in tracks}

    def show(arm_id: str, event: Any) -> None:
        printers[arm_id](event)

    signals = RunSignals(EveryArm(list(inboxes.values())))
    interrupts.progress.started = True
    signals.install()
    if view is not None:
        view.__enter__()
    try:
        outcome = _arms_live(run_arms_live, tracks, {a: arms[a][0] for a in tracks},
                             connections, controls=controls, on_event=show,
                             zeros={a: arms[a][1] for a in tracks},
                             on_fault=on_fault_of(check.tracks.project),
                             clock_views=clock_views, speed=speed,
                             confirm=confirm, command_mode=command_mode,
                             html_report=not no_report, requests_by_arm=inboxes,
                             file=str(file), sessions=sessions, **records.run_options(),
                             on_idle=view.on_idle if view is not None else None)
        if outcome is not None:   # before the handlers go: a Ctrl-C now keeps it
            interrupts.progress.exit_code = outcome.exit_code
    finally:
        if view is not None:
            view.__exit__(None, None, None)
        signals.restore()
        try:
            if tracks_ended is not None:
                tracks_ended()
        finally:
            records.close_mcap()
    if outcome is None:
        fail(f"the run ended in an error (every arm was halted); log: {folder}", EXIT_FAULT)
    for arm_id, arm in outcome.arms.items():
        r = arm.result
        why = f" (halted because arm {arm.halted_for} faulted)" if arm.halted_for else ""
        typer.echo(f"arm {arm_id}: {r.status.upper()} (exit {r.exit_code}): {r.message}{why}")
        host = (r.fault or {}).get("host") or {}
        if host.get("text"):   # the host stalls (a busy host) before this arm's fault
            typer.echo(f"arm {arm_id}: host: {host['text']}")
    for note in outcome.notes:
        typer.echo(note)
    records.finish(check, outcome)
    typer.echo(f"log: {folder}")
    return outcome.exit_code


def _live_view(check, arms: dict[str, Any], plain: bool) -> Any:
    """On a terminal (and without --plain): one status line per arm
    (seqrun/cli/arms_display.py); else None: plain lines."""
    from seqrun.cli.output import make_console

    console = make_console(stderr=False)
    if plain or not console.is_terminal:
        return None
    from seqrun.cli.arms_display import ArmsLiveView

    tracks = check.tracks.tracks
    return ArmsLiveView(console, arms, {a: len(t.steps) for a, t in tracks.items()},
                        f"seqrun: {check.tracks.name}")


def _arms_live(run, *args: Any, **kwargs: Any) -> Any:
    """The run; an error outside every step (a bug: each arm's run has halted its arm and
    the others were halted for it) is one line, never a traceback (None)."""
    try:
        return run(*args, **kwargs)
    except Exception as exc:  # noqa: BLE001 - said in one line, the arms are halted
        typer.echo(f"error: {type(exc).__name__}: {exc}", err=True)
        return None


def _warn(text: str) -> None:
    typer.echo(f"warning: {text}", err=True)


def _printer(arm_id: str):
    """Each step's start and end, prefixed by the arm (the executor's listener: one
    short line per step)."""
    from seqrun.cli.display import iteration_text, skipped_text

    def listener(event) -> None:
        kind = event.type
        step = getattr(event, "step", None)
        if kind == "step_started":
            typer.echo(f"[{arm_id}] {event.t:8.2f} s  step {step}: "
                       f"{getattr(event, 'label', '')}{iteration_text(event.as_dict())}")
        elif kind == "step_iteration":
            typer.echo(f"[{arm_id}] {event.t:8.2f} s  step {step}"
                       f"{iteration_text(event.as_dict())}")
        elif kind == "step_skipped":
            typer.echo(f"[{arm_id}] {event.t:8.2f} s  step {step}: {event.label}: "
                       f"{skipped_text(event.as_dict())}")
        elif kind == "step_retry":
            typer.echo(f"[{arm_id}] {event.t:8.2f} s  step {step}: retry {event.attempt}/"
                       f"{event.times} after: {event.message}")
        elif kind == "step_finished" and getattr(event, "status", "passed") != "passed":
            typer.echo(f"[{arm_id}] {event.t:8.2f} s  step {step} {event.status}")
    return listener
