"""A zero reference recorded for tests that drive `seqrun sim serve` as a real arm: the
served arm powers on at Park, and a real interface needs the record, which belongs to the
arm (its serial numbers, read over its bus), and the operator's word at the power-on
(``--zero-confirmed park``: ``--yes`` does not give it)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

#: What a run on a freshly served arm adds: the operator's word that it stands in Park.
ZERO_CONFIRMED = ("--zero-confirmed", "park")


def socketcand_args(port: int) -> list[str]:
    return ["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1", f"port={port}"]


def with_park_recorded(env: dict, folder: Path, port: int, *,
                       arm_file: Path | None = None, cwd: Path | None = None) -> dict:
    """``env`` with its own state folder in ``folder`` holding a Park record of the arm
    served on ``port``."""
    env = {**env, "SEQRUN_STATE_DIR": str(folder / "zero-state")}
    arm = ["--arm", str(arm_file)] if arm_file is not None else []
    done = subprocess.run([sys.executable, "-m", "seqrun", "zero", "set", "park", "--yes",
                           *arm, *socketcand_args(port)],
                          capture_output=True, text=True, env=env, timeout=60, cwd=cwd)
    assert done.returncode == 0, done.stdout + done.stderr
    return env


def serve_arm(folder: Path, *serve_args: str, cwd: Path,
              **popen) -> tuple[subprocess.Popen, int, dict]:
    """``seqrun sim serve`` on a free loopback port, treated as a real arm (a Park zero
    record in its own state folder under ``folder``), accepting connections:
    ``(server, port, env)``; the caller kills the server. Runs on it add
    :data:`ZERO_CONFIRMED`."""
    import os
    import socket
    import time

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = dict(os.environ, PYTHONPATH=str(cwd))
    popen.setdefault("stdout", subprocess.DEVNULL)
    popen.setdefault("stderr", subprocess.DEVNULL)
    server = subprocess.Popen([sys.executable, "-m", "seqrun", "sim", "serve", "--port",
                               str(port), *serve_args], cwd=cwd, env=env, **popen)
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            break
        except OSError:
            time.sleep(0.1)
    return server, port, with_park_recorded(env, folder, port, cwd=cwd)
