"""The bus owner's local control socket: how ``seqrun status`` and ``seqrun halt`` in
another terminal reach the process that holds the bus, instead of asking the modules
themselves (a second master on a bus without sequence numbers; see :mod:`.bus_claim`).

A unix-domain stream socket in the private runtime directory (its path is in the holder
record). One request per connection, one JSON line each way, every message with
``"v": 1``::

    -> {"v": 1, "op": "status"}
    <- {"v": 1, "ok": true, "status": {"joints": [...], "end_effector": {...}}, ...}
    -> {"v": 1, "op": "halt", "reason": "seqrun halt (pid 4711)"}
    <- {"v": 1, "ok": true, "halt": {"confirmed": true, "modules_confirmed": [...], ...}}
    <- {"v": 1, "ok": false, "error": "unknown op 'x'"}

The server runs in its own daemon thread, each connection in another: a slow or stuck
client never delays the owner's control loop, nor another client.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import threading
from pathlib import Path
from typing import Any, Protocol

from seqrun.service.bus_claim import BusClaim, Holder, holders, read_holder

#: The protocol's version, in every message.
PROTOCOL_VERSION = 1
#: How long either side waits for the other's line, s (a Halt confirmation takes < 1 s).
IO_TIMEOUT_S = 5.0
_MAX_LINE = 1 << 16

logger = logging.getLogger(__name__)


class ControlHandler(Protocol):
    """What the owner answers with (an arm session, or ``seqrun run``'s run)."""

    def status_dict(self) -> dict: ...

    def halt(self, reason: str) -> dict: ...


def halt_reply(result: Any, joint_names: dict[int, str], by: str) -> dict:
    """The ``halt`` op's answer, whoever owns the bus (a run or a console's session):
    ``confirmed``, ``sent``, ``modules_confirmed``, ... of a driver's
    :class:`~seqrun.drivers.base.CommandConfirmation`, and its one-line ``message``."""
    return {"confirmed": result.confirmed, "sent": result.sent,
            "modules_confirmed": list(result.modules_confirmed),
            "modules_unconfirmed": list(result.modules_unconfirmed),
            "attempts": result.attempts, "error": result.error,
            "states": {str(k): getattr(v, "text", str(v)) for k, v in result.states.items()},
            "message": result.describe(joint_names), "confirmed_by": by}


def reading_row(joint: str, module: int, position_deg: float | None,
                velocity_deg_s: float | None, state: str | None, fault: bool,
                stale: bool) -> dict:
    """One joint of the ``status`` op's answer: the row ``seqrun status`` prints (the
    shape of :func:`seqrun.service.arm_access.status_rows`), whoever owns the bus."""
    return {"joint": joint, "module": module, "position_deg": position_deg,
            "velocity_deg_s": velocity_deg_s, "state": state, "fault": fault, "stale": stale}


def handle_request(handler: ControlHandler, line: bytes) -> dict:
    """The reply to one request line (never raises)."""
    try:
        request = json.loads(line)
    except ValueError:
        return _error("not a JSON line")
    if not isinstance(request, dict):
        return _error("a request is a JSON object")
    if request.get("v") != PROTOCOL_VERSION:
        return _error(f"protocol version {request.get('v')!r} not supported "
                      f"(this seqrun speaks {PROTOCOL_VERSION})")
    op = request.get("op")
    try:
        if op == "status":
            return {"v": PROTOCOL_VERSION, "ok": True, "status": handler.status_dict()}
        if op == "halt":
            reason = str(request.get("reason") or "halt from another process")
            return {"v": PROTOCOL_VERSION, "ok": True, "halt": handler.halt(reason)}
    except Exception as exc:  # noqa: BLE001 - the client gets the reason, the owner goes on
        logger.exception("control request %r failed", op)
        return _error(f"{op} failed: {type(exc).__name__}: {exc}")
    return _error(f"unknown op {op!r} (status, halt)")


def _error(text: str) -> dict:
    return {"v": PROTOCOL_VERSION, "ok": False, "error": text}


class ControlServer:
    """Serves ``handler`` on ``path`` until :meth:`close`."""

    def __init__(self, path: Path, handler: ControlHandler) -> None:
        self.path = Path(path)
        self.handler = handler
        self._closed = threading.Event()
        try:
            self.path.unlink()       # a dead owner's socket file (the lock said it is dead)
        except FileNotFoundError:
            pass
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self._sock.bind(str(self.path))
            os.chmod(self.path, 0o600)
            self._sock.listen(8)
            self._sock.settimeout(0.25)   # the accept loop notices close() within this
        except BaseException:
            self._sock.close()
            raise
        self._thread = threading.Thread(target=self._accept_loop, name="seqrun-control",
                                        daemon=True)
        self._thread.start()

    def _accept_loop(self) -> None:
        while not self._closed.is_set():
            try:
                conn, _ = self._sock.accept()
            except socket.timeout:
                continue
            except OSError:
                return            # closed
            threading.Thread(target=self._serve, args=(conn,), name="seqrun-control-client",
                             daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        with conn:
            try:
                conn.settimeout(IO_TIMEOUT_S)
                line = _read_line(conn)
                reply = handle_request(self.handler, line)
                conn.sendall(json.dumps(reply, default=_jsonable).encode() + b"\n")
            except OSError as exc:
                logger.debug("control client went away: %r", exc)

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        try:
            # wakes the accept loop now (Linux): close() alone leaves it blocked until
            # its timeout, a thread outliving the run that served it
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()
        try:
            self.path.unlink()
        except OSError:
            pass
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)


def _jsonable(value: Any) -> Any:
    """numpy scalars and arrays in a reply."""
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)


