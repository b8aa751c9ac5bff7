"""Clocks passed into everything that waits: real time for live runs, virtual time for
tests and dry runs.

A :class:`VirtualClock` only moves when somebody sleeps on it (the executor between
cycles, the simulated bus while a client waits for an acknowledge), so a 10-second
motion is simulated in milliseconds and every run is deterministic.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    #: True when time only advances through :meth:`sleep` (tests, dry runs).
    is_virtual: bool

    def now(self) -> float:
        """Monotonic seconds."""

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` pass (no-op for non-positive values)."""

    def sleep_until(self, t: float) -> None:
        """Let time pass until ``now() >= t``."""


class RealClock:
    """Wall-clock time (``time.monotonic``)."""

    is_virtual = False

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def sleep_until(self, t: float) -> None:
        self.sleep(t - time.monotonic())


class VirtualClock:
    """Time that advances only when asked to. Thread-safe, never goes backwards."""

    is_virtual = True

    def __init__(self, start: float = 0.0) -> None:
        self._now = float(start)
        self._lock = threading.Lock()

    def now(self) -> float:
        return self._now

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            with self._lock:
                self._now += seconds

    def sleep_until(self, t: float) -> None:
        with self._lock:
            if t > self._now:
                self._now = t

    # Alias that reads better in simulator code.
    advance = sleep


class LockstepClock:
    """One virtual time for several threads, each with its own :meth:`view`: time moves
    only when every thread that has joined sleeps, to the earliest time one of them waits
    for, and wakes that one. Two arms' dry runs (each its executor and simulated bus on its
    own thread) thus run on one time base, as they would side by side, and stay
    deterministic. A thread leaves (:meth:`LockstepView.leave`) when it ends."""

    def __init__(self, start: float = 0.0) -> None:
        self._now = float(start)
        self._cond = threading.Condition()
        self._members: set[int] = set()
        self._waiting: dict[int, float] = {}
        self._ids = iter(range(1, 1 << 30))

    def view(self) -> LockstepView:
        with self._cond:
            member = next(self._ids)
            self._members.add(member)
            return LockstepView(self, member)

    def now(self) -> float:
        return self._now

    def _advance(self) -> None:
        # (under the lock) everyone sleeps: time moves to the earliest wake-up
        if self._members and len(self._waiting) == len(self._members):
            earliest = min(self._waiting.values())
            if earliest > self._now:
                self._now = earliest
            self._cond.notify_all()

    def _sleep_until(self, member: int, t: float) -> None:
        with self._cond:
            if t <= self._now:
                return
            self._waiting[member] = t
            self._advance()
            while self._now < t:
                self._cond.wait()
            del self._waiting[member]

    def _leave(self, member: int) -> None:
        with self._cond:
            self._members.discard(member)
            self._waiting.pop(member, None)
            self._advance()


class LockstepView:
    """One thread's :class:`Clock` on a :class:`LockstepClock`."""

    is_virtual = True

    def __init__(self, shared: LockstepClock, member: int) -> None:
        self._shared = shared
        self._member = member

    def now(self) -> float:
        return self._shared._now

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self._shared._sleep_until(self._member, self._shared._now + seconds)

    def sleep_until(self, t: float) -> None:
        self._shared._sleep_until(self._member, t)

    advance = sleep

    def leave(self) -> None:
        """This thread takes no more part (it ended): the others no longer wait for it."""
        self._shared._leave(self._member)
