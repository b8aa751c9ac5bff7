"""Serving the console: bind, print the URL, run uvicorn until Ctrl-C, stop the arm.

The socket is bound before anything is printed, so the printed URL is one that answers
(``--port 0`` picks a free port and prints it).

What a client may hold: a request's head must be complete within :data:`HEAD_TIMEOUT_S` of
the connection (or of the previous response on a kept-alive connection), else the connection
is closed (uvicorn has no such timeout: one byte every few seconds held a connection for
good, and 5,000 of them for 28 s); a live message is at most :data:`WS_MAX_BYTES`; the
process may open as many files as its hard limit allows (a flood of connections should meet
the head timeout, not the default 1,024 descriptors).
"""

from __future__ import annotations

import asyncio
import ipaddress
import socket
from collections.abc import Callable
from typing import Any

from uvicorn.protocols.http.h11_impl import H11Protocol

DEFAULT_PORT = 8765
LOCALHOST = "127.0.0.1"
#: A request's head (request line and headers) must have arrived within this time (s).
HEAD_TIMEOUT_S = 5.0
#: Largest live message a page may send (bytes); the page's are under 200.
WS_MAX_BYTES = 64 * 1024


class HeadDeadline(H11Protocol):
    """uvicorn's HTTP/1.1 protocol with a deadline for each request's head: armed when the
    connection opens and after every response, disarmed when the head is complete (the
    request's cycle starts) or the connection becomes a WebSocket."""

    head_timeout_s = HEAD_TIMEOUT_S

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm_head_deadline()

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        if self.cycle is not self._cycle_before or self.transport.get_protocol() is not self:
            self._disarm_head_deadline()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        # (a pipelined request's head may have been handled already: its cycle runs)
        if not self.transport.is_closing() and (self.cycle is None
                                                or self.cycle.response_complete):
            self._arm_head_deadline()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm_head_deadline()
        super().connection_lost(exc)

    def _arm_head_deadline(self) -> None:
        self._disarm_head_deadline()
        self._cycle_before = self.cycle
        self._head_timer: asyncio.TimerHandle | None = self.loop.call_later(
            self.head_timeout_s, self._head_too_slow)

    def _disarm_head_deadline(self) -> None:
        timer = getattr(self, "_head_timer", None)
        if timer is not None:
            timer.cancel()
        self._head_timer = None

    def _head_too_slow(self) -> None:
        self._head_timer = None
        if self.transport.get_protocol() is self and not self.transport.is_closing():
            self.transport.close()


def more_files() -> None:
    """The soft limit of open files up to the hard limit (Linux: 1,024 -> 4,096+)."""
    try:
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        if soft < hard:
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    except (ImportError, ValueError, OSError):
        pass


def uvicorn_config(app: Any, *, log_level: str = "warning",
                   graceful_s: int = 3) -> Any:
    """How the console is served (``seqrun console`` and the tests' server alike)."""
    import uvicorn

    # No per-message compression: each connection compresses every message on its own (the
    # same status once per page), which cost more of the interpreter than all the rest of
    # the sending; a status is ~1.7 kB.
    return uvicorn.Config(app, log_level=log_level, ws="websockets-sansio", http=HeadDeadline,
                          lifespan="on", timeout_graceful_shutdown=graceful_s,
                          ws_max_size=WS_MAX_BYTES, ws_per_message_deflate=False,
                          timeout_keep_alive=5)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def bind(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host.strip("[]"), port))
    sock.listen(64)
    sock.set_inheritable(True)
    return sock


def url_of(sock: socket.socket, host: str, token: str | None) -> str:
    port = sock.getsockname()[1]
    shown = f"[{host.strip('[]')}]" if ":" in host else host
    if shown in ("0.0.0.0", "[::]"):
        shown = socket.gethostname()
    return f"http://{shown}:{port}/" + (f"?token={token}" if token else "")


def serve(app: Any, sock: socket.socket, *, log_level: str = "warning",
          on_started: Callable[[], None] | None = None) -> None:
    """Run uvicorn on ``sock`` until SIGINT/SIGTERM (uvicorn's own handlers: a graceful
    shutdown that closes every live connection, whose pages' motions are then stopped)."""
    import uvicorn

    more_files()
    server = uvicorn.Server(uvicorn_config(app, log_level=log_level))
    if on_started is not None:
        original = server.startup

        async def startup(sockets: Any = None) -> None:
            await original(sockets=sockets)
            on_started()

        server.startup = startup  # type: ignore[method-assign]
    server.run(sockets=[sock])
