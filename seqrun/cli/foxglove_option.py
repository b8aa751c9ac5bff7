"""``--foxglove[=PORT]`` of ``seqrun run`` and ``seqrun console``: the session's data live
for Foxglove on 127.0.0.1 (seqrun/foxglove/, docs/ros2.md)."""

from __future__ import annotations

import socket
from typing import Annotated, Any, Callable, Optional

import typer

from seqrun.cli.common import fail

FoxgloveOption = Annotated[Optional[int], typer.Option(
    "--foxglove", metavar="[=PORT]",
    help="Serve the arm live to Foxglove on ws://127.0.0.1:PORT (default 8766; 0: a free "
         "port): joint states, /tf, capsules and guards, events; STOP always, commands "
         "with control as in the console (docs/ros2.md). Needs seqrun[foxglove].")]


def check_foxglove(port: int | None) -> None:
    """Before anything is opened: the extra is installed and the port is free (one line,
    exit 2, otherwise)."""
    if port is None:
        return
    from seqrun.foxglove import MISSING, available

    if not available():
        fail(MISSING)
    if not 0 <= port <= 65535:
        fail(f"--foxglove: the port must lie in 0-65535, got {port}")
    if port:
        with socket.socket() as probe:
            # as the server binds: a port whose last client just left (TIME_WAIT) is free
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                probe.bind(("127.0.0.1", port))
            except OSError as exc:
                fail(f"--foxglove: cannot listen on 127.0.0.1:{port}: {exc.strerror or exc}")


def start_foxglove(session: Any, arm: Any, port: int | None,
                   say: Callable[[str], None]) -> Any:
    """The Foxglove server on ``session`` (None without ``--foxglove``); raises OSError or
    RuntimeError when it cannot start."""
    if port is None:
        return None
    from seqrun.foxglove.live import serve

    return serve(session, arm, port, say)
