"""The console under attack (issue 24), watched from the wire by an independent listener
(a second bus on the simulated channel, not the session's): STOP always stops, whatever its
body; a mistyped command never becomes motion.
"""

from __future__ import annotations

import json
import time

import pytest
from consolekit import LIVE, LOCAL, BusListener, console_setup, take_control
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

JSON = {"Content-Type": "application/json"}


@pytest.fixture
def setup(tmp_path):
    s = console_setup(tmp_path)
    yield s
    s.close()


@pytest.fixture
def wire(setup):
    listener = BusListener(setup.connection)
    yield listener
    listener.close()


@pytest.fixture
def client(setup):
    with TestClient(setup.app(), base_url=LOCAL, raise_server_exceptions=False) as c:
        take_control(c)
        yield c


def armed(client) -> None:
    for path in ("/api/v1/arm-up", "/api/v1/home"):
        r = client.post(path)
        assert r.status_code == 200, r.text


def reply_to(ws, msg_id):
    while True:
        message = ws.receive_json()
        if message["type"] == "reply" and message.get("id") == msg_id:
            return message


# ------------------------------------------------------------------ 1. STOP always stops
BAD_HALT_BODIES = {
    "invalid JSON": (b'{"reason": ', JSON),
    "reason null": (b'{"reason": null}', JSON),
    "reason over 200 characters": (json.dumps({"reason": "x" * 300}).encode(), JSON),
    "an extra key": (b'{"reason": "r", "force": true}', JSON),
    "text/plain": (b'{"reason": "r"}', {"Content-Type": "text/plain"}),
    "a number for the reason": (b'{"reason": 5}', JSON),
    "not an object": (b'["halt"]', JSON),
    "duplicate keys": (b'{"reason": "a", "reason": "b"}', JSON),
    "a huge body": (b'{"reason": "' + b"x" * (8 << 20) + b'"}', JSON),
}


@pytest.mark.parametrize("what", list(BAD_HALT_BODIES))
def test_http_stop_halts_whatever_its_body_then_says_what_was_wrong(client, wire, what):
    body, headers = BAD_HALT_BODIES[what]
    before = time.perf_counter()
    r = client.post("/api/v1/halt", content=body, headers=headers)
    assert wire.saw_halt(before), f"{what}: no Halt on the wire ({r.status_code} {r.text[:200]})"
    assert r.status_code == 200, r.text[:300]
    answer = r.json()
    assert answer["halt_sent"] is True and answer["halt_confirmed"] is True, answer
    assert answer["note"] and "\n" not in answer["note"], answer  # what was wrong with it


def test_http_stop_without_a_body_or_with_a_good_one_has_no_note(client, wire):
    for kwargs in ({}, {"json": {"reason": "test STOP"}}):
        before = time.perf_counter()
        answer = client.post("/api/v1/halt", **kwargs).json()
        assert wire.saw_halt(before) and answer["halt_confirmed"] is True
        assert "note" not in answer, answer


def test_a_moving_arm_is_halted_by_a_malformed_stop(client, setup, wire):
    armed(client)
    assert client.post("/api/v1/move/joints", json={"joints": {"j1": 60}}).status_code == 200
    from consolekit import wait_for

    wait_for(lambda: (setup.session.status().joints[0].position_deg or 0) > 1.0)
    before = time.perf_counter()
    r = client.post("/api/v1/halt", content=b'{"reason": null, "extra": 1}', headers=JSON)
    assert wire.saw_halt(before) and r.status_code == 200, r.text
    assert wait_for(lambda: setup.session.status().activity == "halted", timeout=10)
    stopped = setup.session.status().joints[0].position_deg
    time.sleep(0.3)
    assert setup.session.status().joints[0].position_deg == pytest.approx(stopped, abs=0.05)


BAD_HALT_MESSAGES = [
    '{"op": "halt", "reason": null, "id": 1}',
    '{"op": "halt", "reason": 5, "id": 1}',
    '{"op": "halt", "reason": "r", "force": true, "id": 1}',
    '{"op": "halt", "reason": "' + "x" * 300 + '", "id": 1}',
    '{"op": "halt", "op": "halt", "id": 1}',
    '{"op": "jog", "op": "halt", "id": 1}',
    '{"op": "halt", "id": 1',  # not even JSON
]


