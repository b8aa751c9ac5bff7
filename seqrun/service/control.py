"""Who holds control of the arm, and who watches: one operator commands, everybody can STOP.

An arm session is reached by several faces at once: browser tabs of the console, a
coordinator's script on its API, Foxglove clients, the ROS node, the CLI's jog. Every one of
them goes through this one desk, as on an industrial HMI (one operator station in control):

- a client **joins** with a public id and a name the others see ("page-2 · Firefox on
  10.0.0.7"), and **leaves** when its connection closes;
- at most one client **holds control**. Taking it (:meth:`ControlDesk.take`) issues a
  **secret** (``secrets.token_urlsafe``) to that client alone; it is never in an event, a
  status or a list of clients (those carry the public id and name only). Every command
  that moves the arm or changes its settings presents the secret
  (:meth:`ControlDesk.require`): a public id is no credential;
- every client, holder or not, may always **stop**: STOP (Halt), abort, pause, end a jog —
  those need no secret;
- control held by someone else is not taken silently: a client must ask to **take over**
  (``take_over=True``), which first ends the holder's motion with a controlled stop, then
  hands control on; the old holder sees a ``control_taken`` event naming it as ``previous``
  and its secret is worth nothing from then on;
- a holder that **releases** control or **leaves** (its WebSocket or Foxglove connection
  closed) ends its motion with a controlled stop (``stop_motion``, given by the session:
  only a motion that client started is stopped) and holds nothing any more.

Every change is published as a typed event (:mod:`seqrun.events`: ``client_joined``,
``client_left``, ``control_taken``, ``control_released``) carrying the holder and the whole
list of clients, so a face can show who commands and who watches from the events alone.
"""

from __future__ import annotations

import hmac
import secrets
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from seqrun.errors import Refused


@dataclass(frozen=True)
class Client:
    """One client of the session: ``id`` (public, unique while it is connected), the
    ``name`` the others see, its ``kind`` ("page", "api", "foxglove", "ros", "cli") and when
    it joined (``since``, clock s). ``while_holding``: it exists only while it holds control
    (an API client or a process: it leaves when it gives control up or loses it)."""

    id: str
    name: str
    kind: str
    since: float
    while_holding: bool = False

    def as_dict(self) -> dict[str, Any]:
        return {"id": self.id, "name": self.name, "kind": self.kind}


@dataclass(frozen=True)
class ControlState:
    """Who holds control (None: nobody) and every client connected (public: no secret)."""

    holder: Client | None
    clients: tuple[Client, ...]

    def as_dict(self) -> dict[str, Any]:
        return {"holder": self.holder.as_dict() if self.holder else None,
                "clients": [c.as_dict() for c in self.clients]}


@dataclass(frozen=True)
class Grant:
    """What the client that took control gets: its ``secret`` (for it alone: never
    published) and the state after it took control."""

    client: Client
    secret: str
    state: ControlState

    def as_dict(self) -> dict[str, Any]:
        """The answer to the client that took control (its secret in ``token``)."""
        return {"client": self.client.id, "token": self.secret, **self.state.as_dict()}


class NotInControl(Refused):
    """A command without the holder's secret (one line naming the holder)."""


Publish = Callable[..., None]
#: ``stop_motion(client)``: end the motion ``client`` started, if one is under way, with a
#: controlled stop; what was done (None: nothing was under way).
StopMotion = Callable[[Client], "str | None"]


def new_secret() -> str:
    return secrets.token_urlsafe(24)


