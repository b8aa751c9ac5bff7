"""Live telemetry for every open page: one subscription to the session, fanned out.

One daemon thread reads the session's events (its own bounded queue: the control loop never
waits for the console). Each measurement becomes one status snapshot (``session.status()``),
serialised once and handed to every page; every other event is queued per page and kept in
a short history for pages opened later. A page that cannot keep up gets the newest status
only (older snapshots are replaced, never queued) and its oldest events are dropped beyond
:data:`PAGE_EVENTS` (counted), so one slow tablet delays nobody and holds little memory.

The pages share a budget of :data:`STATUS_BUDGET_PER_S` status messages a second: each page
gets at most the measurement rate, and fewer when many pages are open (100 pages: 5 a
second each), and snapshots are built only as often as the pages may take them, so that
building and sending them never takes the interpreter from the control loop for long.
"""

from __future__ import annotations

import asyncio
import collections
import dataclasses
import enum
import json
import logging
import math
import threading
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

#: Most status snapshots per second sent to a page. The control loop measures at 100 Hz;
#: the cap is above it so that a cycle's jitter never halves the rate.
MAX_STATUS_HZ = 150.0
#: A status is pushed at least this often, measurement or not (the page shows it is alive).
HEARTBEAT_S = 0.5
HISTORY = 300
#: Events kept for one page that has not been sent them yet (the oldest go first).
PAGE_EVENTS = 500
#: Status messages a second for all pages together (3 tabs: every measurement; 100 live
#: clients: 5 a second each).
STATUS_BUDGET_PER_S = 500.0
#: Events that carry a new measurement of the arm, never a line of the event log. A
#: ``measurement`` becomes a status snapshot (subscribers get one per cycle of a move and
#: one per idle poll); a ``setpoint`` comes with the same cycle's measurement.
MEASURING_EVENTS = frozenset({"measurement", "setpoint"})


