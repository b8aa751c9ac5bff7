"""One page's live connection (``/api/v1/live``): telemetry and events out; STOP and jog in.

In: ``{"op": "halt"}``, ``{"op": "jog", "joint": "j2", "speed_scale": 0.5}`` (renewed by the
page every ~100 ms while the button is held; it needs control: this connection's secret, or
the one in ``token``), ``{"op": "jog_stop"}``, ``{"op": "take_control", "take_over": false}``
(the reply's ``token`` is this page's secret, sent to it alone; the hello carries it when the
page got control on joining), ``{"op": "release_control"}``, ``{"op": "ping"}``; an
``id`` is echoed in the reply ``{"type": "reply", "id": ..., "ok": bool, "error"?: str}``.
Messages are strict (:mod:`seqrun.console.models`): a repeated key, an unknown key or a value
of the wrong type is refused — except that a message that asks to STOP halts whatever else is
wrong with it (its reply carries a ``note``). A Halt never waits behind another message: it
is sent from its own thread at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections.abc import Awaitable
from typing import Any, Protocol

from fastapi import WebSocket, WebSocketDisconnect

from seqrun.console import models
from seqrun.console.bodies import Malformed, one_line, parse_json, printable, to_model
from seqrun.console.telemetry import PageFeed, dumps
from seqrun.errors import Refused, UserInputError

log = logging.getLogger(__name__)


class Console(Protocol):
    """What a live connection uses of the console (:class:`seqrun.console.app.Console`;
    named here, not imported: the app imports this module)."""

    live_connections: int
    max_pages: int
    telemetry: Any
    control: Any
    motions: Any

    def new_client_id(self) -> str: ...

    def arm_consoles(self, arm_id: str | None, *, every_if_none: bool = False
                     ) -> list[Any]: ...

    def halt_now(self, reason: str) -> Awaitable[Any]: ...

    def status_dict(self) -> dict[str, Any]: ...

#: A page sends something (a ping at least) every 0.5 s; one silent for this long while a
#: motion it started is under way is taken as gone (its motion is stopped).
PAGE_SILENCE_S = 2.0
#: Live connections at most (pages and tools); one more is refused (503) saying so.
MAX_PAGES = 100
#: A page that has not taken a message for this long (its connection's buffers full) is
#: closed: it is not reading, and whatever it shows is old.
SEND_STALL_S = 10.0
#: How often a connection looks at its page's silence and its sends (s).
STALL_CHECK_S = 0.5


class PageTooSlow(Exception):
    """The page did not take a message within :data:`SEND_STALL_S`."""


def wants_halt(raw: str, message: Any) -> bool:
    """The message asks to STOP: its ``op`` is "halt" (even next to other keys, a repeated
    ``op``, wrong types), or it is not JSON but names the op (a page's STOP with a broken
    encoder must still stop)."""
    if isinstance(message, dict):
        return message.get("op") == "halt"
    compact = "".join(raw.split())
    return '"op":"halt"' in compact


def _loose(raw: str) -> Any:
    """The message as JSON with the last of repeated keys (only to find a STOP and an id in
    a message that the strict parser refused)."""
    import json

    with contextlib.suppress(ValueError):
        return json.loads(raw, object_pairs_hook=_halt_wins)
    return None


def _halt_wins(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if any(key == "op" and value == "halt" for key, value in pairs):
        out["op"] = "halt"
    return out


def _message_id(message: Any) -> Any:
    value = message.get("id") if isinstance(message, dict) else None
    ok = (isinstance(value, str) and len(value) <= 64) or (
        isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= 2**53)
    return value if ok else None


async def refuse(ws: WebSocket, message: str, status: int = 503) -> None:
    """Refuse a live connection with an HTTP answer where the server can give one (a
    browser shows a failed connection either way; a tool reads the answer)."""
    from fastapi.responses import JSONResponse

    try:
        await ws.send_denial_response(JSONResponse({"error": message}, status_code=status))
    except RuntimeError:  # no denial responses: a close with the reason
        await ws.close(code=1013, reason=message[:120])


async def live(console: Console, ws: WebSocket) -> None:
    if console.live_connections >= console.max_pages:
        log.warning("console: live connection refused, %d open", console.live_connections)
        await refuse(ws, f"too many live connections ({console.max_pages} open): close a "
                         "page or a tool first")
        return
    console.live_connections += 1  # (counted before the first await: the cap holds)
    try:
        await _live(console, ws)
    finally:
        console.live_connections -= 1


def page_name(client: str, ws: WebSocket) -> str:
    """What the other clients see of a page: its id, its browser and where it is."""
    agent = ws.headers.get("user-agent", "")
    browser = next((name for key, name in (("Edg/", "Edge"), ("Firefox/", "Firefox"),
                                           ("Chrome/", "Chromium"), ("Safari/", "Safari"))
                    if key in agent), "a browser" if "Mozilla" in agent else "a tool")
    host = ws.client.host if ws.client else "?"
    where = "this PC" if host in ("127.0.0.1", "::1", "localhost", "testclient") else host
    return printable(f"{client} · {browser} on {where}")


async def _live(console: Console, ws: WebSocket) -> None:
    await ws.accept()
    loop = asyncio.get_running_loop()
    client = console.new_client_id()
    feed = PageFeed(loop)
    history = console.telemetry.attach(feed)
    # The first page of a console without a holder gets control; the others watch. The
    # secret of this page's control lives here and in the page's memory only.
    console.control.join(client, page_name(client, ws), "page")
    grant = console.control.take_if_free(client)
    secret: list[str | None] = [grant.secret if grant is not None else None]
    control = console.control.state()
    send_lock = asyncio.Lock()

    # When the send under way started (None: none is): a send that waits for the page for
    # longer than SEND_STALL_S ends the connection (checked by the receiving loop, below;
    # a timeout around every send would cost a task per message).
    sending_since: list[float | None] = [None]

    async def send(text: str) -> None:
        async with send_lock:
            sending_since[0] = loop.time()
            try:
                await ws.send_text(text)
            finally:
                sending_since[0] = None

    def stalled() -> bool:
        since = sending_since[0]
        return since is not None and loop.time() - since > SEND_STALL_S

    async def reply(msg_id: Any, ok: bool, **extra: Any) -> None:
        await send(dumps({"type": "reply", "id": msg_id, "ok": ok, **extra}))

    async def pump() -> None:
        gap = console.telemetry.status_gap_s
        while True:
            batch = await feed.next_batch()
            for text in batch:
                await send(text)
            if batch and batch[-1].startswith('{"type":"status"'):
                await asyncio.sleep(gap())  # this page's share of the status budget

    ops: asyncio.Queue[Any] = asyncio.Queue()

    async def worker() -> None:  # jog/jog_stop in order: a renewal never follows its stop
        while True:
            message = await ops.get()
            try:
                if isinstance(message, models.JogMessage):
                    (arm,) = console.arm_consoles(message.arm)  # (several: the one named)
                    holder = console.control.require(message.token or secret[0], "jog")
                    await asyncio.to_thread(arm.session.jog, message.joint,
                                            message.speed_scale, by=holder.name,
                                            mode=message.mode)
                    arm.motions.started(holder.id, "jog")
                elif isinstance(message, models.TakeControlMessage):
                    taken = await asyncio.to_thread(console.control.take, client,
                                                    take_over=message.take_over)
                    secret[0] = taken.secret  # (this page's reply only: never broadcast)
                    await reply(message.id, True, token=taken.secret,
                                control=taken.state.as_dict())
                    continue
                elif isinstance(message, models.ReleaseControlMessage):
                    released = await asyncio.to_thread(console.control.release, secret[0])
                    secret[0] = None
                    await reply(message.id, True, control=released.as_dict())
                    continue
                else:  # (several arms, none named: every arm's jog ends)
                    for arm in console.arm_consoles(message.arm, every_if_none=True):
                        await asyncio.to_thread(arm.session.jog_stop)
                        arm.motions.jog_ended(client)
                await reply(message.id, True)
            except (Refused, UserInputError) as exc:
                await reply(message.id, False, error=one_line(str(exc)))
            except Exception as exc:  # noqa: BLE001 - a bug: this message fails, not the arm
                log.error("console: live %s failed: %s", message.op, printable(repr(exc)))
                await reply(message.id, False,
                            error=one_line(printable(f"{message.op} failed: internal error ({exc!r})")))

    async def halt(msg_id: Any, reason: str, note: str | None) -> None:
        while not ops.empty():  # queued jog renewals die with the STOP
            ops.get_nowait()
        try:
            result = await console.halt_now(reason)
        except Exception as exc:  # noqa: BLE001 - the page must hear that STOP failed
            await reply(msg_id, False, error=one_line(f"Halt failed: {exc}"))
            return
        extra = {"note": one_line(note)} if note else {}
        await reply(msg_id, True, result=result, **extra)

    async def handle(raw: str) -> None:
        try:
            message: Any = parse_json(raw)
        except Malformed as exc:
            loose = _loose(raw)
            if wants_halt(raw, loose):
                await halt_task(_message_id(loose), "STOP (console)",
                                f"the arm was halted; the message was refused: {exc}")
                return
            await reply(_message_id(loose), False, error=one_line(f"malformed message: {exc}"))
            return
        if not isinstance(message, dict) or not isinstance(message.get("op"), str):
            await reply(_message_id(message), False,
                        error="malformed message: expected an object with an 'op'")
            return
        op, msg_id = message["op"], _message_id(message)
        kind = models.LIVE_MESSAGES.get(op)
        if kind is None:
            await reply(msg_id, False, error=one_line(f"unknown op '{op[:40]}'"))
            return
        try:
            parsed: Any = to_model(message, kind)
        except Malformed as exc:
            if op == "halt":
                await halt_task(msg_id, "STOP (console)",
                                f"the arm was halted; the message was refused: {exc}")
            else:
                await reply(msg_id, False, error=one_line(f"{op}: {exc}"))
            return
        if isinstance(parsed, models.HaltMessage):
            await halt_task(parsed.id, parsed.reason, None)
        elif isinstance(parsed, (models.JogMessage, models.JogStopMessage,
                                 models.TakeControlMessage, models.ReleaseControlMessage)):
            ops.put_nowait(parsed)
        elif parsed.id is not None:  # a ping that wants an answer
            await reply(parsed.id, True)

    halts: set[asyncio.Task[None]] = set()

    async def halt_task(msg_id: Any, reason: str, note: str | None) -> None:
        # The Halt's thread starts now; the reply goes out when it is confirmed, while the
        # next messages are read.
        task = asyncio.ensure_future(halt(msg_id, reason, note))
        halts.add(task)
        task.add_done_callback(halts.discard)
        await asyncio.sleep(0)  # let it start before anything else is read

    tasks: list[asyncio.Task[Any]] = []
    receiving: asyncio.Task[str] | None = None
    try:
        await send(dumps({"type": "hello", "client": client, "api_version": 1,
                          "status": console.status_dict(), "control": control.as_dict(),
                          "token": secret[0]}))
        for text in history:
            await send(text)
        pumping = asyncio.create_task(pump())
        tasks += [pumping, asyncio.create_task(worker())]
        heard = loop.time()
        while True:
            if receiving is None:
                receiving = asyncio.create_task(ws.receive_text())
            done, _ = await asyncio.wait({receiving, pumping}, timeout=STALL_CHECK_S,
                                         return_when=asyncio.FIRST_COMPLETED)
            if pumping in done or stalled():  # it does not read: nothing it shows is current
                log.warning("console page %s took no message for %.0f s: closed", client,
                            SEND_STALL_S)
                break
            if receiving in done:
                raw, receiving = receiving.result(), None
                heard = loop.time()
                await handle(raw)
                continue
            if loop.time() - heard < PAGE_SILENCE_S:
                continue
            # A page that went silent (a tablet off the Wi-Fi: no TCP close for a long
            # time) while its motion is under way is taken as gone.
            if await asyncio.to_thread(console.motions.owns_motion, client):
                log.warning("console page %s silent for %.1f s during its motion",
                            client, PAGE_SILENCE_S)
                break
    except (WebSocketDisconnect, PageTooSlow):
        pass
    except Exception as exc:  # noqa: BLE001 - a bug ends this connection, not the arm
        log.error("console: the live connection of %s failed: %s", client,
                  printable(repr(exc)))
    finally:
        for task in tasks + ([receiving] if receiving is not None else []):
            task.cancel()
        console.telemetry.detach(feed)
        # Its motion ends with a controlled stop (the desk's rule, then the page's own), on
        # a thread started at once: it runs to its end even if this connection's task is
        # torn down before the stop is confirmed.
        gone = threading.Thread(target=_page_gone, args=(console, client),
                                name=f"console page {client} gone", daemon=True)
        gone.start()
        await asyncio.to_thread(gone.join)
        # (already closed by the page, or not; a page that does not read never takes the
        # close frame either: the server drops the connection when this returns)
        with contextlib.suppress(Exception):
            await asyncio.wait_for(ws.close(), 1.0)


def _page_gone(console: Console, client: str) -> None:
    """A page's connection ended: it leaves the desk (a holder's motion stopped), and what
    it started stops (controlled)."""
    try:
        console.control.leave(client)
    finally:
        console.motions.page_gone(client)