@pytest.mark.parametrize("text", BAD_HALT_MESSAGES)
def test_a_malformed_live_stop_still_halts(client, wire, text):
    with client.websocket_connect(LIVE) as ws:
        ws.receive_json()
        before = time.perf_counter()
        ws.send_text(text)
        wire.wait_for_halt(before)
        reply = next(m for m in iter(ws.receive_json, None)
                     if m["type"] == "reply" and "result" in m)
        assert reply["result"]["halt_confirmed"] is True, reply
        assert reply.get("note"), reply


# ------------------------------------------------------------------ 2. wrong types never move
MISTYPED = [
    ("/api/v1/move/joints", b'{"joints": {"j1": true}}'),
    ("/api/v1/move/joints", b'{"joints": {"j1": false}}'),
    ("/api/v1/move/joints", b'{"joints": {"j1": "12"}}'),
    ("/api/v1/move/joints", b'{"joints": {"j1": " 14 "}}'),
    ("/api/v1/move/joints", b'{"joints": {"j1": 5, "j1": 6}}'),
    ("/api/v1/move/joints", b'{"joints": {"j1": 5}, "joints": {"j1": 6}}'),
    ("/api/v1/move/pose", b'{"name": "totem", "velocity_scale": true}'),
    ("/api/v1/move/pose", b'{"name": "totem", "velocity_scale": "0.5"}'),
    ("/api/v1/jog", b'{"joint": "j1", "speed_scale": true}'),
    ("/api/v1/velocities", b'{"joints": {"j1": true}}'),
    ("/api/v1/run", b'{"sequence": "confirm_nudge.yaml", "step_mode": 0}'),
    ("/api/v1/run", b'{"sequence": "confirm_nudge.yaml", "first_step": true}'),
    ("/api/v1/run", b'{"sequence": "confirm_nudge.yaml", "speed": "1"}'),
]


def test_the_reported_mistyped_commands_are_refused_and_nothing_moves(client, wire):
    armed(client)
    before = time.perf_counter()
    for path, body in MISTYPED:
        r = client.post(path, content=body, headers=JSON)
        assert r.status_code == 422, (path, body, r.status_code, r.text)
        assert "\n" not in r.json()["error"]
    time.sleep(0.3)
    assert wire.not_reads(before) == [], "a mistyped command reached the modules"


def test_a_live_jog_with_a_boolean_speed_is_refused(client, wire):
    armed(client)
    before = time.perf_counter()
    with client.websocket_connect(LIVE) as ws:
        ws.receive_json()
        for k, text in enumerate(['{"op": "jog", "joint": "j1", "speed_scale": true, "id": 0}',
                                  '{"op": "jog", "joint": "j1", "speed_scale": "1", "id": 1}',
                                  '{"op": "jog", "joint": "j1", "speed_scale": 0.5, "id": 2, '
                                  '"speed_scale": 1}',
                                  '{"op": "jog", "joint": "j1", "speed_scale": 0.5, "id": 3, '
                                  '"x": 1}']):
            ws.send_text(text)
            reply = reply_to(ws, k)
            assert reply["ok"] is False and reply["error"], (text, reply)
    time.sleep(0.3)
    assert wire.not_reads(before) == []


# Every command's body, valid (each would move the arm, start a run or change something),
# with the type of each value: hypothesis replaces one value by a value of another type,
# adds an unknown key or repeats a key, and the command must be refused with nothing sent.
COMMANDS = {
    "/api/v1/move/joints": {"joints": {"j1": 5.0, "j2": -80}},
    "/api/v1/move/pose": {"name": "totem", "velocity_scale": 0.5},
    "/api/v1/velocities": {"joints": {"j1": 10.0}},
    "/api/v1/jog": {"joint": "j1", "speed_scale": 0.5},
    "/api/v1/run": {"sequence": "confirm_nudge.yaml", "speed": 1.0, "step_mode": False,
                    "first_step": 1},
    "/api/v1/answer": {"question_id": "q1", "yes": True},
    "/api/v1/poses": {"name": "spot", "overwrite": False},
    "live jog": {"op": "jog", "joint": "j1", "speed_scale": 0.5, "id": 1},
    "live jog_stop": {"op": "jog_stop", "id": 1},
}


