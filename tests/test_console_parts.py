"""The console's parts on their own: the access guard (token, Host, Origin) on a bare
Starlette app, and the telemetry fan-out on the real event hub (a slow page gets the newest
status only, events in order, history bounded, the publisher never waits)."""

from __future__ import annotations

import asyncio
import json
import threading
import time

import pytest
from starlette.applications import Starlette
from starlette.responses import PlainTextResponse
from starlette.routing import Route, WebSocketRoute
from starlette.testclient import TestClient, WebSocketDenialResponse

from seqrun.console.guard import COOKIE, AccessGuard
from seqrun.console.telemetry import HISTORY, PageFeed, Telemetry, dumps, jsonable
from seqrun.events import EventHub, make_event


def _app(**guard) -> AccessGuard:
    async def hello(request):
        return PlainTextResponse("hello")

    async def socket(ws):
        await ws.accept()
        await ws.send_text("hello")
        await ws.close()

    return AccessGuard(Starlette(routes=[Route("/", hello, methods=["GET", "POST"]),
                                         WebSocketRoute("/ws", socket)]), **guard)


def test_token_by_header_query_or_cookie_else_401():
    client = TestClient(_app(token="t0k", local_only=False))
    for headers in ({}, {"Authorization": "Bearer nope"}, {"Authorization": "t0k"},
                    {"Cookie": f"{COOKIE}=nope"}, {"Cookie": "garbage;;=="}):
        r = client.get("/", headers=headers)  # (a person's browser: a page saying so)
        assert r.status_code == 401 and "token required" in r.text, headers
        r = client.post("/", headers=headers)
        assert r.status_code == 401 and "token" in r.json()["error"], headers
    assert client.get("/", headers={"Authorization": "Bearer t0k"}).text == "hello"
    assert client.get("/?token=t0k").text == "hello"
    assert client.get("/", headers={"Cookie": f"{COOKIE}=t0k"}).text == "hello"
    with pytest.raises(WebSocketDenialResponse) as denied:
        with client.websocket_connect("/ws"):
            pass
    assert denied.value.status_code == 401
    with client.websocket_connect("/ws?token=t0k") as ws:
        assert ws.receive_text() == "hello"


def test_local_only_refuses_other_host_names_and_foreign_origins():
    client = TestClient(_app(token=None, local_only=True), base_url="http://127.0.0.1:8765")
    assert client.get("/").text == "hello"
    assert client.get("/", headers={"Host": "localhost:8765"}).text == "hello"
    assert client.get("/", headers={"Host": "[::1]:8765"}).text == "hello"
    for host in ("evil.example", "evil.example:8765", "127.0.0.1.evil.example:8765"):
        r = client.get("/", headers={"Host": host})
        assert r.status_code == 403 and "host" in r.json()["error"], host
    for origin in ("http://evil.example", "null", "http://127.0.0.1:9999", "file://"):
        r = client.post("/", headers={"Origin": origin})
        assert r.status_code == 403 and "origin" in r.json()["error"], origin
    assert client.post("/", headers={"Origin": "http://127.0.0.1:8765"}).text == "hello"


def test_jsonable_never_emits_nan():
    from dataclasses import dataclass
    from pathlib import Path

    @dataclass
    class Thing:
        a: float
        b: tuple
        c: Path

    assert jsonable(Thing(float("nan"), (1, float("inf")), Path("/x"))) == \
        {"a": None, "b": [1, None], "c": "/x"}
    json.loads(dumps({"v": float("nan")}))  # valid JSON


class _Source:
    """What Telemetry needs of a session: subscribe() (the real hub) and status()."""

    def __init__(self) -> None:
        self.hub = EventHub()
        self.polls = 0

    def subscribe(self, **kw):
        return self.hub.subscribe(**kw)


def test_a_slow_page_gets_the_newest_status_and_every_event_in_order():
    source = _Source()
    counter = iter(range(10**6))
    telemetry = Telemetry(source, status_dict=lambda: {"n": next(counter)})

    async def scenario() -> list[str]:
        feed = PageFeed(asyncio.get_running_loop())
        telemetry.attach(feed)
        telemetry.start()
        try:
            for k in range(300):  # a burst: the page reads nothing meanwhile
                source.hub.publish(make_event("measurement", k * 0.01,
                                              {"joints_deg": [0.0] * 7, "state": [0] * 7}))
                if k % 100 == 0:
                    source.hub.publish(make_event("step_started", k * 0.01, {
                        "step": k // 100 + 1, "kind": "wait", "label": f"s{k}",
                        "location": "x:1:1"}))
            await asyncio.sleep(0.5)
            return await feed.next_batch()
        finally:
            telemetry.stop()

    out: list = []  # its own thread: Playwright's sync API may own this thread's loop
    worker = threading.Thread(target=lambda: out.append(asyncio.run(scenario())))
    worker.start()
    worker.join(30)
    batch = out[0]
    messages = [json.loads(m) for m in batch]
    events = [m["event"]["label"] for m in messages if m["type"] == "event"]
    statuses = [m for m in messages if m["type"] == "status"]
    assert events == ["s0", "s100", "s200"]
    assert len(statuses) == 1  # only the newest snapshot waits for a slow page
    assert telemetry.snapshots > 1 and statuses[0]["status"]["n"] > 0  # not the first


