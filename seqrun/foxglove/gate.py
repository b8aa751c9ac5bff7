"""The door of the Foxglove server: the console's Host and Origin rules before a byte passes.

foxglove-sdk's server shows seqrun neither the WebSocket handshake's headers nor who
connects, so it cannot refuse a web page of another site by itself (a page open in the
operator's browser may open a WebSocket to 127.0.0.1). So the SDK listens on a loopback
address of its own, drawn at random in 127.0.0.0/8 with a random port (a page cannot find
it by trying), and this gate listens where seqrun says: it reads each connection's HTTP
upgrade request, refuses (403, one line) what :func:`seqrun.service.web_access.foreign`
refuses for the console too, and passes anything else through, byte for byte, both ways.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import secrets
import socket
import threading

from seqrun.service.web_access import foreign

#: The longest request head a client may send, and how long it has to send it.
HEAD_LIMIT = 16 * 1024
HEAD_TIMEOUT_S = 5.0
CHUNK = 64 * 1024
SERVER = "the Foxglove server"


def inner_host() -> str:
    """A loopback address no one guesses (127.x.y.z; Linux answers on all of 127.0.0.0/8)."""
    return (f"127.{1 + secrets.randbelow(254)}.{secrets.randbelow(256)}."
            f"{1 + secrets.randbelow(254)}")


def head_headers(head: bytes) -> dict[str, str]:
    """The request head's headers, names in lower case (a repeated header: the first)."""
    headers: dict[str, str] = {}
    for line in head.decode("latin-1").split("\r\n")[1:]:
        name, colon, value = line.partition(":")
        if colon:
            headers.setdefault(name.strip().lower(), value.strip())
    return headers


def refusal(reason: str) -> bytes:
    body = json.dumps({"error": reason}).encode()
    return (b"HTTP/1.1 403 Forbidden\r\nContent-Type: application/json\r\n"
            b"Content-Length: " + str(len(body)).encode() + b"\r\nConnection: close\r\n\r\n"
            + body)


class Gate:
    """Listens on ``host:port`` (0: a free port; :attr:`port` says which) and passes the
    connections the rules let through to ``inner`` (host, port), in a thread of its own."""

    def __init__(self, host: str, port: int, inner: tuple[str, int]) -> None:
        self.inner = inner
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        # (a port a client left a moment ago is free again at once)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((host, port))
            self.sock.listen(128)
        except OSError:
            self.sock.close()
            raise
        self.sock.setblocking(False)
        self.port: int = self.sock.getsockname()[1]
        self.loop = asyncio.new_event_loop()
        self._server: asyncio.AbstractServer | None = None
        self._connections: set[asyncio.Task[None]] = set()
        started = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(started,),
                                       name="foxglove gate", daemon=True)
        self.thread.start()
        started.wait(10.0)

    def _run(self, started: threading.Event) -> None:
        asyncio.set_event_loop(self.loop)
        self._server = self.loop.run_until_complete(asyncio.start_server(
            self._serve, sock=self.sock, limit=HEAD_LIMIT))
        started.set()
        self.loop.run_forever()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._connections.add(task)
        try:
            await self._pass(reader, writer)
        except (OSError, asyncio.IncompleteReadError, asyncio.LimitOverrunError,
                asyncio.TimeoutError, ValueError):
            pass  # a client that went, or sent no request: nothing to pass on
        except asyncio.CancelledError:
            # the gate closes with a client connected (a run's end): the connection ends
            # here; re-raised, asyncio would print a traceback after the run's summary
            pass
        finally:
            if task is not None:
                self._connections.discard(task)
            writer.close()

    async def _pass(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), HEAD_TIMEOUT_S)
        reason = foreign(head_headers(head), local_only=True, server=SERVER)
        if reason is not None:
            writer.write(refusal(reason))
            await writer.drain()
            return
        up_reader, up_writer = await asyncio.open_connection(*self.inner)
        try:
            up_writer.write(head)
            both = [asyncio.ensure_future(_pipe(reader, up_writer)),
                    asyncio.ensure_future(_pipe(up_reader, writer))]
            # either side ends: the connection ends (the SDK sees its client leave)
            _, pending = await asyncio.wait(both, return_when=asyncio.FIRST_COMPLETED)
            for task in pending:
                task.cancel()
        finally:
            up_writer.close()

    def close(self) -> None:
        def stop() -> None:
            if self._server is not None:
                self._server.close()
            for task in list(self._connections):
                task.cancel()
            self.loop.call_later(0.05, self.loop.stop)

        with contextlib.suppress(RuntimeError):  # (a loop that stopped already)
            self.loop.call_soon_threadsafe(stop)
        self.thread.join(timeout=5.0)
        with contextlib.suppress(OSError):
            self.sock.close()


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    with contextlib.suppress(OSError):
        while True:
            data = await reader.read(CHUNK)
            if not data:
                break
            writer.write(data)
            await writer.drain()


__all__ = ["Gate", "head_headers", "inner_host"]
