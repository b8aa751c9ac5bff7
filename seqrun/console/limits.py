"""Request bodies the console reads: at most :data:`~seqrun.console.bodies.MAX_BODY_BYTES`,
within :data:`~seqrun.console.bodies.BODY_TIMEOUT_S` of the request's head.

An ASGI middleware, outside every handler. A request that says it brings more
(``Content-Length``) is answered 413 before a byte of it is read — except STOP: its handler
halts first and then learns that the body was cut. A body that grows past the cap while it
is read (chunked), or trickles in too slowly, is cut: the handler sees the end of the body
and the reason in the scope (:data:`~seqrun.console.bodies.BODY_CUT`), and refuses it.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from seqrun.console.bodies import BODY_CUT, BODY_TIMEOUT_S, MAX_BODY_BYTES

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

_END = {"type": "http.request", "body": b"", "more_body": False}


def declared_length(scope: Scope) -> int | None:
    for key, value in scope.get("headers", ()):
        if key.lower() == b"content-length":
            try:
                return int(value)
            except ValueError:
                return None
    return None


class RequestLimits:
    """Caps what a request body may cost (size, time); ``always_read`` lists the paths whose
    handler runs whatever the body (STOP)."""

    def __init__(self, app: ASGIApp, *, always_read: frozenset[str],
                 max_bytes: int = MAX_BODY_BYTES, timeout_s: float = BODY_TIMEOUT_S) -> None:
        self.app = app
        self.always_read = always_read
        self.max_bytes = max_bytes
        self.timeout_s = timeout_s

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = declared_length(scope)
        too_large = length is not None and length > self.max_bytes
        if too_large and scope.get("path") not in self.always_read:
            body = json.dumps({"error": f"the request body is over {self.max_bytes} bytes "
                                        f"({length} announced)"}).encode()
            await send({"type": "http.response.start", "status": 413,
                        "headers": [(b"content-type", b"application/json"),
                                    (b"content-length", str(len(body)).encode()),
                                    (b"connection", b"close")]})
            await send({"type": "http.response.body", "body": body})
            return
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.timeout_s
        received = 0
        done = False

        async def limited_receive() -> Message:
            nonlocal received, done
            if done:  # after the body: the disconnect, whenever it comes
                return await receive()
            if too_large:
                scope[BODY_CUT] = "too large"
                done = True
                return dict(_END)
            try:
                message = await asyncio.wait_for(receive(), max(0.0, deadline - loop.time()))
            except asyncio.TimeoutError:
                scope[BODY_CUT] = "too slow"
                done = True
                return dict(_END)
            if message["type"] != "http.request":
                return message
            received += len(message.get("body", b""))
            if received > self.max_bytes:
                scope[BODY_CUT] = "too large"
                done = True
                return dict(_END)
            if not message.get("more_body", False):
                done = True
            return message

        await self.app(scope, limited_receive, send)
