"""Who holds control of the arm, and who watches: one operator commands, everybody can STOP.

An arm session may be reached by several clients at once: browser tabs of the console, a
coordinator's script on its API, later a Foxglove connection or a ROS 2 node. As on an
industrial HMI (one operator station in control) or a ROS tool with a single commander:

- a client **joins** with a name the others see ("page-2 · Firefox on 10.0.0.7"), and
  **leaves** (its connection closed);
- at most one client **holds control**; only the holder may command — start or change
  motion, answer a run's questions, change settings (:meth:`ControlDesk.require`);
- every client, holder or not, may always **stop**: STOP (Halt), abort, pause, end a jog;
- control is **taken** explicitly (:meth:`ControlDesk.take`), from nobody or from the
  holder, who is told (a ``control_taken`` event naming the previous holder); the holder
  may **release** it; a holder that leaves frees it (``control_released``, ``left``).

Every change is published as a typed event (:mod:`seqrun.events`: ``client_joined``,
``client_left``, ``control_taken``, ``control_released``) carrying the holder and the whole
list of clients, so a face can show who commands and who watches from the events alone.
Nothing here touches the bus: losing control never stops a motion (STOP does).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from seqrun.errors import Refused


@dataclass(frozen=True)
class Client:
    """One client of the session: ``id`` (unique while it is connected), the ``name`` the
    others see, its ``kind`` ("page", "api", ...) and when it joined (``since``, clock s)."""

    id: str
    name: str
    kind: str
    since: float

    def as_dict(self) -> dict[str, Any]:
        return {"id": self.id, "name": self.name, "kind": self.kind}


@dataclass(frozen=True)
class ControlState:
    """Who holds control (None: nobody) and every client connected."""

    holder: Client | None
    clients: tuple[Client, ...]

    def as_dict(self) -> dict[str, Any]:
        return {"holder": self.holder.as_dict() if self.holder else None,
                "clients": [c.as_dict() for c in self.clients]}


class NotInControl(Refused):
    """A command from a client that does not hold control (one line naming the holder)."""


Publish = Callable[..., None]


class ControlDesk:
    """The control of one arm session (thread-safe). ``publish(type_, **fields)`` hands the
    events on (the session's hub)."""

    def __init__(self, publish: Publish | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._publish = publish
        self._clock = clock
        self._lock = threading.Lock()
        self._clients: dict[str, Client] = {}
        self._holder: str | None = None

    # -- reading ---------------------------------------------------------------------------
    def state(self) -> ControlState:
        with self._lock:
            return self._state()

    def _state(self) -> ControlState:
        holder = self._clients.get(self._holder) if self._holder else None
        return ControlState(holder, tuple(self._clients.values()))

    def holds(self, client_id: str | None) -> bool:
        with self._lock:
            return client_id is not None and client_id == self._holder

    def client(self, client_id: str | None) -> Client | None:
        with self._lock:
            return self._clients.get(client_id) if client_id else None

    def name_of(self, client_id: str | None) -> str | None:
        client = self.client(client_id)
        return client.name if client else None

    def require(self, client_id: str | None, what: str) -> None:
        """Refused (:class:`NotInControl`) unless ``client_id`` holds control."""
        with self._lock:
            if client_id is not None and client_id == self._holder:
                return
            holder = self._clients.get(self._holder) if self._holder else None
            known = client_id is not None and client_id in self._clients
        who = ("nobody holds control" if holder is None
               else f"{holder.name} holds control")
        if not known:
            raise NotInControl(f"{what}: {who}; a client must join and take control first "
                               "(POST /api/v1/control/take); STOP is always allowed")
        raise NotInControl(f"{what}: {who}; take control first (STOP is always allowed)")

    # -- changing --------------------------------------------------------------------------
    def join(self, client_id: str, name: str, kind: str, *,
             take_if_free: bool = False) -> ControlState:
        """Add a client (a watcher; the holder if ``take_if_free`` and nobody holds it)."""
        with self._lock:
            if client_id in self._clients:
                raise Refused(f"client id {client_id!r} is in use")
            client = Client(client_id, name, kind, self._clock())
            self._clients[client_id] = client
            took = take_if_free and self._holder is None
            if took:
                self._holder = client_id
            state = self._state()
        self._emit("client_joined", client=client.as_dict(), **state.as_dict())
        if took:
            self._emit("control_taken", previous=None, **state.as_dict())
        return state

    def leave(self, client_id: str) -> ControlState:
        """Remove a client; a holder that leaves frees control."""
        with self._lock:
            client = self._clients.pop(client_id, None)
            held = client is not None and self._holder == client_id
            if held:
                self._holder = None
            state = self._state()
        if client is None:
            return state
        if held:
            self._emit("control_released", previous=client.as_dict(), left=True,
                       **state.as_dict())
        self._emit("client_left", client=client.as_dict(), **state.as_dict())
        return state

    def take(self, client_id: str) -> ControlState:
        """``client_id`` holds control from now on (from nobody, or from the holder)."""
        with self._lock:
            if client_id not in self._clients:
                raise Refused(f"take control: unknown client {client_id!r} (join first)")
            if self._holder == client_id:
                return self._state()
            previous = self._clients.get(self._holder) if self._holder else None
            self._holder = client_id
            state = self._state()
        self._emit("control_taken", previous=previous.as_dict() if previous else None,
                   **state.as_dict())
        return state

    def release(self, client_id: str) -> ControlState:
        """The holder gives control up (nobody holds it then)."""
        with self._lock:
            if self._holder != client_id:
                raise Refused("release control: this client does not hold it")
            previous = self._clients[client_id]
            self._holder = None
            state = self._state()
        self._emit("control_released", previous=previous.as_dict(), left=False,
                   **state.as_dict())
        return state

    def _emit(self, type_: str, **fields: Mapping[str, Any] | Any) -> None:
        if self._publish is not None:
            self._publish(type_, **fields)