def _read_line(conn: socket.socket) -> bytes:
    data = b""
    while b"\n" not in data:
        chunk = conn.recv(4096)
        if not chunk:
            break
        data += chunk
        if len(data) > _MAX_LINE:
            raise OSError("request line too long")
    return data.split(b"\n", 1)[0]


def serve_control(claim: BusClaim, handler: ControlHandler) -> ControlServer | None:
    """Serve ``handler`` for as long as ``claim`` is held (released with it); the socket's
    path goes into the holder record. None when the socket cannot be served: the claim
    still holds, other processes are then refused without being answered."""
    try:
        server = ControlServer(claim.socket_path, handler)
    except OSError as exc:
        logger.warning("control socket %s not served: %s", claim.socket_path, exc)
        return None
    claim.on_release(server.close)
    claim.set_socket(str(server.path))
    return server


def send_request(path: str | Path, request: dict, *, timeout: float = IO_TIMEOUT_S) -> dict:
    """One request to the socket at ``path``; the reply.

    :raises OSError: nobody listens there, or no whole reply within ``timeout``.
    """
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(timeout)
        sock.connect(str(path))
        sock.sendall(json.dumps({"v": PROTOCOL_VERSION, **request}).encode() + b"\n")
        line = _read_line(sock)
    if not line:
        raise OSError("the owner closed the connection without an answer")
    try:
        reply = json.loads(line)
    except ValueError:
        raise OSError("the owner's answer is not JSON") from None
    if not isinstance(reply, dict):
        raise OSError("the owner's answer is not a JSON object")
    return reply


def owner(interface: str, channel: str, *, directory: Path | None = None) -> Holder | None:
    """The holder of the bus, if it is alive and serves a control socket."""
    holder = read_holder(interface, channel, directory=directory)
    if holder is None or not holder.socket or not holder.alive():
        return None
    return holder


def live_owners(*, directory: Path | None = None) -> list[Holder]:
    """Every live seqrun (run or console) of this user on this machine that serves a
    control socket, whatever its bus (the built-in simulator's included)."""
    return [h for h in holders(directory=directory)
            if h.socket and not h.transient and h.alive() and Path(h.socket).exists()]


def ask_holder(holder: Holder, op: str, *, reason: str | None = None,
               timeout: float = IO_TIMEOUT_S) -> dict | None:
    """:func:`ask_owner` for a holder already found (:func:`live_owners`)."""
    if holder.socket is None:
        return None
    request: dict[str, Any] = {"op": op}
    if reason is not None:
        request["reason"] = reason
    try:
        reply = send_request(holder.socket, request, timeout=timeout)
    except (FileNotFoundError, ConnectionRefusedError):
        return None           # the owner has just gone (or never served)
    except OSError as exc:
        reply = _error(f"no answer from pid {holder.pid}: {exc.strerror or exc}")
    reply["holder"] = holder.as_dict()
    return reply


def ask_owner(interface: str, channel: str, op: str, *, reason: str | None = None,
              timeout: float = IO_TIMEOUT_S, directory: Path | None = None
              ) -> dict | None:
    """Ask the process that holds the bus (``op``: ``status`` or ``halt``).

    :return: None when nobody holds it or the holder serves no socket (then the caller may
        claim the bus itself); else the reply, with ``"holder"`` (its record as a dict)
        added. A holder that did not answer gives ``{"ok": False, "error": ...}``.
    """
    holder = owner(interface, channel, directory=directory)
    if holder is None:
        return None
    return ask_holder(holder, op, reason=reason, timeout=timeout)
