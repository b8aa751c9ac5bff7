"""The start of a run at the terminal, shared by ``seqrun run FILE`` and ``seqrun run
SUITE`` (cli/run.py, cli/suite.py): the operator's questions (shown where the live view
is), who answers signed confirms and breakpoints, the REAL arm's yes and the zero
reference, real-time scheduling.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable

import typer

from seqrun.defaults import EXIT_OPERATOR_ABORT

if TYPE_CHECKING:
    from rich.console import Console


def _ask(console: Console, question: str, assume_yes: bool,
         read: Callable[[], str | None] | None = None) -> bool:
    """Ask the operator (cli/questions.py); EOF on stdin (no operator) is a no, said on
    the question's line. ``read`` returns None when a signal interrupted the question (a
    no as well)."""
    from seqrun.cli.questions import ask

    def say(text: str, end: str = "\n") -> None:
        console.print(text, end=end, highlight=False, markup=False, soft_wrap=True)

    return ask(question, assume_yes, say=say, read=read)


def ask_shown(console: Console, displays: list, question: str, assume_yes: bool, *,
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


class Attended:
    """Signed confirms, breakpoints and on_fail: pause on the terminal: asked of the
    person there, even
    with --yes (which the run refuses beforehand: :func:`refuse_yes_for_attended`)."""

    #: Where its answers come from (an on_fail: pause's operator_choice event says).
    where = "terminal"

    def __init__(self, console: Console, displays: list,
                 read: Callable[[], str | None]) -> None:
        self.console, self.displays, self.read = console, displays, read

    def sign(self, prompt: str, role: str | None) -> str | None:
        from seqrun.cli.questions import ask_name

        as_what = f" [signed by the {role}]" if role else " [signed]"
        if not ask_shown(self.console, self.displays, f"{prompt}{as_what}", False,
                         read=self.read):
            return None

        def say(text: str, end: str = "\n") -> None:
            self.console.print(text, end=end, highlight=False, markup=False, soft_wrap=True)

        if self.displays and hasattr(self.displays[0], "asking"):
            with self.displays[0].asking(None):
                return ask_name(role, say=say, read=self.read)
        return ask_name(role, say=say, read=self.read)

    def breakpoint(self, prompt: str) -> bool:
        return ask_shown(self.console, self.displays, prompt, False, read=self.read)

    def choose(self, prompt: str, choices: tuple[str, ...]) -> str | None:
        from seqrun.cli.questions import ask_choice

        def say(text: str, end: str = "\n") -> None:
            self.console.print(text, end=end, highlight=False, markup=False, soft_wrap=True)

        if self.displays and hasattr(self.displays[0], "asking"):
            with self.displays[0].asking(None):
                return ask_choice(prompt, choices, say=say, read=self.read)
        for display in self.displays:  # the plain lines so far come before the question
            getattr(display, "flush", lambda: None)()
        return ask_choice(prompt, choices, say=say, read=self.read)


def refuse_yes_for_attended(loaded, yes: bool, hazards=None) -> str | None:
    """--yes answers plain confirm steps only: a sequence with a signed confirm or a
    breakpoint (or a hazardous step: ``hazards``, the validation's classes by step number)
    needs a person at the run, so --yes refuses it before anything is sent (why, in one
    line; None: nothing to refuse)."""
    from seqrun.service.attended import yes_refusal

    return yes_refusal(loaded.steps, hazards) if yes else None


def confirm_start_or_record(console: Console, run, yes: bool, log_dir: Path | None,
                            zero_confirmed: str | None = None, what: str | None = None):
    """:func:`_confirm_start`, where SIGTERM, SIGHUP or SIGQUIT at a question (the REAL
    arm's, the zero reference's) end the command in one line, exit 130, and a run not
    started (a no, a signal) leaves a run folder saying that nothing was sent."""
    from seqrun.cli.questions import QuestionInterrupted, signals_end_the_question
    from seqrun.service import campaign_records

    def record(message: str) -> None:
        campaign_records.not_started(run.loaded, run.arm_path, log_dir, message,
                                     arm=run.arm, bus=run.connection.description,
                                     arm_id=run.arm_id)

    try:
        with signals_end_the_question():
            return _confirm_start(console, run, yes, zero_confirmed, what)
    except QuestionInterrupted as exc:
        run.connection.close()  # (closing twice is harmless)
        record(f"not started: {exc.name} before the run started; nothing was sent")
        typer.echo(f"seqrun run: {exc.name} before the run started; nothing was sent",
                   err=True)
        raise typer.Exit(EXIT_OPERATOR_ABORT) from None
    except typer.Exit as exc:
        if exc.exit_code == EXIT_OPERATOR_ABORT:  # the operator said no
            record("not started: the operator declined; nothing was sent")
        raise


def _confirm_start(console: Console, run, yes: bool, zero_confirmed: str | None = None,
                   what: str | None = None):
    """The bus banner, on real hardware the operator's yes, and the zero reference in
    force (on real hardware after a power-on, confirmed); the arm of the run gets it."""
    from seqrun.cli.zero import zero_or_exit

    connection, loaded = run.connection, run.loaded
    what = what or f"'{loaded.name}'"   # a suite names itself
    style = "bold black on yellow" if connection.is_simulator else "bold white on red"
    headline = run.context.headline(connection) if run.context else connection.description
    console.print(f" {headline} ", style=style, highlight=False, markup=False, soft_wrap=True)
    for note in run.overrides:  # files used in place of shipped ones: said before any yes
        console.print(f"note: {note}", style="yellow", highlight=False, markup=False,
                      soft_wrap=True)
    if not connection.is_simulator and not _ask(
            console, f"Run {what} on the REAL arm?", yes):
        console.print("Not started: the operator declined. Nothing was sent.")
        connection.close()
        raise typer.Exit(EXIT_OPERATOR_ABORT)
    # The modules' zeros are where they were powered off: use (and on real hardware after
    # a power-on, confirm) the recorded pose's offsets before anything moves. --yes never
    # answers that question: a wrong zero drives the arm anywhere, and every check with it.
    def ask_zero(question: str) -> bool:
        if yes:
            console.print("(--yes does not answer the zero question: the operator does, or "
                          "--zero-confirmed POSE)", highlight=False, markup=False,
                          soft_wrap=True)
        return _ask(console, question, False)

    try:
        zero = zero_or_exit(connection, run.arm, ask_zero,
                            lambda text: console.print(text, style="bold", highlight=False,
                                                       markup=False),
                            confirmed=zero_confirmed)
        run.arm = zero.apply(run.arm)
    except BaseException:
        connection.close()
        raise
    return zero


def watchdog_at_real_time(console: Console, run) -> None:
    """At real-time priority the arm file's ``can.watchdog.with_rt_priority`` arms the
    modules' watchdog for the whole run: said once, recorded by its watchdog_enabled
    event."""
    arm = run.arm.at_loop_priority(True)
    if arm is not run.arm:
        run.arm = arm
        console.print("watchdog: armed for the whole run (real-time priority; the arm "
                      "file's can.watchdog.with_rt_priority): if this process stops talking "
                      "the modules stop by themselves", highlight=False)


def use_realtime(console: Console, rt_priority: int | None,
                 virtual_time: bool = False) -> bool:
    """``--rt-priority N``: the control loop (this thread, and the threads it starts) at
    SCHED_FIFO N; the threads already running (the control socket's, the display's) at
    SCHED_RR 1, above every normal process, so that none of them is kept off the CPU
    while it holds the interpreter lock the loop waits for; the lock handed over within
    1 ms (seqrun/service/realtime.py, as the console does)."""
    if rt_priority is None:
        if virtual_time:   # no loop on the wall clock: the host's load changes nothing
            return False
        from seqrun.service.host_watch import busy_host_note

        note = busy_host_note()
        if note is not None:   # once, at the start: what --rt-priority would change
            console.print(note, style="yellow", highlight=False, markup=False, soft_wrap=True)
        return False
    from seqrun.service.realtime import hand_over_the_lock_often, use_fifo, use_round_robin

    why = use_round_robin()
    if why is None:
        why = use_fifo(rt_priority)
    if why is None:
        hand_over_the_lock_often()
        console.print(f"real-time scheduling: SCHED_FIFO priority {rt_priority} (other "
                      "threads SCHED_RR 1)", highlight=False)
        return True
    console.print(f"warning: real-time scheduling not available ({why}); running at "
                  "normal priority", style="yellow", highlight=False, markup=False)
    return False
