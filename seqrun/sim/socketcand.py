"""A socketcand server on the loopback interface, in front of a simulated arm.

``seqrun sim serve`` runs this so that other processes can drive the simulated LWA 3 with
python-can's own ``socketcand`` interface, exactly as they would a real bus served by
socketcand::

    can.Bus(interface="socketcand", host="127.0.0.1", port=29536, channel="can0")

Each TCP client is one node on the simulated wire (:mod:`seqrun.sim.network`): it sees
the module replies and every other client's frames, never its own (as a raw SocketCAN
socket does by default).

Protocol — the subset of socketcand's ASCII protocol python-can's client uses, one
``< ... >`` element per message, nothing after the closing ``>``::

    server: < hi >                              on connect
    client: < open CHANNEL >    server: < ok >  (or < error ... > for another channel)
    client: < rawmode >         server: < ok >
    client: < send 0E1 6 b 4 0 0 80 3f >        id hex, dlc hex, data bytes hex
    server: < frame 0A1 1700000000.123456 0B0464 >
    client: < echo >            server: < echo >

python-can reads each handshake answer with a single ``recv()`` and compares it exactly,
so the server sends nothing unasked until ``rawmode`` has been answered, and holds the
first frames back for ``RAWMODE_GRACE`` seconds so they cannot arrive glued to that
``< ok >`` — or until the client's first ``send``, which shows it has read it. Frame
timestamps are wall-clock (epoch) seconds like socketcand's, converted from the
simulation's monotonic delivery times.

Whole elements: after the handshake every element is padded with leading blanks to a
multiple of ``ELEMENT_ALIGN`` (64) bytes and written with one ``sendall`` (the frames
waiting for a client go out together). A client that reads a power-of-two number of bytes
at a time — python-can's reads 1024 — therefore never finds half an element at the end of
a read (python-can would log "Got incomplete message" for each, which also garbles
``python -m can.viewer``'s screen). Parsers look for the ``<``, so the blanks are harmless.

Every frame a client sent is delivered, also when the client disconnects right after
sending (a ``seqrun halt`` from a second terminal): the session reads its socket to the
end, and a closed endpoint's frames still go out (:meth:`Endpoint.close`). Bytes that are
not ASCII are answered with an ``< error ... >`` element; the session goes on.

Only loopback addresses are served: the simulator has no authentication and speaks for a
robot arm. Not implemented: broadcast-manager and control modes, ISO-TP, the UDP beacon,
remote and error frames.
"""

from __future__ import annotations

import ipaddress
import logging
import re
import select
import socket
import threading
import time
from typing import Self

from seqrun.errors import BusError
from seqrun.sim.network import Endpoint, NetworkClosedError, SimNetwork, WireFrame

logger = logging.getLogger(__name__)

DEFAULT_PORT = 29536
#: Seconds between answering ``< rawmode >`` and the first forwarded frame.
RAWMODE_GRACE = 0.05
_POLL = 0.2  # seconds between checks of the stop flag in blocking loops
_ELEMENT = re.compile(r"<([^<>]*)>")
#: Every element after the handshake is padded to a multiple of this many bytes.
ELEMENT_ALIGN = 64
#: Frames written to a client in one ``sendall`` at most.
_MAX_BATCH = 256


def check_loopback(host: str) -> str:
    """The numeric loopback address for ``host``.

    :raises ValueError: ``host`` is not a loopback address (or ``localhost``).
    """
    if host == "localhost":
        return "127.0.0.1"
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        raise ValueError(f"--host {host!r}: give a loopback IP address such as 127.0.0.1 "
                         "(the simulator serves this machine only)") from None
    if not address.is_loopback:
        raise ValueError(f"--host {host}: not a loopback address; the simulator serves this "
                         "machine only (127.0.0.1 or ::1)")
    return str(address)


def format_frame(frame: WireFrame, wall_timestamp: float) -> str:
    """``< frame ID SECS.USECS DATA >`` as socketcand sends it."""
    can_id = f"{frame.can_id:08X}" if frame.is_extended else f"{frame.can_id:03X}"
    seconds = int(wall_timestamp)
    micros = round((wall_timestamp - seconds) * 1e6)
    if micros == 1_000_000:
        seconds, micros = seconds + 1, 0
    return f"< frame {can_id} {seconds}.{micros:06d} {frame.data.hex().upper()} >"