#: Values that may be null (the default).
NULLABLE = {("velocity_scale",)}


def _other_type(value, nullable=False):
    """Values of any type but ``value``'s (an int is a fine float, so neither replaces the
    other; None only where it is not a value)."""
    numbers = st.one_of(st.integers(-1000, 1000),
                        st.floats(-1000, 1000, allow_nan=False, allow_infinity=False))
    texts = st.one_of(st.just("12"), st.just(" 14 "), st.just("true"), st.text(max_size=8))
    options = [st.lists(st.integers(), max_size=2),
               st.dictionaries(st.text(max_size=3), st.integers(), max_size=2)]
    if not nullable:
        options.append(st.none())
    if isinstance(value, bool):
        options += [numbers, texts]
    elif isinstance(value, (int, float)):
        options += [st.booleans(), texts]
    elif isinstance(value, str):
        options += [st.booleans(), numbers]
    return st.one_of(options)


def _leaves(body, path=()):
    for key, value in body.items():
        if isinstance(value, dict):
            yield from _leaves(value, path + (key,))
        else:
            yield path + (key,)


@st.composite
def mistyped(draw):
    name = draw(st.sampled_from(sorted(COMMANDS)))
    body = json.loads(json.dumps(COMMANDS[name]))
    how = draw(st.sampled_from(["type", "type", "extra key", "repeated key"]))
    leaves = [p for p in _leaves(body) if p not in (("op",), ("id",))]
    if how == "type" and leaves:
        where = draw(st.sampled_from(leaves))
        parent = body
        for key in where[:-1]:
            parent = parent[key]
        parent[where[-1]] = draw(_other_type(parent[where[-1]], where in NULLABLE))
        text = json.dumps(body)
    elif how == "extra key":
        body[draw(st.sampled_from(["force", "j1", "unsafe", "Joints"]))] = \
            draw(st.one_of(st.booleans(), st.integers(), st.text(max_size=4)))
        text = json.dumps(body)
    else:  # the first key again, with another value after it (the last would win)
        key = "op" if name.startswith("live") else next(iter(body))
        text = json.dumps(body)[:-1] + f", {json.dumps(key)}: {json.dumps(body[key])}}}"
    return name, text


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=mistyped())
def test_no_mistyped_command_moves_anything(client, wire, armed_once, case):
    name, text = case
    before = time.perf_counter()
    if name.startswith("live"):
        with client.websocket_connect(LIVE) as ws:
            ws.receive_json()
            ws.send_text(text)
            reply = reply_to(ws, json.loads(text, object_pairs_hook=dict).get("id"))
        assert reply["ok"] is False, (text, reply)
    else:
        r = client.post(name, content=text.encode(), headers=JSON)
        assert r.status_code == 422, (name, text, r.status_code, r.text)
    assert wire.not_reads(before) == [], (name, text)


@pytest.fixture
def armed_once(client):
    armed(client)


# ------------------------------------------------------------------ 3. GETs and crashes
def test_a_nul_in_a_run_file_path_is_refused_without_halting_a_moving_arm(client, setup, wire):
    from consolekit import wait_for

    armed(client)
    assert client.post("/api/v1/move/joints", json={"joints": {"j1": 40}}).status_code == 200
    wait_for(lambda: (setup.session.status().joints[0].position_deg or 0) > 1.0)
    before = time.perf_counter()
    for path in ("/api/v1/runs/x/%00", "/api/v1/runs/%00/report.json"):
        r = client.get(path)
        assert r.status_code in (404, 409), (path, r.status_code, r.text)
        assert set(r.json()) == {"error"}, r.text
    assert setup.session.status().activity == "moving"
    assert not wire.saw_halt(before, timeout=0.5)


class _Crashing:
    def set_move_velocities(self, velocities_deg_s):
        raise RuntimeError("a bug in a handler \x1b[31mred\x1b[0m")


