"""Which page started the motion under way, so that a page that goes away stops it.

A motion is the page's whose control secret commanded it (the desk names the holder: its
public client id, given to its WebSocket). When that WebSocket closes, or the page falls
silent, while a motion the page started is still under way, the server ends it: a jog with
``jog_stop()``, a move or a run with ``abort()`` (controlled stop); the control desk stops it
too when the page leaves (:mod:`seqrun.service.control`). Motions started by API clients
(a coordinator's script) are not tied to any connection.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Any

log = logging.getLogger(__name__)


@dataclass
class _Owned:
    client: str
    kind: str  # "jog", "move", "run"
    activity: Any = None


class Motions:
    def __init__(self, session: Any) -> None:
        self.session = session
        self._lock = threading.Lock()
        self._owned: _Owned | None = None
        #: What was done when a page went away (for the event log and the tests).
        self.stops: list[tuple[str, str]] = []

    def started(self, client: str | None, kind: str, activity: Any = None) -> None:
        if not client:
            return
        with self._lock:
            self._owned = _Owned(client, kind, activity)

    def jog_ended(self, client: str | None) -> None:
        with self._lock:
            if self._owned is not None and self._owned.kind == "jog" \
                    and self._owned.client == client:
                self._owned = None

    def owns_motion(self, client: str) -> bool:
        """``client`` started the motion under way."""
        with self._lock:
            owned = self._owned
        return owned is not None and owned.client == client and self.under_way(owned)

    def under_way(self, owned: _Owned) -> bool:
        if owned.kind == "jog":
            return self.session.status().activity == "jogging"
        return owned.activity is not None and not owned.activity.done

    def page_gone(self, client: str) -> str | None:
        """Stop the motion ``client`` started if it is still under way; what was done."""
        with self._lock:
            owned = self._owned
            if owned is None or owned.client != client:
                return None
            self._owned = None
        if not self.under_way(owned):
            return None
        if owned.kind == "jog":
            self.session.jog_stop()
            done = "jog stopped"
        else:
            self.session.abort()
            done = f"{owned.kind} stopped (controlled stop)"
        log.warning("console page %s went away during a %s: %s", client, owned.kind, done)
        self.stops.append((client, done))
        return done
