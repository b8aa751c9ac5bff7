"""One operator holds control (issue 24, item 6): the service's ControlDesk on its own, and
the console's pages and API clients on a real session over the simulated arm."""

from __future__ import annotations

import json
import time

import pytest
from consolekit import (CONTROL, LIVE, LOCAL, BusListener, console_setup, take_control,
                        wait_for)
from fastapi.testclient import TestClient

from seqrun.errors import Refused
from seqrun.service.control import ControlDesk, NotInControl


# ------------------------------------------------------------------ the service's desk
def test_one_holder_many_watchers_and_every_change_is_an_event():
    events: list[tuple[str, dict]] = []
    stopped: list[str] = []
    desk = ControlDesk(publish=lambda type_, **f: events.append((type_, f)),
                       stop_motion=lambda client: stopped.append(client.id) or "jog stopped")
    desk.join("a", "tab A", "page")
    desk.join("b", "tab B", "page")
    grant_a = desk.take_if_free("a")
    assert grant_a is not None and desk.take_if_free("b") is None  # taken already: B watches
    assert desk.state().holder.id == "a" and [c.id for c in desk.state().clients] == ["a", "b"]
    assert desk.require(grant_a.secret, "move").id == "a"
    with pytest.raises(NotInControl, match="tab A holds control"):
        desk.require("a", "move")  # the public id is no credential
    with pytest.raises(NotInControl, match="secret"):
        desk.require(None, "move")
    with pytest.raises(Refused, match="tab A holds control.*take over"):
        desk.take("b")  # not silently: the holder must release, or B takes over
    grant_b = desk.take("b", take_over=True)
    assert stopped == ["a"]  # A's motion was stopped first
    assert desk.holds("b") and not desk.holds("a")
    with pytest.raises(NotInControl):
        desk.require(grant_a.secret, "move")  # A's secret is worth nothing now
    taken = [f for t, f in events if t == "control_taken"][-1]
    assert taken["holder"]["id"] == "b" and taken["previous"]["id"] == "a"
    assert taken["stopped"] == "jog stopped"
    with pytest.raises(Refused):
        desk.release(grant_a.secret)  # not the holder's secret
    desk.leave("b")  # a holder that leaves frees control, its motion stopped
    assert stopped == ["a", "b"]
    released = [f for t, f in events if t == "control_released"][-1]
    assert released["left"] is True and released["holder"] is None
    assert desk.state().holder is None
    assert [t for t, _ in events] == ["client_joined", "client_joined", "control_taken",
                                      "control_taken", "control_released", "client_left"]
    assert all("clients" in f for _, f in events)  # the whole picture in every event
    published = repr(events) + repr(desk.state().as_dict())
    assert grant_a.secret not in published and grant_b.secret not in published


def test_an_api_client_exists_only_while_it_holds_control():
    desk = ControlDesk()
    grant = desk.join_and_take("api-1", "script (api-1)", "api")
    with pytest.raises(Refused, match="script"):
        desk.join_and_take("api-2", "other (api-2)", "api")
    assert [c.id for c in desk.state().clients] == ["api-1"]  # the refused one is gone
    desk.release(grant.secret)
    assert desk.state().clients == ()


def test_the_session_s_control_publishes_typed_events(tmp_path):
    setup = console_setup(tmp_path)
    try:
        sub = setup.session.subscribe(maxsize=100)
        setup.session.control.join_and_take("x", "someone", "api")
        seen = wait_for(lambda: [e for e in sub.drain() if e.type == "control_taken"])
        assert type(seen[0]).__name__ == "ControlTaken" and seen[0].holder["name"] == "someone"
    finally:
        setup.close()


# ------------------------------------------------------------------ the console
@pytest.fixture
def setup(tmp_path):
    s = console_setup(tmp_path)
    yield s
    s.close()


def hello(ws) -> dict:
    message = ws.receive_json()
    assert message["type"] == "hello"
    return message


def next_event(ws, type_: str, where=lambda event: True, pinging=()) -> dict:
    """The next event ``type_`` on ``ws``; ``pinging``: pages kept alive meanwhile (a page
    silent for 2 s during its motion is taken as gone)."""
    while True:
        for page in pinging:
            page.send_json({"op": "ping"})
        message = ws.receive_json()
        if (message["type"] == "event" and message["event"]["type"] == type_
                and where(message["event"])):
            return message["event"]


def reply(ws, msg_id) -> dict:
    while True:
        message = ws.receive_json()
        if message["type"] == "reply" and message["id"] == msg_id:
            return message