def test_a_crashed_handler_is_a_500_for_that_request_only(tmp_path, caplog):
    from seqrun.service.session import ArmSession

    session_class = type("CrashingSession", (_Crashing, ArmSession), {})
    setup = console_setup(tmp_path, session_class=session_class)
    listener = BusListener(setup.connection)
    try:
        with TestClient(setup.app(), base_url=LOCAL, raise_server_exceptions=False) as client:
            take_control(client)
            armed(client)
            before = time.perf_counter()
            with caplog.at_level("ERROR"):
                r = client.post("/api/v1/velocities", json={"joints": {"j1": 10}})
            assert r.status_code == 500, r.text
            message = r.json()["error"]
            assert "internal error" in message and "a bug in a handler" in message
            assert "halted" not in message and "\n" not in message
            assert not listener.saw_halt(before, timeout=0.5)
            assert client.get("/api/v1/status").json()["activity"] == "idle"
            logged = "\n".join(r.getMessage() for r in caplog.records)
            assert "a bug in a handler" in logged
            assert "\x1b" not in logged, logged  # escape codes never reach the terminal raw
    finally:
        listener.close()
        setup.close()


def test_a_logged_path_and_message_are_escaped(setup, caplog):
    from seqrun.console.app import create_app
    from seqrun.console.catalog import Catalog

    class CrashingCatalog(Catalog):
        def run_file(self, run_id, name):
            raise RuntimeError(f"cannot serve {name}")

    app = create_app(setup.session, CrashingCatalog(setup.project, setup.runs), setup.arm)
    with TestClient(app, base_url=LOCAL, raise_server_exceptions=False) as client:
        with caplog.at_level("INFO"):
            for path in ("/api/v1/runs/%1B%5B31m/x", "/api/v1/runs/%1B%5D0;pwned%07/%1B%5B2J"):
                assert client.get(path).status_code == 500
    logged = [r.getMessage() for r in caplog.records]
    assert any("pwned" in m for m in logged), logged
    assert all("\x1b" not in m and "\x07" not in m for m in logged), logged


def test_the_dry_run_check_is_no_get(client):
    """An <img> of any web page can send a GET (without an Origin): a GET must cost little
    and change nothing, so the check (seconds of dry run) is a POST."""
    r = client.get("/api/v1/sequences/opsafe.yaml/check")
    assert r.status_code == 405, r.text[:200]
    assert set(r.json()) == {"error"}, r.text
    foreign = client.post("/api/v1/sequences/opsafe.yaml/check",
                          headers={"Origin": "http://evil.example"})
    assert foreign.status_code == 403
    r = client.post("/api/v1/sequences/opsafe.yaml/check")
    assert r.status_code == 200 and r.json()["dry_run"]["passed"] is True, r.text[:300]


def test_checks_are_rate_limited(client):
    codes = [client.post("/api/v1/sequences/too_far.yaml/check") for _ in range(8)]
    limited = [r for r in codes if r.status_code == 429]
    assert limited, [r.status_code for r in codes]
    assert "Retry-After" in limited[0].headers and set(limited[0].json()) == {"error"}


def test_the_check_runs_in_a_worker_process_below_the_console(setup):
    import os

    from seqrun.console.checker import CHECK_NICE, CheckWorker

    worker = CheckWorker()
    try:
        result = json.loads(worker.check(setup.catalog(), "opsafe.yaml", None, started=False))
        assert result["dry_run"]["passed"] is True
        assert worker.pid is not None and worker.pid != os.getpid()
        assert os.getpriority(os.PRIO_PROCESS, worker.pid) == \
            min(19, os.getpriority(os.PRIO_PROCESS, 0) + CHECK_NICE)
        assert os.sched_getscheduler(worker.pid) == os.SCHED_OTHER
    finally:
        worker.close()


# ------------------------------------------------------------------ 4. clients and the loop
def test_live_connections_are_capped_with_a_clear_refusal(setup):
    from starlette.testclient import WebSocketDenialResponse

    with TestClient(setup.app(max_pages=2), base_url=LOCAL) as client:
        with client.websocket_connect(LIVE) as one, client.websocket_connect(LIVE) as two:
            assert one.receive_json()["type"] == two.receive_json()["type"] == "hello"
            with pytest.raises(WebSocketDenialResponse) as refused:
                with client.websocket_connect(LIVE):
                    pass
            assert refused.value.status_code == 503
            assert "too many live connections" in refused.value.json()["error"]
        with client.websocket_connect(LIVE) as again:  # room again once they closed
            assert again.receive_json()["type"] == "hello"


