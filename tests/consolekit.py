"""The console on a real arm session over the simulated arm, for the API, browser and bench.

``console_setup(folder)`` builds a project tree (arms, poses, sequences + a sequence with a
confirm step), opens the built-in simulator in real time with every frame the session sends
recorded (``Wire``), and an :class:`ArmSession` on it. ``LiveServer`` serves the app with
uvicorn on a free port of 127.0.0.1 in a thread (browser tests, bench).
"""

from __future__ import annotations

import shutil
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]

HALT_ID, HALT_DATA = 0x100, bytes([0x02])

CONFIRM_SEQUENCE = """\
name: Confirm then nudge
description: start-up, a question to the operator, then j1 turns by 3 degrees
steps:
  - include: startup.yaml
  - confirm: Is the space around the arm clear for the nudge?
  - move: {joints: {j1: 3}, label: Nudge j1}
"""

INVALID_SEQUENCE = """\
name: Too far
description: a target outside the limits
steps:
  - move: {joints: {j2: 150}}
"""


def project_tree(folder: Path) -> Path:
    for kind in ("arms", "poses", "sequences"):
        shutil.copytree(ROOT / kind, folder / kind)
    (folder / "sequences" / "confirm_nudge.yaml").write_text(CONFIRM_SEQUENCE)
    (folder / "sequences" / "too_far.yaml").write_text(INVALID_SEQUENCE)
    return folder


@dataclass
class Wire:
    """Every frame the session sent, with ``time.perf_counter()`` and ``time.time()`` (epoch
    seconds, comparable with a browser's ``performance.timeOrigin + timeStamp``) at the send."""

    frames: list[tuple[float, int, bytes, float]] = field(default_factory=list)

    def record(self, msg: Any) -> None:
        self.frames.append((time.perf_counter(), msg.arbitration_id, bytes(msg.data),
                            time.time()))

    def halts(self, since: float = 0.0) -> list[float]:
        return [t for t, can_id, data, _ in list(self.frames)
                if can_id == HALT_ID and data[:1] == HALT_DATA and t >= since]

    def halts_epoch(self, since_epoch: float = 0.0) -> list[float]:
        return [e for _, can_id, data, e in list(self.frames)
                if can_id == HALT_ID and data[:1] == HALT_DATA and e >= since_epoch]

    def motions(self, since: float = 0.0) -> int:
        """Motion commands (SetMotion 0x0B on a module's set id) sent since ``since``."""
        return sum(1 for t, can_id, data, _ in list(self.frames)
                   if t >= since and 0x0E1 <= can_id <= 0x0FF and data[:1] == b"\x0b")


#: Host requests that change nothing on a module: a read (GetExtended) or a Halt.
READ_OR_HALT = (0x0A, 0x02)


class BusListener:
    """An independent listener on the simulated bus: a second python-can bus on the same
    channel (not the session's), collecting every frame any host sends to the modules
    with ``time.perf_counter()`` at its arrival. What the console did, as the wire saw it."""

    def __init__(self, connection: Any) -> None:
        import can

        inner = connection.bus
        inner = getattr(inner, "inner", inner)  # (the tests' WrapBus)
        self.bus = can.Bus(interface="seqrun-sim", channel=inner.channel,
                           clock=connection.clock)
        self.frames: list[tuple[float, int, bytes]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="bus-listener")
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.05)
            if msg is not None and 0x0E0 <= msg.arbitration_id <= HALT_ID:
                # when the frame was on the wire (the simulator's own time stamp, the
                # monotonic clock), on the tests' perf_counter
                at = time.perf_counter() - (time.monotonic() - msg.timestamp)
                self.frames.append((at, msg.arbitration_id, bytes(msg.data)))

    def requests(self, since: float = 0.0) -> list[tuple[float, int, bytes]]:
        return [f for f in list(self.frames) if f[0] >= since]

    def halts(self, since: float = 0.0) -> list[float]:
        return [t for t, can_id, data in self.requests(since)
                if can_id == HALT_ID and data[:1] == HALT_DATA]

    def not_reads(self, since: float = 0.0) -> list[tuple[int, bytes]]:
        """Requests since ``since`` that are neither a read nor a Halt (a motion, a
        parameter write, a Reset or Home)."""
        return [(can_id, data) for _, can_id, data in self.requests(since)
                if not data or data[0] not in READ_OR_HALT]

    def wait_for_halt(self, since: float, timeout: float = 5.0) -> float:
        return wait_for(lambda: self.halts(since), timeout)[0]

    def saw_halt(self, since: float, timeout: float = 2.0) -> bool:
        """A Halt arrived since ``since`` (waiting up to ``timeout`` for it)."""
        try:
            self.wait_for_halt(since, timeout)
        except TimeoutError:
            return False
        return True

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.bus.shutdown()


@dataclass
class Setup:
    folder: Path
    arm: Any
    project: Any
    connection: Any
    session: Any
    wire: Wire
    runs: Path

    def catalog(self):
        from seqrun.console.catalog import Catalog

        return Catalog(self.project, self.runs)

    def app(self, **kw: Any):
        from seqrun.console.app import create_app

        return create_app(self.session, self.catalog(), self.arm, **kw)

    def close(self) -> None:
        self.session.close()


