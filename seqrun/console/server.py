"""Serving the console: bind, print the URL, run uvicorn until Ctrl-C, stop the arm.

The socket is bound before anything is printed, so the printed URL is one that answers
(``--port 0`` picks a free port and prints it).
"""

from __future__ import annotations

import ipaddress
import socket
from collections.abc import Callable
from typing import Any

DEFAULT_PORT = 8765
LOCALHOST = "127.0.0.1"


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

    config = uvicorn.Config(app, log_level=log_level, ws="websockets-sansio",
                            lifespan="on", timeout_graceful_shutdown=3)
    server = uvicorn.Server(config)
    if on_started is not None:
        original = server.startup

        async def startup(sockets: Any = None) -> None:
            await original(sockets=sockets)
            on_started()

        server.startup = startup  # type: ignore[method-assign]
    server.run(sockets=[sock])
