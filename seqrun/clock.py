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