def console_setup(folder: Path, *, session_class: Any = None, arm_extra: str = "",
                  **session_kw: Any) -> Setup:
    """A campaign in ``folder`` and an arm session on the simulated arm; ``arm_extra``:
    YAML appended to the campaign's arm file (tools, say)."""
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from wrapbus import WrapBus

    from seqrun.arm.description import load_arm
    from seqrun.service.connection import open_connection
    from seqrun.sequence.project import open_project
    from seqrun.service.session import ArmSession

    project_tree(folder)
    if arm_extra:
        arm_file = folder / "arms" / "lwa3.yaml"
        arm_file.write_text(arm_file.read_text() + "\n" + arm_extra)
    project = open_project(folder)
    arm = load_arm(folder / "arms" / "lwa3.yaml").with_zero_reference("park")
    connection = open_connection(force_sim=True, default_bitrate=arm.can.bitrate)
    wire = Wire()
    connection.bus = WrapBus(connection.bus, before_send=wire.record)
    runs = folder / "runs"
    session = (session_class or ArmSession)(arm, connection, project=project, log_root=runs,
                                            **session_kw)
    return Setup(folder, arm, project, connection, session, wire, runs)


class LiveServer:
    """The console app served by uvicorn on 127.0.0.1:<free port> in a daemon thread."""

    def __init__(self, app: Any) -> None:
        import uvicorn

        from seqrun.console.server import bind, uvicorn_config

        self.sock = bind("127.0.0.1", 0)
        self.port = self.sock.getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}/"
        self.server = uvicorn.Server(uvicorn_config(app, graceful_s=2))
        self.server.install_signal_handlers = lambda: None  # type: ignore[method-assign]
        self.thread = threading.Thread(target=self.server.run,
                                       kwargs={"sockets": [self.sock]}, daemon=True)

    def __enter__(self) -> "LiveServer":
        self.thread.start()
        deadline = time.monotonic() + 20
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("the console server did not start")
            time.sleep(0.02)
        return self

    def __exit__(self, *exc: Any) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)
        try:
            self.sock.close()
        except OSError:
            pass


#: The header that carries the control secret (seqrun/service/control.py).
CONTROL = "X-Seqrun-Control"
#: Where the test client's requests claim to go (the Host a local browser sends).
LOCAL = "http://127.0.0.1:8765"
LIVE = "ws://127.0.0.1:8765/api/v1/live"


def refused(response, status: int, *words: str) -> str:
    """The response is a refusal with ``status``: one line naming ``words``, no traceback."""
    assert response.status_code == status, response.text
    message = response.json()["error"]
    assert "\n" not in message and "Traceback" not in message
    for word in words:
        assert word in message, message
    return message


def take_control(client: Any, name: str = "tests", ws: Any = None,
                 take_over: bool | None = None) -> str:
    """``client`` (a TestClient or an httpx client) takes control and sends the secret it
    got with every request from then on: as an API client named ``name``, or, given a
    page's live connection ``ws``, as that page (the page's secret, as the page's script
    keeps it). Returns the public client id (an API client) or the secret (a page).
    ``take_over`` (default: a page does, as its operator confirms; an API client does not):
    from the client that holds control."""
    if ws is not None:
        ws.send_json({"op": "take_control", "take_over": take_over is not False,
                      "id": "take"})
        while True:
            message = ws.receive_json()
            if message["type"] == "reply" and message["id"] == "take":
                break
        assert message["ok"] is True, message
        client.headers[CONTROL] = message["token"]
        return message["token"]
    r = client.post("/api/v1/control/take", json={"name": name, "take_over": bool(take_over)})
    assert r.status_code == 200, r.text
    client.headers[CONTROL] = r.json()["token"]
    return r.json()["client"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(predicate, timeout: float = 10.0, period: float = 0.02) -> Any:
    """Poll ``predicate`` until it returns something true; that value, or TimeoutError."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"condition not met within {timeout} s")
        time.sleep(period)


def console_process(log_dir: Path, *options: str) -> tuple[Any, str]:
    """``seqrun console --sim --port 0 --yes --log-dir LOG_DIR OPTIONS`` in a process of its
    own: the process and the URL it printed (with its token)."""
    import os
    import re
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "seqrun", "console", "--sim", "--port", "0",
                             "--yes", "--log-dir", str(log_dir), *options], cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)},
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    while True:
        line = proc.stdout.readline()
        if not line:
            proc.kill()
            proc.wait()
            raise RuntimeError("seqrun console ended before printing its URL:\n"
                               + "".join(lines))
        lines.append(line)
        found = re.search(r"(http://127\.0\.0\.1:\d+/\S*)", line)
        if found:
            if "token=" not in found.group(1):  # a console that prints no token
                proc.kill()
                proc.wait()
                raise RuntimeError(f"no token in the printed URL: {found.group(1)}")
            threading.Thread(target=lambda: proc.stdout.read(), daemon=True).start()
            return proc, found.group(1)