def pad_element(text: str) -> str:
    """``text`` (one ``< ... >`` element) with leading blanks up to a multiple of
    :data:`ELEMENT_ALIGN` characters, so element boundaries fall on read boundaries."""
    return text.rjust(-(-len(text) // ELEMENT_ALIGN) * ELEMENT_ALIGN)


def parse_send(words: list[str]) -> WireFrame:
    """The frame of a ``< send ID DLC DATA... >`` element (``words`` after "send").

    :raises ValueError: with what is wrong.
    """
    if len(words) < 2:
        raise ValueError("send needs an id and a length")
    id_text, dlc_text, byte_texts = words[0], words[1], words[2:]
    can_id, dlc = int(id_text, 16), int(dlc_text, 16)
    extended = len(id_text) > 3
    data = bytes(int(b, 16) for b in byte_texts)
    if dlc != len(data):
        raise ValueError(f"length {dlc} but {len(data)} data bytes")
    return WireFrame(can_id, data, is_extended=extended)


class _Session:
    """One TCP client: reader thread (commands) and, in raw mode, writer thread (frames).

    The reader owns the session's end: it reads the socket to its end (so every frame the
    client sent is queued for the wire) and then closes. The writer only stops writing
    when the client is gone, and never blocks on a timeout: a client that reads slowly
    gets its frames late, never a closed session.
    """

    def __init__(self, server: SocketcandServer, conn: socket.socket, peer: object) -> None:
        self.server = server
        self.conn = conn
        self.peer = peer
        self.endpoint: Endpoint | None = None
        self.opened = False
        self._send_lock = threading.Lock()
        self._closed = threading.Event()
        #: Set once the client shows it has read the handshake (its first ``send``).
        self._handshake_read = threading.Event()
        #: Set once ``< rawmode >`` is answered: from then on every element is padded.
        self._aligned = False
        self.reader = threading.Thread(target=self._read_loop, daemon=True,
                                       name=f"socketcand-read-{peer}")
        self.writer: threading.Thread | None = None

    def start(self) -> None:
        self._send_text("< hi >")
        self.reader.start()

    def _write(self, text: str) -> None:
        """One element from the reader thread (answers and errors)."""
        self._send_text(pad_element(text) if self._aligned else text)

    def _error(self, message: object) -> None:
        # '<' and '>' would end the element early; the text may quote the client's bytes.
        text = str(message).replace("<", "(").replace(">", ")")
        self._write(f"< error {text} >")

    def _send_text(self, text: str) -> None:
        # backslashreplace: an element quoting a client's non-ASCII bytes stays ASCII.
        data = text.encode("ascii", "backslashreplace")
        with self._send_lock:
            self.conn.sendall(data)

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        if self.endpoint is not None:
            self.endpoint.close()  # (its frames not yet on the wire still go out)
        try:
            self.conn.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.conn.close()

    def _read_loop(self) -> None:
        buffer = ""
        try:
            while not self._closed.is_set():
                # select, not a socket timeout: a timeout would also cut the writer's
                # sendall short when the client reads slowly.
                ready, _, _ = select.select([self.conn], [], [], _POLL)
                if not ready:
                    continue
                chunk = self.conn.recv(4096)
                if not chunk:
                    break
                buffer += chunk.decode("ascii", errors="backslashreplace")
                while (match := _ELEMENT.search(buffer)) is not None:
                    buffer = buffer[match.end():]
                    self._command(match.group(1).split())
                if len(buffer) > 4096:  # garbage without a closing '>'
                    self._error("element too long")
                    buffer = ""
        except (OSError, ValueError) as exc:  # (ValueError: select on a closed socket)
            if not self._closed.is_set():
                logger.info("socketcand client %s: %s", self.peer, exc)
        finally:
            self.close()
            self.server._forget(self)

    def _command(self, words: list[str]) -> None:
        if not words:
            self._error("empty command")
            return
        verb, args = words[0], words[1:]
        if verb == "open":
            if args != [self.server.channel]:
                self._error(f"could not open bus {' '.join(args) or '(none)'}")
                return
            self.opened = True
            self._write("< ok >")
        elif verb == "rawmode":
            if not self.opened:
                self._error("open a bus first")
                return
            if self.endpoint is None:
                self.endpoint = self.server.network.attach(name=f"socketcand {self.peer}")
                self.writer = threading.Thread(target=self._forward_loop, daemon=True,
                                               name=f"socketcand-write-{self.peer}")
            self._write("< ok >")  # (unpadded: python-can compares it exactly)
            self._aligned = True
            if self.writer is not None and not self.writer.is_alive():
                self.writer.start()
        elif verb == "send":
            if self.endpoint is None:
                self._error("not in raw mode")
                return
            # A client that sends has read the rawmode "< ok >": no need to hold frames back.
            self._handshake_read.set()
            try:
                self.endpoint.send(parse_send(args), timeout=1.0)
            except (ValueError, BusError) as exc:
                self._error(exc)
        elif verb == "echo":
            self._write("< echo >")
        else:
            self._error(f"unsupported command {verb}")

    def _forward_loop(self) -> None:
        endpoint = self.endpoint
        assert endpoint is not None
        clock = self.server.network.clock
        self._handshake_read.wait(RAWMODE_GRACE)
        try:
            while not self._closed.is_set():
                frame = endpoint.receive(clock.now() + _POLL)
                parts: list[str] = []
                # Everything already delivered goes out in one write: fewer system calls
                # and thread switches when a client falls behind a busy wire.
                while frame is not None:
                    if not frame.is_remote:
                        parts.append(pad_element(format_frame(
                            frame, frame.timestamp + self.server.wall_offset)))
                    if len(parts) >= _MAX_BATCH:
                        break
                    frame = endpoint.receive(clock.now())  # (no waiting)
                if parts:
                    self._send_text("".join(parts))
        except NetworkClosedError:
            pass
        except OSError as exc:
            # The client is gone; the reader sees that too, reads what it had sent and
            # closes the session.
            if not self._closed.is_set():
                logger.info("socketcand client %s: %s", self.peer, exc)


class SocketcandServer:
    """Serves ``network`` on ``host:port`` (loopback only) as socketcand channel ``channel``.

    ``port=0`` picks a free port (see :attr:`port`). Use :meth:`start` for a background
    thread or :meth:`serve_forever` in the calling thread; :meth:`shutdown` stops either.
    """

    def __init__(self, network: SimNetwork, *, host: str = "127.0.0.1",
                 port: int = DEFAULT_PORT, channel: str = "can0") -> None:
        if network.clock.is_virtual:
            raise ValueError("the socketcand server runs in real time; give the network a "
                             "RealClock")
        self.network = network
        self.channel = channel
        self.host = check_loopback(host)
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        self._listener = socket.create_server((self.host, port), family=family, backlog=16)
        self._listener.settimeout(_POLL)
        self.port: int = self._listener.getsockname()[1]
        #: Added to the simulation's monotonic timestamps to give epoch seconds.
        self.wall_offset = time.time() - network.clock.now()
        self._sessions: set[_Session] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.shutdown()

    @property
    def client_count(self) -> int:
        with self._lock:
            return len(self._sessions)

    def start(self) -> threading.Thread:
        """Serve in a background (daemon) thread."""
        self._thread = threading.Thread(target=self.serve_forever, daemon=True,
                                        name=f"socketcand-{self.port}")
        self._thread.start()
        return self._thread

    def serve_forever(self) -> None:
        """Accept clients until :meth:`shutdown` (or KeyboardInterrupt in this thread)."""
        try:
            while not self._stop.is_set():
                try:
                    conn, peer = self._listener.accept()
                except TimeoutError:
                    continue
                except OSError:
                    if self._stop.is_set():
                        break
                    raise
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                session = _Session(self, conn, f"{peer[0]}:{peer[1]}")
                with self._lock:
                    self._sessions.add(session)
                try:
                    session.start()
                except OSError:
                    session.close()
                    self._forget(session)
        finally:
            self._close_all()

    def _forget(self, session: _Session) -> None:
        with self._lock:
            self._sessions.discard(session)

    def _close_all(self) -> None:
        self._listener.close()
        with self._lock:
            sessions = list(self._sessions)
            self._sessions.clear()
        for session in sessions:
            session.close()

    def shutdown(self, timeout: float = 2.0) -> None:
        """Stop accepting, disconnect every client. Safe to call twice."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        self._close_all()