def jsonable(value: Any) -> Any:
    """Dataclasses, enums, paths, tuples, numpy numbers -> JSON values; NaN/inf -> None."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        if hasattr(value, "as_dict"):
            return jsonable(value.as_dict())
        return {f.name: jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [jsonable(v) for v in value]
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, enum.Enum):
        return value.name if isinstance(value, enum.Flag) else jsonable(value.value)
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, (Path, datetime)):
        return str(value)
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return jsonable(value.tolist())
    return str(value)


def dumps(message: dict[str, Any]) -> str:
    return json.dumps(jsonable(message), separators=(",", ":"), allow_nan=False)


class PageFeed:
    """What one page has not been sent yet: events in order, and the newest status."""

    def __init__(self, loop: asyncio.AbstractEventLoop, max_events: int = PAGE_EVENTS) -> None:
        self.loop = loop
        self.events: collections.deque[str] = collections.deque(maxlen=max_events)
        #: The newest status of each arm (key None: the console of one arm).
        self.statuses: dict[str | None, str] = {}
        self.ready = asyncio.Event()
        #: Events dropped (the page did not take them in time) and statuses replaced by a
        #: newer one before they were sent.
        self.dropped_events = 0
        self.replaced_statuses = 0

    def push_event(self, text: str) -> None:
        if len(self.events) == self.events.maxlen:
            self.dropped_events += 1
        self.events.append(text)
        self.ready.set()

    @property
    def status(self) -> str | None:
        """The newest status not sent yet (of the one arm; of any arm with several)."""
        return next(reversed(self.statuses.values()), None)

    def push_status(self, text: str, arm_id: str | None = None) -> None:
        """The newest status of ``arm_id`` (replaces that arm's older one only)."""
        if self.statuses.pop(arm_id, None) is not None:
            self.replaced_statuses += 1
        self.statuses[arm_id] = text
        self.ready.set()

    async def next_batch(self) -> list[str]:
        await self.ready.wait()
        self.ready.clear()
        batch = list(self.events)
        self.events.clear()
        batch.extend(self.statuses.values())
        self.statuses.clear()
        return batch


def _deliver(feeds: list[PageFeed], text: str, status: bool, arm_id: str | None = None
             ) -> None:
    for feed in feeds:
        if status:
            feed.push_status(text, arm_id)
        else:
            feed.push_event(text)


class Telemetry:
    """The fan-out: ``attach()`` a page's feed, ``detach()`` it when the page goes."""

    def __init__(self, session: Any, *, status_dict: Callable[[], dict[str, Any]],
                 arm_id: str | None = None) -> None:
        self.session = session
        self.status_dict = status_dict
        #: In a console of several arms, every message names its arm (``"arm": "B"``).
        self.arm_id = arm_id
        self._tag: dict[str, Any] = {"arm": arm_id} if arm_id is not None else {}
        self.history: collections.deque[str] = collections.deque(maxlen=HISTORY)
        self._feeds: set[PageFeed] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._subscription: Any = None
        #: Snapshots built (status messages), for the bench and the tests.
        self.snapshots = 0

    # -- pages (event loop thread) ------------------------------------------------------
    def attach(self, feed: PageFeed) -> list[str]:
        with self._lock:
            self._feeds.add(feed)
            return list(self.history)

    def detach(self, feed: PageFeed) -> None:
        with self._lock:
            self._feeds.discard(feed)

    @property
    def pages(self) -> int:
        return len(self._feeds)

    def status_gap_s(self) -> float:
        """Least time between two statuses to one page: the budget shared by the pages."""
        return max(1.0 / MAX_STATUS_HZ, len(self._feeds) / STATUS_BUDGET_PER_S)

    def build_gap_s(self) -> float:
        """Least time between two status snapshots: none is built faster than a page may be
        sent one (twice as often, so that what a page gets is at most half its gap old).
        A snapshot (forward kinematics, encoding) holds the interpreter a few hundred
        microseconds: 100 a second for 100 pages that take 5 each was most of the console's
        work."""
        return max(1.0 / MAX_STATUS_HZ, self.status_gap_s() / 2)

    # -- the reader thread ----------------------------------------------------------------
    def start(self) -> None:
        self._subscription = self.session.subscribe(maxsize=2000, name="console")
        self._thread = threading.Thread(target=self._run, name="console-telemetry",
                                        daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._subscription is not None:
            self._subscription.close()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def _broadcast(self, text: str, *, status: bool) -> None:
        """Hand ``text`` (encoded once) to every page: one wake-up of each event loop for all
        of its pages, nothing per page in this thread."""
        with self._lock:
            by_loop: dict[asyncio.AbstractEventLoop, list[PageFeed]] = {}
            for feed in self._feeds:
                by_loop.setdefault(feed.loop, []).append(feed)
        for loop, feeds in by_loop.items():
            try:
                loop.call_soon_threadsafe(_deliver, feeds, text, status, self.arm_id)
            except RuntimeError:  # its loop has closed: the pages are gone
                for feed in feeds:
                    self.detach(feed)

    def publish_status(self) -> None:
        with self._lock:
            if not self._feeds:
                return  # no page open: no snapshot to build (GET /status builds its own)
        self.snapshots += 1
        self._broadcast(dumps({"type": "status", **self._tag, "status": self.status_dict()}),
                        status=True)

    def _run(self) -> None:
        last_status = 0.0
        while not self._stop.is_set():
            try:
                event = self._subscription.get(timeout=HEARTBEAT_S)
                now = time.monotonic()
                if event is None:
                    self.publish_status()  # heartbeat: nothing measured for a while
                    last_status = now
                    continue
                kind = getattr(event, "type", None)
                if kind in MEASURING_EVENTS:
                    if kind == "measurement" and now - last_status >= self.build_gap_s():
                        self.publish_status()
                        last_status = now
                    continue
                text = dumps({"type": "event", **self._tag, "event": event.as_dict()})
                self.history.append(text)
                self._broadcast(text, status=False)
                self.publish_status()  # the activity may have changed with this event
                last_status = now
            except Exception:  # noqa: BLE001 - the feed must outlive one bad event
                if self._stop.is_set():
                    return
                log.exception("console telemetry: an event could not be sent")
                time.sleep(0.05)
