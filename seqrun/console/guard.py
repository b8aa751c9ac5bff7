"""Who may talk to the console: the token, the Host header and the Origin header.

Checked for every HTTP request and every WebSocket before any handler runs (a pure ASGI
middleware, so nothing reaches the session first):

- **Token** (``--host``: the console listens beyond this machine): every request carries
  the token printed at start, as ``Authorization: Bearer TOKEN``, a ``?token=TOKEN`` query
  parameter (the URL printed at start, and WebSockets) or the cookie the page gets when it
  is opened with the token. Anything else: 401.
- **Host** (default, 127.0.0.1): the Host header must name this machine, so a web page of
  another site cannot reach the console through a DNS name that resolves to 127.0.0.1.
- **Origin**: a browser request from another site's page (its Origin is not this console)
  is refused, so a page open in the operator's browser cannot send commands to the arm.
"""

from __future__ import annotations

import hmac
import json
import secrets
from collections.abc import Awaitable, Callable, MutableMapping
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import parse_qs, urlsplit

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

COOKIE = "seqrun_console_token"
LOCAL_HOSTS = frozenset({"127.0.0.1", "localhost", "::1", "[::1]"})


def new_token() -> str:
    return secrets.token_urlsafe(24)


def _headers(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}


def _host_name(host: str) -> str:
    """``127.0.0.1:8765`` -> ``127.0.0.1``, ``[::1]:8765`` -> ``[::1]``."""
    if host.startswith("["):
        return host[:host.find("]") + 1]
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def presented_token(scope: Scope) -> str | None:
    headers = _headers(scope)
    auth = headers.get("authorization", "")
    if auth.lower().startswith("bearer "):
        return auth[7:].strip()
    query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
    if query.get("token"):
        return query["token"][0]
    if "cookie" in headers:
        cookie: SimpleCookie = SimpleCookie()
        try:
            cookie.load(headers["cookie"])
        except Exception:  # noqa: BLE001 - a malformed cookie header is no token
            return None
        if COOKIE in cookie:
            return cookie[COOKIE].value
    return None


class AccessGuard:
    """ASGI middleware: refuses (401/403) before the application sees the request."""

    def __init__(self, app: ASGIApp, *, token: str | None, local_only: bool) -> None:
        self.app = app
        self.token = token
        self.local_only = local_only

    def refusal(self, scope: Scope) -> tuple[int, str] | None:
        headers = _headers(scope)
        host = headers.get("host", "")
        if self.local_only and _host_name(host) not in LOCAL_HOSTS:
            return 403, f"host '{host}' refused: the console answers on 127.0.0.1 only"
        origin = headers.get("origin")
        if origin is not None and urlsplit(origin).netloc != host:  # "null" too (file://)
            return 403, f"origin '{origin}' refused: only the console's own page may send commands"
        if self.token is not None:
            given = presented_token(scope)
            if given is None or not hmac.compare_digest(given.encode(), self.token.encode()):
                return 401, "token required: open the URL printed when the console started"
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        refused = self.refusal(scope)
        if refused is None:
            await self.app(scope, receive, send)
            return
        status, message = refused
        body = json.dumps({"error": message}).encode()
        start = {"status": status, "headers": [(b"content-type", b"application/json"),
                                               (b"content-length", str(len(body)).encode())]}
        if scope["type"] == "http":
            await send({"type": "http.response.start", **start})
            await send({"type": "http.response.body", "body": body})
            return
        # WebSocket: the HTTP answer itself where the server supports it, else a close.
        await receive()  # websocket.connect
        if "websocket.http.response" in scope.get("extensions", {}):
            await send({"type": "websocket.http.response.start", **start})
            await send({"type": "websocket.http.response.body", "body": body})
        else:
            await send({"type": "websocket.close", "code": 4000 + status, "reason": message})