def test_the_first_page_holds_control_the_others_watch_and_may_stop(setup):
    wire = BusListener(setup.connection)
    try:
        with TestClient(setup.app(), base_url=LOCAL) as client, \
                client.websocket_connect(LIVE) as tab_a, client.websocket_connect(LIVE) as tab_b:
            a, b = hello(tab_a), hello(tab_b)
            assert a["control"]["holder"]["id"] == a["client"] and a["token"]
            assert b["control"]["holder"]["id"] == a["client"]  # B watches
            assert b["token"] is None
            assert {c["id"] for c in b["control"]["clients"]} == {a["client"], b["client"]}
            as_a, as_b = {CONTROL: a["token"]}, {CONTROL: b["client"]}
            for path in ("/api/v1/arm-up", "/api/v1/home"):
                assert client.post(path, headers=as_a).status_code == 200
            # B may not command ...
            before = time.perf_counter()
            r = client.post("/api/v1/move/joints", json={"joints": {"j1": 5}}, headers=as_b)
            assert r.status_code == 409 and a["client"] in r.json()["error"], r.text
            tab_b.send_json({"op": "jog", "joint": "j1", "speed_scale": 0.5, "id": 1})
            refused = reply(tab_b, 1)
            assert refused["ok"] is False and "holds control" in refused["error"]
            assert wire.not_reads(before) == []
            # ... but may always STOP
            tab_b.send_json({"op": "halt", "id": 2})
            assert reply(tab_b, 2)["result"]["halt_confirmed"] is True
            assert wire.saw_halt(before)
            # B may not take control silently; it takes over, and A is told who took it
            tab_b.send_json({"op": "take_control", "id": 3})
            assert "take over" in reply(tab_b, 3)["error"]
            tab_b.send_json({"op": "take_control", "take_over": True, "id": 4})
            took = reply(tab_b, 4)
            assert took["ok"] is True and took["control"]["holder"]["id"] == b["client"]
            taken = next_event(tab_a, "control_taken", lambda e: e["previous"] is not None)
            assert taken["holder"]["id"] == b["client"]
            assert taken["previous"]["id"] == a["client"]
            r = client.post("/api/v1/reset", headers=as_a)
            assert r.status_code == 409 and b["client"] in r.json()["error"]
            assert client.post("/api/v1/reset", headers={CONTROL: took["token"]}
                               ).status_code == 200
    finally:
        wire.close()


def test_a_watching_page_that_sends_the_holder_s_id_commands_nothing(setup):
    """Issue 43: the holder's id was the credential (X-Seqrun-Client) and every page saw it:
    a watcher that sent it could arm, home and move, and the holder was never told."""
    wire = BusListener(setup.connection)
    try:
        with TestClient(setup.app(), base_url=LOCAL) as client, \
                client.websocket_connect(LIVE) as tab_a, client.websocket_connect(LIVE) as tab_b:
            a, b = hello(tab_a), hello(tab_b)
            holder = b["control"]["holder"]["id"]  # what the watcher sees of the holder
            assert holder == a["client"]
            spoof = {"X-Seqrun-Client": holder, CONTROL: holder}
            before = time.perf_counter()
            for path, body in (("/api/v1/arm-up", None), ("/api/v1/home", None),
                               ("/api/v1/move/joints", {"joints": {"j1": 5}}),
                               ("/api/v1/control/release", None)):
                r = client.post(path, json=body, headers=spoof)
                assert r.status_code == 409, (path, r.text)
            tab_b.send_json({"op": "jog", "joint": "j1", "speed_scale": 0.5, "token": holder,
                             "id": 1})
            assert reply(tab_b, 1)["ok"] is False
            assert wire.not_reads(before) == []  # nothing but reads reached the bus
            assert client.get("/api/v1/control").json()["holder"]["id"] == a["client"]
            # the secret itself never reaches another page: not in its hello, the events,
            # the list of clients, the event log
            tab_a.send_json({"op": "ping", "id": "x"})
            reply(tab_a, "x")
            seen = json.dumps(b) + json.dumps(client.get("/api/v1/control").json()) \
                + json.dumps(client.get("/api/v1/events").json())
            assert a["token"] not in seen
    finally:
        wire.close()


def j1(client) -> float:
    status = client.get("/api/v1/status").json()
    return next(j["position_deg"] for j in status["joints"] if j["name"] == "j1")


