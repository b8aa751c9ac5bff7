"""One operator holds control (issue 24, item 6): the service's ControlDesk on its own, and
the console's pages and API clients on a real session over the simulated arm."""

from __future__ import annotations

import time

import pytest
from consolekit import LIVE, LOCAL, BusListener, console_setup, take_control, wait_for
from fastapi.testclient import TestClient

from seqrun.errors import Refused
from seqrun.service.control import ControlDesk, NotInControl


# ------------------------------------------------------------------ the service's desk
def test_one_holder_many_watchers_and_every_change_is_an_event():
    events: list[tuple[str, dict]] = []
    desk = ControlDesk(publish=lambda type_, **f: events.append((type_, f)))
    desk.join("a", "tab A", "page", take_if_free=True)
    desk.join("b", "tab B", "page", take_if_free=True)  # taken already: B watches
    assert desk.state().holder.id == "a" and [c.id for c in desk.state().clients] == ["a", "b"]
    desk.require("a", "move")
    with pytest.raises(NotInControl, match="tab A holds control"):
        desk.require("b", "move")
    with pytest.raises(NotInControl, match="join and take control"):
        desk.require(None, "move")
    desk.take("b")  # explicitly, from the holder: the holder is told who took it
    assert desk.holds("b") and not desk.holds("a")
    taken = [f for t, f in events if t == "control_taken"][-1]
    assert taken["holder"]["id"] == "b" and taken["previous"]["id"] == "a"
    with pytest.raises(Refused):
        desk.release("a")  # not the holder
    desk.leave("b")  # a holder that leaves frees control
    released = [f for t, f in events if t == "control_released"][-1]
    assert released["left"] is True and released["holder"] is None
    assert desk.state().holder is None
    assert [t for t, _ in events] == ["client_joined", "control_taken", "client_joined",
                                      "control_taken", "control_released", "client_left"]
    assert all("clients" in f for _, f in events)  # the whole picture in every event


def test_the_session_s_control_publishes_typed_events(tmp_path):
    setup = console_setup(tmp_path)
    try:
        sub = setup.session.subscribe(maxsize=100)
        setup.session.control.join("x", "someone", "api", take_if_free=True)
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


def next_event(ws, type_: str, where=lambda event: True) -> dict:
    while True:
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
            assert a["control"]["holder"]["id"] == a["client"]
            assert b["control"]["holder"]["id"] == a["client"]  # B watches
            assert {c["id"] for c in b["control"]["clients"]} == {a["client"], b["client"]}
            as_a, as_b = {"X-Seqrun-Client": a["client"]}, {"X-Seqrun-Client": b["client"]}
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
            # B takes control explicitly: A is told who took it
            r = client.post("/api/v1/control/take", headers=as_b)
            assert r.status_code == 200 and r.json()["holder"]["id"] == b["client"]
            taken = next_event(tab_a, "control_taken", lambda e: e["previous"] is not None)
            assert taken["holder"]["id"] == b["client"]
            assert taken["previous"]["id"] == a["client"]
            r = client.post("/api/v1/reset", headers=as_a)
            assert r.status_code == 409 and b["client"] in r.json()["error"]
            assert client.post("/api/v1/reset", headers=as_b).status_code == 200
    finally:
        wire.close()


@pytest.mark.slow  # a run with a question, in real time
def test_a_question_says_who_started_the_run_and_only_the_holder_answers(setup):
    with TestClient(setup.app(), base_url=LOCAL) as client, \
            client.websocket_connect(LIVE) as tab_a, client.websocket_connect(LIVE) as tab_b:
        a, b = hello(tab_a), hello(tab_b)
        as_a, as_b = {"X-Seqrun-Client": a["client"]}, {"X-Seqrun-Client": b["client"]}
        r = client.post("/api/v1/run", json={"sequence": "confirm_nudge.yaml"}, headers=as_a)
        assert r.status_code == 200, r.text
        question = next_event(tab_b, "confirm_requested")
        assert question["started_by"].startswith(a["client"] + " · ")  # tab A, named
        answer = {"question_id": question["question_id"], "yes": True}
        r = client.post("/api/v1/answer", json=answer, headers=as_b)
        assert r.status_code == 409 and "holds control" in r.json()["error"]
        assert client.post("/api/v1/answer", json=answer, headers=as_a).status_code == 200
        finished = next_event(tab_a, "run_finished")
        assert finished["status"] == "passed", finished


def test_an_api_client_joins_takes_and_leaves(setup):
    with TestClient(setup.app(), base_url=LOCAL) as client, \
            client.websocket_connect(LIVE) as tab:
        page = hello(tab)["client"]
        assert client.post("/api/v1/arm-up").status_code == 409  # no id: not in control
        me = take_control(client, "coordinator script")
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
        assert client.post("/api/v1/control/leave").status_code == 200
        assert {c["id"] for c in client.get("/api/v1/control").json()["clients"]} == {page}
