"""Stop requests as the run loop takes them: abort (a controlled stop; a second one is a
Halt), Halt (STOP, SIGTERM, another master on the bus), pause and resume.

A pause is not a stop of the motion: the step under way finishes (a move to rest), then the
run holds before the next step (:meth:`StopControl.begin_hold`). A resume is an ask the loop
answers (:class:`ResumeAsk`): it validates the rest of the sequence from the measured pose
first, and refuses with the reason when that fails.

Requests are posted from any thread or signal handler into a lock-free inbox
(:mod:`seqrun.stop_requests`); the loop takes them at its next look and acts within a
cycle. Taking them is a sign of life of the loop (the watchdog keeper feeds the modules
only while the loop shows one).
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable


from seqrun.errors import RunAborted
from seqrun.stop_requests import OPERATOR_HALT, StopRequest, StopRequests


class ResumeAsk:
    """One Resume request: the loop answers it (None: resumed; a text: refused, why)."""

    def __init__(self) -> None:
        self._done = threading.Event()
        self.refused: str | None = None

    def answer(self, refused: str | None) -> None:
        self.refused = refused
        self._done.set()

    def wait(self, timeout_s: float) -> bool:
        """True once answered within ``timeout_s`` (real seconds)."""
        return self._done.wait(timeout_s)


class StopControl:
    """The stop requests of one run.

    :param requests: the inbox (shared with signal handlers and the session).
    :param emit: the run's event emitter.
    :param alive: called whenever the loop looks at the inbox (a sign of life).
    """

    def __init__(self, requests: StopRequests, emit: Callable[..., None],
                 alive: Callable[[], None]) -> None:
        self.requests = requests
        self._emit = emit
        self._alive = alive
        self._aborts = 0
        self._halt: StopRequest | None = None
        self._taking = False
        #: Set while a pause is asked for (any thread); the loop holds before the next step.
        self.paused = threading.Event()
        # Whether the loop holds (a pause taken), and the Resume asks it has to answer;
        # the lock orders a Resume against the loop's taking the pause.
        self._hold_lock = threading.Lock()
        self._holding = False
        self._resume_asks: deque[ResumeAsk] = deque()

    # ------------------------------------------------------------------ any thread
    def abort(self, reason: str) -> None:
        """First: controlled stop. Second: Halt. Takes no lock (safe in a signal handler)."""
        self.requests.abort(reason)

    def halt(self, reason: str, cause: str = OPERATOR_HALT) -> None:
        """Immediate Halt; a ``cause`` other than operator_halt ends the run as a fault."""
        self.requests.halt(reason, cause)

    def pause(self) -> None:
        """Hold before the next step (the step under way finishes first)."""
        self.paused.set()
        self._emit("pause_requested")

    def resume(self) -> ResumeAsk:
        """Go on after a pause: the loop answers the returned ask once it has validated the
        rest of the sequence from the measured pose. A pause the loop has not taken yet (the
        step still runs) is withdrawn at once: nothing stopped, nothing to check."""
        ask = ResumeAsk()
        with self._hold_lock:
            if self._holding:
                self._resume_asks.append(ask)
                return ask
            self.paused.clear()
        ask.answer(None)
        return ask

    # ------------------------------------------------------------------ the run loop: pause
    def begin_hold(self) -> bool:
        """Run loop, between steps: True when a pause is asked for (the loop now holds)."""
        with self._hold_lock:
            self._holding = self.paused.is_set()
            return self._holding

    def next_resume(self) -> ResumeAsk | None:
        """Run loop, holding: the oldest Resume ask not answered yet."""
        try:
            return self._resume_asks.popleft()
        except IndexError:
            return None

    def end_hold(self, refused: str | None = None) -> None:
        """Run loop: the hold is over (resumed: None; ended otherwise: why). Every Resume
        ask still waiting gets that answer."""
        with self._hold_lock:
            self._holding = False
            self.paused.clear()
            asks, self._resume_asks = list(self._resume_asks), deque()
        for ask in asks:
            ask.answer(refused)

    @property
    def abort_requested(self) -> bool:
        """An abort was taken (no look at the inbox: any thread)."""
        return self._aborts > 0

    # ------------------------------------------------------------------ the run loop
    def take(self) -> None:
        """Run loop only: act on the stop requests posted since the last look."""
        self._alive()
        if self._taking or not self.requests:
            return
        self._taking = True   # a listener reading the flags must not re-enter
        try:
            for request in self.requests.take():
                self.paused.clear()
                if request.kind == "abort":
                    self._aborts += 1
                    self._emit("abort_requested", reason=request.reason, count=self._aborts)
                    if self._aborts >= 2 and self._halt is None:
                        self._halt = request
                elif self._halt is None:
                    self._halt = request
                    self._emit("halt_requested", reason=request.reason, cause=request.cause)
        finally:
            self._taking = False

    @property
    def aborts(self) -> int:
        """Aborts taken so far (the loop looks at the inbox first)."""
        self.take()
        return self._aborts

    @property
    def halt_request(self) -> StopRequest | None:
        """The Halt taken (the loop looks at the inbox first), None while there is none."""
        self.take()
        return self._halt

    def raise_for_halt(self) -> None:
        """A Halt taken ends the step: operator_halt (exit 130) or the cause it names."""
        halt = self.halt_request
        if halt is not None:
            if halt.cause == OPERATOR_HALT:
                raise RunAborted(OPERATOR_HALT, f"Halt requested by the operator ({halt.reason})")
            raise RunAborted(halt.cause, f"{halt.reason}: Halt")

    def operator_halt_seen(self, exc: Exception) -> Exception:
        """A module reporting HALTED while an operator's Halt is posted is that Halt (an
        arm session sends the broadcast from the operator's thread at once and posts the
        request; the loop may read HALTED before it takes the request): exit 130."""
        halt = self.halt_request if isinstance(exc, RunAborted) and exc.cause == "halted" \
            else None
        if halt is not None and halt.cause == OPERATOR_HALT:
            return RunAborted(OPERATOR_HALT, f"Halt requested by the operator ({halt.reason})")
        return exc


