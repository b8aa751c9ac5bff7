"""A sequence's check (validation and dry run) in a worker process, below the control loop.

A dry run is seconds of pure Python. Run in the console's process it holds the interpreter
lock the 100 Hz loop needs several times a cycle: a page asking for checks in a loop slowed
the loop during a run from p99 20 ms to 137 ms. So the check runs in one worker process of
its own (spawned, not forked: the console has threads), at normal scheduling and ``nice``
19 even when the console has real-time scheduling, one check at a time; a check that takes
longer than :data:`CHECK_TIMEOUT_S` is stopped (the worker is replaced). The worker hands
back the answer encoded as JSON, so that the console's process only passes bytes on.
:class:`RateLimit` refuses requests beyond a few (429), so nobody can keep the worker busy.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import threading
import time
from collections.abc import Mapping
from typing import Any

from seqrun.errors import Refused

log = logging.getLogger(__name__)

#: The worker's niceness (0 is the console's; 19 yields the CPU to it almost entirely).
CHECK_NICE = 19
#: Longest a check may take (s) before it is stopped.
CHECK_TIMEOUT_S = 120.0


class TooMany(Exception):
    """Over the rate (429); ``retry_after_s`` says when the next one may come."""

    def __init__(self, message: str, retry_after_s: float) -> None:
        super().__init__(message)
        self.retry_after_s = retry_after_s


class RateLimit:
    """A token bucket: ``burst`` requests at once, then one per ``every_s`` seconds; and at
    most one at a time (:meth:`take` ... :meth:`give_back`)."""

    def __init__(self, *, burst: int = 3, every_s: float = 3.0, what: str = "check") -> None:
        self.burst = burst
        self.every_s = every_s
        self.what = what
        self._tokens = float(burst)
        self._at = time.monotonic()
        self._busy = False
        self._lock = threading.Lock()

    def take(self) -> None:
        with self._lock:
            now = time.monotonic()
            self._tokens = min(self.burst, self._tokens + (now - self._at) / self.every_s)
            self._at = now
            if self._busy:
                raise TooMany(f"a {self.what} is under way: wait for it", 1.0)
            if self._tokens < 1.0:
                wait = (1.0 - self._tokens) * self.every_s
                raise TooMany(f"too many {self.what}s: the next in {wait:.1f} s", wait)
            self._tokens -= 1.0
            self._busy = True

    def give_back(self) -> None:
        with self._lock:
            self._busy = False


def _lower_priority(nice: int) -> None:
    """The worker below the console: normal scheduling (a console at SCHED_RR hands its
    policy on to the processes it starts) and ``nice``."""
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (AttributeError, OSError):  # not Linux, or not allowed: nice still applies
        pass
    try:
        os.nice(nice)
    except OSError:
        pass


def _serve(conn: Any, nice: int) -> None:
    """The worker's loop: (catalog, name, start, started) in, (kind, value) out; the value
    of an answer is its JSON text (bytes)."""
    _lower_priority(nice)
    from seqrun.console.telemetry import dumps
    from seqrun.errors import SeqrunError, UserInputError

    while True:
        try:
            request = conn.recv()
        except (EOFError, OSError):
            return
        if request is None:
            return
        catalog, name, start, started = request
        try:
            answer = catalog.check(name, start, started=started)
            reply: tuple[str, Any] = ("ok", dumps(answer).encode())
        except (Refused, UserInputError) as exc:
            reply = ("refused", str(exc))
        except SeqrunError as exc:
            reply = ("refused", str(exc))
        except Exception as exc:  # noqa: BLE001 - the console answers 500 with it
            reply = ("error", f"{type(exc).__name__}: {exc}")
        conn.send(reply)


class CheckWorker:
    """The worker process (started at the first check). :meth:`check` blocks: call it on a
    thread (it holds no interpreter lock while it waits)."""

    def __init__(self, *, nice: int = CHECK_NICE, timeout_s: float = CHECK_TIMEOUT_S) -> None:
        self.nice = nice
        self.timeout_s = timeout_s
        self._context = multiprocessing.get_context("spawn")
        self._process: Any = None
        self._conn: Any = None
        self._lock = threading.Lock()
        self._closed = False

    @property
    def pid(self) -> int | None:
        return self._process.pid if self._process is not None else None

    def start(self) -> None:
        """Start the worker now (``seqrun console`` does, before it serves: starting a
        process in the middle of a run would take the interpreter from the loop)."""
        with self._lock:
            if not self._closed and (self._process is None or not self._process.is_alive()):
                self._start()

    def _start(self) -> None:
        parent, child = self._context.Pipe()
        process = self._context.Process(target=_serve, args=(child, self.nice), daemon=True,
                                        name="seqrun-console-check")
        process.start()
        child.close()
        self._process, self._conn = process, parent

    def _stop(self) -> None:
        process, conn = self._process, self._conn
        self._process = self._conn = None
        if conn is not None:
            try:
                conn.send(None)
            except (OSError, ValueError):
                pass
            conn.close()
        if process is not None:
            process.join(timeout=2.0)
            if process.is_alive():
                process.kill()
                process.join(timeout=2.0)

    def check(self, catalog: Any, name: str, start: Mapping[str, float] | None, *,
              started: bool) -> bytes:
        """The catalog's check of ``name`` in the worker, as JSON; Refused as the catalog
        refuses, RuntimeError when the worker failed."""
        with self._lock:
            if self._closed:
                raise Refused("the console is closing")
            if self._process is None or not self._process.is_alive():
                self._start()
            try:
                self._conn.send((catalog, name, None if start is None else dict(start),
                                 started))
                if not self._conn.poll(self.timeout_s):
                    self._stop()
                    raise Refused(f"the check of '{name}' took over {self.timeout_s:g} s "
                                  "and was stopped")
                kind, value = self._conn.recv()
            except (EOFError, OSError) as exc:
                self._stop()
                raise RuntimeError(f"the check's worker process ended ({exc!r})") from None
        if kind == "ok":
            return value
        if kind == "refused":
            raise Refused(value)
        raise RuntimeError(value)

    def close(self) -> None:
        """Stop the worker (a check under way ends with RuntimeError)."""
        self._closed = True
        process = self._process
        if process is not None and process.is_alive():
            process.kill()
        with self._lock:
            self._stop()
