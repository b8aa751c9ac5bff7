"""Who may talk to the console: the token, the Host header and the Origin header.

Checked for every HTTP request and every WebSocket before any handler runs (a pure ASGI
middleware, so nothing reaches the session first):

- **Token** (``seqrun console`` makes one at every start, on 127.0.0.1 too: any local
  process could otherwise command the arm): every request carries the token printed at
  start, as ``Authorization: Bearer TOKEN``, a ``?token=TOKEN`` query parameter (the URL
  printed at start, and WebSockets) or the cookie the page gets when it is opened with the
  token. Anything else: 401 — except STOP (``POST /api/v1/halt``): stopping the arm never
  needs a token.
- **Host** (default, 127.0.0.1) and **Origin**: :func:`seqrun.service.web_access.foreign`,
  the rules the Foxglove server applies too: the Host header must name this machine, and a
  browser request from another site's page (its Origin is not this console) is refused, so
  a page open in the operator's browser cannot send commands to the arm.
"""

from __future__ import annotations

import hmac
import json
import secrets
from collections.abc import Awaitable, Callable, MutableMapping
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import parse_qs

from seqrun.service.web_access import foreign

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

COOKIE = "seqrun_console_token"


def new_token() -> str:
    return secrets.token_urlsafe(24)


def _headers(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}


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

    def __init__(self, app: ASGIApp, *, token: str | None, local_only: bool,
                 open_to_all: frozenset[tuple[str, str]] = frozenset()) -> None:
        self.app = app
        self.token = token
        self.local_only = local_only
        #: (method, path) that need no token (STOP).
        self.open_to_all = open_to_all

    def refusal(self, scope: Scope) -> tuple[int, str] | None:
        reason = foreign(_headers(scope), local_only=self.local_only)
        if reason is not None:
            return 403, reason
        if self.token is not None and (scope.get("method"), scope.get("path")) \
                not in self.open_to_all:
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
        kind = b"application/json"
        if (scope["type"] == "http" and status == 401 and scope.get("path") == "/"
                and scope.get("method") == "GET"):
            body, kind = _TOKEN_PAGE.encode(), b"text/html; charset=utf-8"  # a person
        start = {"status": status, "headers": [(b"content-type", kind),
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


#: What a browser opened without the token shows: where to find the URL, and a STOP that
#: works without it.
_TOKEN_PAGE = """<!doctype html><html lang="en"><head><meta charset="utf-8">
<title>seqrun console: token required</title>
<style>body{font:16px system-ui,sans-serif;background:#15181c;color:#e4e7eb;margin:40px}
button{font:800 28px system-ui;color:#fff;background:#c81e1e;border:4px solid #fde047;
border-radius:10px;padding:18px 40px;cursor:pointer}</style></head><body>
<h1>seqrun console: token required</h1>
<p>Open the URL that <code>seqrun console</code> printed when it started: it carries the
token (<code>?token=...</code>).</p>
<p>Stopping the arm needs no token:</p>
<button id="stop" type="button">STOP</button> <span id="said"></span>
<script>
document.getElementById("stop").addEventListener("pointerdown", async () => {
  const said = document.getElementById("said");
  try {
    const r = await fetch("/api/v1/halt", {method: "POST"});
    const answer = await r.json();
    said.textContent = answer.message || answer.error || r.status;
  } catch (err) {
    said.textContent = "STOP FAILED: the console does not answer - use the emergency stop";
  }
});
</script></body></html>
"""