class ControlDesk:
    """The control of one arm session, or of the arms of one console (thread-safe).
    ``publish(type_, **fields)`` hands the events on (the session's hub); ``stop_motion``
    ends a holder's motion when it releases, leaves or is taken over."""

    def __init__(self, publish: Publish | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 stop_motion: StopMotion | None = None) -> None:
        self._publish = publish
        self._clock = clock
        self.stop_motion = stop_motion
        self._lock = threading.Lock()
        self._clients: dict[str, Client] = {}
        self._holder: str | None = None
        self._secret: str | None = None

    # -- reading ---------------------------------------------------------------------------
    def state(self) -> ControlState:
        with self._lock:
            return self._state()

    def _state(self) -> ControlState:
        holder = self._clients.get(self._holder) if self._holder else None
        return ControlState(holder, tuple(self._clients.values()))

    def holds(self, client_id: str | None) -> bool:
        """``client_id`` (a public id) holds control: for display, never a credential."""
        with self._lock:
            return client_id is not None and client_id == self._holder

    def client(self, client_id: str | None) -> Client | None:
        with self._lock:
            return self._clients.get(client_id) if client_id else None

    def holder_of(self, secret: str | None) -> Client | None:
        """The holder, if ``secret`` is its secret; None otherwise."""
        with self._lock:
            return self._holder_of(secret)

    def _holder_of(self, secret: str | None) -> Client | None:
        if not secret or self._secret is None or self._holder is None:
            return None
        if not hmac.compare_digest(secret.encode(), self._secret.encode()):
            return None
        return self._clients.get(self._holder)

    def require(self, secret: str | None, what: str) -> Client:
        """The holder, whose ``secret`` this is; :class:`NotInControl` (one line naming the
        holder) otherwise."""
        with self._lock:
            holder = self._holder_of(secret)
            if holder is not None:
                return holder
            current = self._clients.get(self._holder) if self._holder else None
        who = "nobody holds control" if current is None else f"{current.name} holds control"
        if not secret:
            raise NotInControl(f"{what}: {who}; commands need the secret a client gets when "
                               "it takes control (STOP is always allowed)")
        raise NotInControl(f"{what}: {who}; this client's secret does not hold control "
                           "(take control first; STOP is always allowed)")

    # -- changing --------------------------------------------------------------------------
    def join(self, client_id: str, name: str, kind: str, *,
             while_holding: bool = False) -> ControlState:
        """Add a client (a watcher until it takes control)."""
        with self._lock:
            if client_id in self._clients:
                raise Refused(f"client id {client_id!r} is in use")
            client = Client(client_id, name, kind, self._clock(), while_holding)
            self._clients[client_id] = client
            state = self._state()
        self._emit("client_joined", client=client.as_dict(), **state.as_dict())
        return state

    def take(self, client_id: str, *, take_over: bool = False) -> Grant:
        """``client_id`` holds control from now on, with a new secret. Held by another
        client: refused unless ``take_over`` (that holder's motion then ends with a
        controlled stop first, and it is told). The holder taking it again gets a new
        secret (the old one is worth nothing)."""
        with self._lock:
            client = self._clients.get(client_id)
            if client is None:
                raise Refused(f"take control: unknown client {client_id!r} (join first)")
            previous = (self._clients.get(self._holder)
                        if self._holder not in (None, client_id) else None)
            if previous is not None and not take_over:
                raise Refused(f"take control: {previous.name} holds control; it must release "
                              "it, or take over (take_over: its motion is stopped first and "
                              "it is told)")
        stopped = self._stop(previous) if previous is not None else None
        with self._lock:
            if self._clients.get(client_id) is None:
                raise Refused(f"take control: client {client_id!r} left meanwhile")
            now_previous = (self._clients.get(self._holder)
                            if self._holder not in (None, client_id) else None)
            if now_previous is not None and now_previous != previous:
                raise Refused(f"take control: {now_previous.name} took control meanwhile")
            self._holder = client_id
            self._secret = new_secret()
            secret = self._secret
            dropped = None
            if previous is not None and previous.while_holding:
                dropped = self._clients.pop(previous.id, None)
            state = self._state()
        self._emit("control_taken", previous=previous.as_dict() if previous else None,
                   stopped=stopped, **state.as_dict())
        if dropped is not None:
            self._emit("client_left", client=dropped.as_dict(), **state.as_dict())
        return Grant(client, secret, state)

    def join_and_take(self, client_id: str, name: str, kind: str, *,
                      take_over: bool = False) -> Grant:
        """A client that exists only while it holds control (an API client, the ROS node,
        the CLI's jog) joins and takes control; if it may not, it is gone again."""
        self.join(client_id, name, kind, while_holding=True)
        try:
            return self.take(client_id, take_over=take_over)
        except BaseException:
            self.leave(client_id)
            raise

    def take_if_free(self, client_id: str) -> Grant | None:
        """Control for ``client_id`` if nobody holds it (the first page of a console)."""
        try:
            return self.take(client_id)
        except Refused:
            return None

    def release(self, secret: str | None) -> ControlState:
        """The holder (whose ``secret`` this is) gives control up: its motion ends with a
        controlled stop; nobody holds control then. A client that exists only while
        holding leaves."""
        holder = self.require(secret, "release control")
        self._stop(holder)
        with self._lock:
            if self._holder != holder.id:
                return self._state()
            self._holder = self._secret = None
            dropped = self._clients.pop(holder.id, None) if holder.while_holding else None
            state = self._state()
        self._emit("control_released", previous=holder.as_dict(), left=dropped is not None,
                   **state.as_dict())
        if dropped is not None:
            self._emit("client_left", client=dropped.as_dict(), **state.as_dict())
        return state

    def leave(self, client_id: str) -> ControlState:
        """A client's connection closed: it is gone; if it held control, its motion ends
        with a controlled stop and nobody holds control."""
        client = self.client(client_id)
        if client is None:
            return self.state()
        held = self.holds(client_id)
        if held:
            self._stop(client)
        with self._lock:
            self._clients.pop(client_id, None)
            held = self._holder == client_id
            if held:
                self._holder = self._secret = None
            state = self._state()
        if held:
            self._emit("control_released", previous=client.as_dict(), left=True,
                       **state.as_dict())
        self._emit("client_left", client=client.as_dict(), **state.as_dict())
        return state

    def _stop(self, client: Client) -> str | None:
        """End ``client``'s motion (controlled stop); outside the lock: it waits for the
        arm."""
        return self.stop_motion(client) if self.stop_motion is not None else None

    def _emit(self, type_: str, **fields: Mapping[str, Any] | Any) -> None:
        if self._publish is not None:
            self._publish(type_, **fields)
