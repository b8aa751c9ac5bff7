"""``--foxglove[=PORT]`` and ``--foxglove-types`` of ``seqrun run`` and ``seqrun console``:
the session's data live for Foxglove on 127.0.0.1 (seqrun/foxglove/, docs/ros2.md)."""

from __future__ import annotations

import socket
from enum import Enum
from typing import Annotated, Any, Callable, Optional

import typer

from seqrun.cli.common import fail

FoxgloveOption = Annotated[Optional[int], typer.Option(
    "--foxglove", metavar="[=PORT]",
    help="Serve the arm live to Foxglove on ws://127.0.0.1:PORT (default 8766; 0: a free "
         "port): joint states, /tf, capsules and guards, events; STOP always, commands "
         "with control as in the console (docs/ros2.md). Needs seqrun[foxglove].")]




class FoxgloveTypes(str, Enum):
    """What the live channels carry (seqrun.foxglove.live.TYPES)."""

    foxglove = "foxglove"
    ros = "ros"


FoxgloveTypesOption = Annotated[Optional[FoxgloveTypes], typer.Option(
    "--foxglove-types", case_sensitive=False,
    help="With --foxglove: 'foxglove' (default): Foxglove's own schemas, read by every "
         "Foxglove and Lichtblick panel; 'ros': run.mcap's topics, ROS 2 types and CDR, so "
         "one layout serves live and recorded runs (docs/ros2.md).")]


def check_foxglove(port: int | None, types: FoxgloveTypes | None = None) -> None:
    """Before anything is opened: the extra is installed and the port is free (one line,
    exit 2, otherwise); ``--foxglove-types`` only with ``--foxglove``."""
    if port is None:
        if types is not None:
            fail(f"--foxglove-types {types.value}: only with --foxglove (it says what the "
                 "live channels carry)")
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
                   say: Callable[[str], None], types: FoxgloveTypes | None = None, *,
                   arms: Any = None) -> Any:
    """The Foxglove server on ``session`` (None without ``--foxglove``), or on every arm of
    a campaign's run (``arms``: arm id -> :class:`seqrun.foxglove.live.LiveArm`); raises
    OSError or RuntimeError when it cannot start."""
    if port is None:
        return None
    from seqrun.foxglove.live import DEFAULT_TYPES, serve

    return serve(session, arm, port, say,
                 types=types.value if types is not None else DEFAULT_TYPES, arms=arms)