def test_releasing_control_ends_the_holder_s_move_with_a_controlled_stop(setup):
    wire = BusListener(setup.connection)
    try:
        with TestClient(setup.app(), base_url=LOCAL) as client, \
                client.websocket_connect(LIVE) as tab:
            as_page = {CONTROL: hello(tab)["token"]}
            for path in ("/api/v1/arm-up", "/api/v1/home"):
                assert client.post(path, headers=as_page).status_code == 200
            start = j1(client)
            tab.send_json({"op": "ping"})  # (a page that is silent for 2 s is taken as gone)
            r = client.post("/api/v1/move/joints", json={"joints": {"j1": 60}}, headers=as_page)
            assert r.status_code == 200, r.text
            wait_for(lambda: tab.send_json({"op": "ping"}) or j1(client) - start > 1.0)
            tab.send_json({"op": "release_control", "id": 1})
            assert reply(tab, 1)["ok"] is True
            status = client.get("/api/v1/status").json()
            assert status["activity"] == "idle", status
            assert 1.0 < j1(client) - start < 50
            assert client.get("/api/v1/control").json()["holder"] is None
            assert client.post("/api/v1/home", headers=as_page).status_code == 409
            assert not wire.halts()  # a controlled stop, not a Halt
    finally:
        wire.close()


def test_taking_over_stops_the_holder_s_move_first_and_tells_it(setup):
    wire = BusListener(setup.connection)
    try:
        with TestClient(setup.app(), base_url=LOCAL) as client, \
                client.websocket_connect(LIVE) as tab_a, client.websocket_connect(LIVE) as tab_b:
            a, b = hello(tab_a), hello(tab_b)
            as_a = {CONTROL: a["token"]}
            for path in ("/api/v1/arm-up", "/api/v1/home"):
                assert client.post(path, headers=as_a).status_code == 200
            start = j1(client)
            tab_a.send_json({"op": "ping"})
            r = client.post("/api/v1/move/joints", json={"joints": {"j1": 60}}, headers=as_a)
            assert r.status_code == 200, r.text
            wait_for(lambda: tab_a.send_json({"op": "ping"}) or j1(client) - start > 1.0)
            tab_b.send_json({"op": "take_control", "take_over": True, "id": 1})
            assert reply(tab_b, 1)["ok"] is True
            assert client.get("/api/v1/status").json()["activity"] == "idle"  # stopped first
            assert 1.0 < j1(client) - start < 50
            taken = next_event(tab_a, "control_taken", lambda e: e["previous"] is not None)
            assert taken["previous"]["id"] == a["client"]
            assert taken["stopped"] == "move stopped (controlled stop)"
            assert not wire.halts()  # a controlled stop, not a Halt
    finally:
        wire.close()


@pytest.mark.slow  # a run with a question, in real time
def test_a_question_says_who_started_the_run_and_only_the_holder_answers(setup):
    with TestClient(setup.app(), base_url=LOCAL) as client, \
            client.websocket_connect(LIVE) as tab_a, client.websocket_connect(LIVE) as tab_b:
        a, b = hello(tab_a), hello(tab_b)
        as_a, as_b = {CONTROL: a["token"]}, {CONTROL: b["client"]}
        r = client.post("/api/v1/run", json={"sequence": "confirm_nudge.yaml"}, headers=as_a)
        assert r.status_code == 200, r.text
        question = next_event(tab_b, "confirm_requested", pinging=(tab_a,))
        assert question["started_by"].startswith(a["client"] + " · ")  # tab A, named
        answer = {"question_id": question["question_id"], "yes": True}
        r = client.post("/api/v1/answer", json=answer, headers=as_b)
        assert r.status_code == 409 and "holds control" in r.json()["error"]
        assert client.post("/api/v1/answer", json=answer, headers=as_a).status_code == 200
        finished = next_event(tab_a, "run_finished", pinging=(tab_a,))
        assert finished["status"] == "passed", finished


def test_an_api_client_joins_takes_and_leaves(setup):
    with TestClient(setup.app(), base_url=LOCAL) as client, \
            client.websocket_connect(LIVE) as tab:
        page = hello(tab)["client"]
        assert client.post("/api/v1/arm-up").status_code == 409  # no secret: not in control
        r = client.post("/api/v1/control/take", json={"name": "coordinator script"})
        assert r.status_code == 409 and "take over" in r.json()["error"]  # the page holds it
        me = take_control(client, "coordinator script", take_over=True)
        state = client.get("/api/v1/control").json()
        assert state["holder"] == {"id": me, "name": f"coordinator script ({me})",
                                   "kind": "api"}
        assert {c["id"] for c in state["clients"]} == {page, me}
        taken = next_event(tab, "control_taken",  # the page, which held it, is told
                           lambda e: e["previous"] is not None)
        assert taken["previous"]["id"] == page and taken["holder"]["id"] == me
        assert client.post("/api/v1/arm-up").status_code == 200
        assert client.post("/api/v1/control/release").status_code == 200
        assert client.post("/api/v1/arm-up").status_code == 409
        assert {c["id"] for c in client.get("/api/v1/control").json()["clients"]} == {page}