def test_a_request_body_is_capped(client, wire):
    from seqrun.console.bodies import MAX_BODY_BYTES

    big = b'{"joints": {"j1": 5}, "pad": "' + b"x" * (2 * MAX_BODY_BYTES) + b'"}'
    r = client.post("/api/v1/move/joints", content=big, headers=JSON)
    assert r.status_code == 413 and "over" in r.json()["error"], r.text[:200]

    def chunks():  # no Content-Length: the cap holds while reading
        yield b'{"joints": {"j1": 5}, "pad": "'
        for _ in range(40):
            yield b"x" * 8192
        yield b'"}'

    r = client.post("/api/v1/move/joints", content=chunks(), headers=JSON)
    assert r.status_code == 413, r.text[:200]
    assert wire.not_reads() == []


def _raw(port: int):
    import socket

    return socket.create_connection(("127.0.0.1", port), timeout=10)


def _closed_within(sock, seconds: float) -> bool:
    """The server closed ``sock`` within ``seconds`` (what it sent first is skipped)."""
    sock.settimeout(0.2)
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            if sock.recv(65536) == b"":
                return True
        except TimeoutError:
            continue
        except OSError:
            return True
    return False


def test_a_request_head_must_arrive_in_time(setup, monkeypatch):
    """Slowloris: a head sent a byte at a time held a connection for good."""
    from consolekit import LiveServer

    from seqrun.console.server import HeadDeadline

    monkeypatch.setattr(HeadDeadline, "head_timeout_s", 1.0)
    with LiveServer(setup.app()) as server:
        slow = _raw(server.port)
        slow.sendall(b"GET /api/v1/status HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # never ends
        assert _closed_within(slow, 3.0), "a request head was allowed to trickle for good"
        silent = _raw(server.port)  # connected, sends nothing
        assert _closed_within(silent, 3.0)
        # A whole request is answered; the next head on the kept-alive connection has its
        # own deadline.
        kept = _raw(server.port)
        kept.sendall(b"GET /api/v1/status HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        assert b"200 OK" in kept.recv(65536)
        kept.sendall(b"GET /api/v1/status HTTP/1.1\r\n")
        assert _closed_within(kept, 3.0)
        # A live connection is not a request head: it stays open.
        import websockets.sync.client

        with websockets.sync.client.connect(f"ws://127.0.0.1:{server.port}/api/v1/live") as ws:
            time.sleep(1.5)
            ws.send('{"op": "ping", "id": 5}')
            assert any(json.loads(ws.recv(timeout=5)).get("id") == 5 for _ in range(400))
        for s in (slow, silent, kept):
            s.close()


def test_a_page_that_does_not_read_is_closed_and_holds_nothing_up(setup, monkeypatch):
    import base64
    import os
    import socket

    from consolekit import LiveServer, wait_for

    from seqrun.console import live
    from seqrun.events import make_event

    monkeypatch.setattr(live, "SEND_STALL_S", 1.0)
    app = setup.app()
    with LiveServer(app) as server:
        console = app.state.console
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect(("127.0.0.1", server.port))
        key = base64.b64encode(os.urandom(16)).decode()
        sock.sendall((f"GET /api/v1/live HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\n"
                      "Upgrade: websocket\r\nConnection: Upgrade\r\n"
                      f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n")
                     .encode())
        assert b"101" in sock.recv(1024)
        wait_for(lambda: console.live_connections == 1)
        hub = setup.session.events
        slowest, k = 0.0, 0
        deadline = time.monotonic() + 30
        while console.live_connections and time.monotonic() < deadline:
            for _ in range(50):  # 500 kB of events the page never takes
                k += 1
                started = time.perf_counter()
                hub.publish(make_event("status_poll_failed", float(k), {"error": "x" * 10_000}))
                slowest = max(slowest, time.perf_counter() - started)
            time.sleep(0.01)
        assert console.live_connections == 0, f"still open after {10 * k} kB sent to it"
        assert slowest < 0.05, slowest  # publishing never waited for the page
        sock.close()
