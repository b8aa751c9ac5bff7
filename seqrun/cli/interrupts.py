"""Signals during ``seqrun run``: what each one asks for, and nothing more.

A handler runs in the main thread between two bytecodes of whatever it is doing (inside a
display's lock, the executor's, a log write), so it only posts a request
(:class:`~seqrun.stop_requests.StopRequests`, lock-free) that the control loop acts on at
its next cycle. The one exception is a blocking read of the operator's answer: the handler
interrupts it (KeyboardInterrupt), but only while the main thread is inside
:meth:`RunSignals.read_answer`'s guarded window, so the exception can never land anywhere
else.

=========  ====================================================  ============
signal     request                                               exit code
=========  ====================================================  ============
SIGINT     first: controlled stop; second: Halt                  130
SIGTERM    Halt                                                  130
SIGHUP     Halt (the operator's terminal is gone)                3
SIGQUIT    Halt                                                  3
=========  ====================================================  ============
"""

from __future__ import annotations

import signal
import sys
from typing import Any, Callable, TextIO

from seqrun.stop_requests import StopRequests

#: SIGHUP and SIGQUIT end the run as a fault (exit 3): no operator decided to stop.
FAULT_CAUSE = "signal"

_HANDLED = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
                 if hasattr(signal, name))


class RunSignals:
    """The run's signal handlers; :meth:`handle` is the handler for every signal."""

    def __init__(self, requests: StopRequests) -> None:
        self.requests = requests
        self.interrupts = 0          # SIGINTs so far
        self.received = 0            # signals of any kind so far
        self._reading = False        # the main thread is blocked reading an answer
        self._saved: dict[int, Any] = {}  # what signal.signal returned: restored as is

    # ------------------------------------------------------------------ the handler
    def handle(self, signum: int, frame=None) -> None:
        """Post the request ``signum`` stands for; interrupt a pending answer read."""
        self.received += 1
        if signum == signal.SIGINT:
            self.interrupts += 1
            if self.interrupts == 1:
                self.requests.abort("Ctrl-C: controlled stop")
            else:
                self.requests.halt("second Ctrl-C")
        elif signum == signal.SIGTERM:
            self.requests.halt("SIGTERM")
        else:
            name = signal.Signals(signum).name
            what = " (terminal closed)" if name == "SIGHUP" else ""
            self.requests.halt(f"{name}{what}", cause=FAULT_CAUSE)
        if self._reading:
            self._reading = False    # at most one KeyboardInterrupt per read
            raise KeyboardInterrupt

    # ------------------------------------------------------------------ reading an answer
    def read_answer(self, stream: TextIO | None = None,
                    readline: Callable[[], str] | None = None) -> str | None:
        """One line from the operator, or None when a signal came (before or during the
        read): a signal is never answered by waiting for input."""
        read = readline or (stream or sys.stdin).readline
        try:
            try:
                self._reading = True
                if self.received:    # a signal came before the question: do not block
                    return None
                return read()
            finally:
                self._reading = False
        except KeyboardInterrupt:
            return None

    # ------------------------------------------------------------------ installation
    def install(self) -> None:
        for signum in _HANDLED:
            self._saved[signum] = signal.signal(signum, self.handle)

    def restore(self) -> None:
        """The handlers from before :meth:`install`; but SIGINT ignored once the verdict
        holds (:func:`_verdict_holds`), in one step: no moment is left in between."""
        quiet = _verdict_holds()
        for signum, old in self._saved.items():
            signal.signal(signum, signal.SIG_IGN if quiet and signum == signal.SIGINT else old)
        self._saved.clear()


class RunProgress:
    """How far the run of this command got, for a Ctrl-C outside the run's own handlers
    (before they are installed, after they are gone: seqrun/cli/run.py): ``started`` once
    frames may have been sent, ``exit_code`` once its verdict is decided."""

    def __init__(self) -> None:
        self.started = False
        self.exit_code: int | None = None


def _verdict_holds() -> bool:
    """True once this command's exit code is decided and the process is the ``seqrun``
    program: then SIGINT is ignored from the run's handlers to the process's end. A Ctrl-C
    between the command's return and the interpreter's exit (typer turns a KeyboardInterrupt
    there into exit 130) reported a faulted run, exit 3, as an operator abort. In-process
    callers (tests, tools) keep their handler: the command catches a KeyboardInterrupt once
    the verdict stands."""
    if progress.exit_code is None:
        return False
    from seqrun.cli import starting_command_line

    return starting_command_line() is not None


#: The run of this command (:func:`new_run` at its start).
progress = RunProgress()


def new_run() -> RunProgress:
    """A new :data:`progress`, for the run a command is about to start."""
    global progress
    progress = RunProgress()
    return progress