def test_the_history_for_new_pages_is_bounded_and_skips_measurements():
    source = _Source()
    telemetry = Telemetry(source, status_dict=lambda: {})
    telemetry.start()
    try:
        for k in range(HISTORY + 50):
            source.hub.publish(make_event("measurement", k, {"joints_deg": [0.0] * 7,
                                                             "state": [0] * 7}))
            source.hub.publish(make_event("retry", k, {"what": f"r{k}"}))
        deadline = time.monotonic() + 5
        while (not telemetry.history or json.loads(telemetry.history[-1])["event"]["what"]
               != f"r{HISTORY + 49}") and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        telemetry.stop()
    whats = [json.loads(h)["event"]["what"] for h in telemetry.history]
    assert len(whats) == HISTORY and whats[-1] == f"r{HISTORY + 49}" and whats[0] == "r50"


class _CountingLoop(asyncio.SelectorEventLoop):
    """An event loop that counts the wake-ups other threads ask of it."""

    wakes = 0

    def call_soon_threadsafe(self, *args, **kw):
        self.wakes += 1
        return super().call_soon_threadsafe(*args, **kw)


def test_one_snapshot_encoded_once_for_all_pages_and_none_without_pages():
    source = _Source()
    built = []
    telemetry = Telemetry(source, status_dict=lambda: built.append(1) or {"n": len(built)})

    def measure(n: int) -> None:
        for k in range(n):
            source.hub.publish(make_event("measurement", k * 0.01,
                                          {"joints_deg": [0.0] * 7, "state": [0] * 7}))
            time.sleep(0.01)

    def scenario() -> tuple[list, int]:
        loop = _CountingLoop()
        try:
            measure(20)  # no page open: nothing to build
            time.sleep(0.1)
            assert built == [] and telemetry.snapshots == 0
            feeds = [PageFeed(loop) for _ in range(3)]
            for feed in feeds:
                telemetry.attach(feed)
            measure(20)
            time.sleep(0.2)
            loop.run_until_complete(asyncio.sleep(0))  # deliver what the reader handed over
            batches = [loop.run_until_complete(feed.next_batch()) for feed in feeds]
            telemetry.stop()  # (its reader thread ends: the counts stand still)
            return batches, loop.wakes
        finally:
            loop.close()

    telemetry.start()
    out: list = []  # its own thread: Playwright's sync API may own this thread's loop
    try:
        worker = threading.Thread(target=lambda: out.append(scenario()))
        worker.start()
        worker.join(30)
    finally:
        telemetry.stop()
    batches, wakes = out[0]
    assert telemetry.snapshots > 0 and len(built) == telemetry.snapshots
    # every page gets the same encoded text, and the loop is woken once per snapshot,
    # not once per page
    assert batches[0][-1] is batches[1][-1] is batches[2][-1]
    assert wakes == telemetry.snapshots


def test_a_page_s_events_are_bounded_oldest_dropped_and_counted():
    from seqrun.console.telemetry import PAGE_EVENTS

    async def scenario() -> tuple[PageFeed, list[str]]:
        feed = PageFeed(asyncio.get_running_loop())
        for k in range(PAGE_EVENTS + 25):
            feed.push_event(f"e{k}")
        feed.push_status("s1")
        feed.push_status("s2")
        return feed, await feed.next_batch()

    # (a loop of its own on a thread of its own: a browser test before this one in the
    # same process may leave this thread's loop running)
    out: list[tuple[PageFeed, list[str]]] = []
    worker = threading.Thread(target=lambda: out.append(asyncio.run(scenario())))
    worker.start()
    worker.join(timeout=10)
    feed, batch = out[0]
    assert batch[0] == "e25" and batch[-2] == f"e{PAGE_EVENTS + 24}" and batch[-1] == "s2"
    assert len(batch) == PAGE_EVENTS + 1
    assert feed.dropped_events == 25 and feed.replaced_statuses == 1


def test_the_pages_share_a_budget_of_statuses():
    from seqrun.console.telemetry import MAX_STATUS_HZ, STATUS_BUDGET_PER_S

    telemetry = Telemetry(_Source(), status_dict=lambda: {})
    loop = asyncio.new_event_loop()
    try:
        assert telemetry.status_gap_s() == pytest.approx(1 / MAX_STATUS_HZ)
        for _ in range(3):  # a few tabs: every measurement
            telemetry.attach(PageFeed(loop))
        assert telemetry.status_gap_s() == pytest.approx(1 / MAX_STATUS_HZ)
        for _ in range(97):  # a hundred clients: their share each
            telemetry.attach(PageFeed(loop))
        assert telemetry.status_gap_s() == pytest.approx(100 / STATUS_BUDGET_PER_S)
        assert 100 / telemetry.status_gap_s() <= STATUS_BUDGET_PER_S + 1e-9
    finally:
        loop.close()
