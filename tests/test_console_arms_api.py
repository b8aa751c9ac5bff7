"""The console of two arms (issue 28, item 3's console part) through its API (FastAPI's
test client) on two arm sessions, each over a built-in simulator of its own, in real time:
each arm's API under /api/v1/arms/{id}, one STOP for every arm that confirms each, one
control desk for the whole console, the live connection carrying both arms."""

from __future__ import annotations

import json
import time

import pytest
from armsconsolekit import arms_setup
from consolekit import LIVE, LOCAL, refused, take_control, wait_for
from fastapi.testclient import TestClient

#: B's modules stop answering at once: its Halt cannot be confirmed (its status goes stale).
B_SILENT = {"B": ["all:drop_acks=1.0@0"]}


@pytest.fixture
def setup(tmp_path):
    s = arms_setup(tmp_path)
    yield s
    s.close()


@pytest.fixture
def client(setup):
    with TestClient(setup.app(token="sesame"), base_url=LOCAL,
                    raise_server_exceptions=False) as c:
        c.headers["Authorization"] = "Bearer sesame"
        yield c


def test_every_arm_has_its_own_api_and_the_arms_their_bases(client, setup):
    arms = client.get("/api/v1/arms").json()
    assert [a["id"] for a in arms] == ["A", "B"]
    assert all(a["simulator"] for a in arms)
    assert arms[0]["bus"] != arms[1]["bus"]  # a simulated bus each
    import numpy as np

    np.testing.assert_allclose(arms[1]["base"], setup.contexts["B"].base_transform())
    np.testing.assert_allclose(np.array(arms[1]["base"])[:3, 3], [0, 900, 0], atol=1e-9)
    for arm_id in ("A", "B"):
        status = client.get(f"/api/v1/arms/{arm_id}/status").json()
        assert len(status["joints"]) == 7 and status["simulator"] is True
        scene = client.get(f"/api/v1/arms/{arm_id}/arm").json()
        assert len(scene["joints"]) == 7
    # the sessions are the arms': each its own bus, driver and zero
    a, b = setup.sessions["A"], setup.sessions["B"]
    assert a.connection is not b.connection and a.driver is not b.driver
    openapi = client.get("/api/v1/openapi.json").json()["paths"]
    assert "/api/v1/arms/B/move/joints" in openapi and "/api/v1/halt" in openapi


def test_an_unknown_arm_or_a_route_without_an_arm_is_one_line(client):
    refused(client.get("/api/v1/arms/C/status"), 404, "unknown arm 'C'", "arms A, B")
    refused(client.post("/api/v1/arms/C/home"), 404, "unknown arm 'C'")
    refused(client.get("/api/v1/status"), 404, "arms A, B", "/api/v1/arms/ID/status")
    refused(client.post("/api/v1/move/joints", json={"joints": {"j1": 1}}), 404, "arms A, B")
    refused(client.get("/api/v1/arms/A/nothing"), 404, "Not Found")


def test_stop_halts_every_arm_and_confirms_each_without_a_token(setup):
    with TestClient(setup.app(token="sesame"), base_url=LOCAL,
                    raise_server_exceptions=False) as anyone:  # no token
        assert anyone.get("/api/v1/arms").status_code == 401
        before = time.perf_counter()
        r = anyone.post("/api/v1/halt", json={"reason": "floor not clear"})
    assert r.status_code == 200, r.text
    answer = r.json()
    assert answer["halt_confirmed"] is True and answer["not_confirmed"] == []
    assert set(answer["arms"]) == {"A", "B"}
    assert all(answer["arms"][a]["halt_confirmed"] for a in "AB")
    assert answer["reason"] == "floor not clear" and "every arm halted" in answer["message"]
    assert setup.wires["A"].halts(before) and setup.wires["B"].halts(before)
    for arm_id in "AB":
        assert setup.sessions[arm_id].status().activity == "halted"


def test_a_stop_with_a_bad_body_still_halts_every_arm(client, setup):
    before = time.perf_counter()
    r = client.post("/api/v1/halt", content=b'{"reason": 5', headers={
        "Content-Type": "application/json"})
    assert r.status_code == 200 and r.json()["halt_confirmed"] is True, r.text
    assert "every arm was halted" in r.json()["note"]
    assert setup.wires["A"].halts(before) and setup.wires["B"].halts(before)


def test_an_arm_that_does_not_confirm_keeps_no_other_from_being_halted(tmp_path):
    setup = arms_setup(tmp_path, faults=B_SILENT)
    try:
        with TestClient(setup.app(), base_url=LOCAL, raise_server_exceptions=False) as client:
            before = time.perf_counter()
            r = client.post("/api/v1/halt")
        answer = r.json()
        assert r.status_code == 200, r.text
        assert answer["halt_confirmed"] is False and answer["not_confirmed"] == ["B"]
        assert answer["arms"]["A"]["halt_confirmed"] is True
        assert answer["arms"]["B"]["halt_confirmed"] is False
        assert answer["arms"]["B"]["modules_not_halted"] == [1, 2, 3, 4, 5, 6, 7]
        assert "STOP FAILED for arm B" in answer["message"]
        # both Halts went out, A's at once (not after B's confirmation gave up)
        halt_a, halt_b = setup.wires["A"].halts(before), setup.wires["B"].halts(before)
        assert halt_a and halt_b
        assert halt_a[0] - before < 1.0
        assert setup.sessions["A"].status().activity == "halted"
        # lost contact with B: its status says so (the page greys that arm)
        wait_for(lambda: setup.sessions["B"].status().stale, 10)
        assert not setup.sessions["A"].status().stale
    finally:
        setup.close()


def test_the_live_connection_carries_both_arms_and_its_stop_halts_both(client, setup):
    with client.websocket_connect(LIVE) as ws:
        hello = ws.receive_json()
        assert hello["type"] == "hello" and set(hello["status"]["arms"]) == {"A", "B"}
        seen: set[str] = set()
        deadline = time.monotonic() + 10
        while seen != {"A", "B"} and time.monotonic() < deadline:
            message = ws.receive_json()
            if message["type"] == "status":
                assert len(message["status"]["joints"]) == 7
                seen.add(message["arm"])
        assert seen == {"A", "B"}
        before = time.perf_counter()
        ws.send_json({"op": "halt", "id": 3})
        reply = next(m for m in iter(ws.receive_json, None) if m["type"] == "reply")
        assert reply["id"] == 3 and reply["ok"] is True
        assert reply["result"]["halt_confirmed"] is True
        assert set(reply["result"]["arms"]) == {"A", "B"}
        assert setup.wires["A"].halts(before) and setup.wires["B"].halts(before)
        # the events name their arm
        event = next(m for m in iter(ws.receive_json, None)
                     if m["type"] == "event" and m["event"]["type"] == "session_halt")
        assert event["arm"] in ("A", "B")


def test_a_live_stop_with_one_arm_silent_lists_each(tmp_path):
    setup = arms_setup(tmp_path, faults=B_SILENT)
    try:
        with TestClient(setup.app(), base_url=LOCAL, raise_server_exceptions=False) as client, \
                client.websocket_connect(LIVE) as ws:
            ws.receive_json()
            ws.send_text('{"op": "halt", "id": 9, "extra": 1}')  # halts whatever is wrong
            reply = next(m for m in iter(ws.receive_json, None) if m["type"] == "reply")
        assert reply["ok"] is True and "note" in reply
        result = reply["result"]
        assert result["arms"]["A"]["halt_confirmed"] is True
        assert result["arms"]["B"]["halt_confirmed"] is False
        assert result["not_confirmed"] == ["B"]
    finally:
        setup.close()


def test_a_live_jog_names_its_arm(client, setup):
    with client.websocket_connect(LIVE) as ws:
        page = ws.receive_json()["client"]
        take_control(client, ws=ws)
        for text, words in (
                ('{"op": "jog", "joint": "j1", "speed_scale": 0.5, "id": 1}', "which arm?"),
                ('{"op": "jog", "arm": "C", "joint": "j1", "speed_scale": 0.5, "id": 2}',
                 "unknown arm 'C'"),
                ('{"op": "jog", "arm": 1, "joint": "j1", "speed_scale": 0.5, "id": 3}',
                 "arm")):
            ws.send_text(text)
            reply = next(m for m in iter(ws.receive_json, None) if m["type"] == "reply")
            assert reply["ok"] is False and words in reply["error"], (text, reply)
        ws.send_json({"op": "jog_stop", "id": 4})  # no arm: every arm's jog ends
        reply = next(m for m in iter(ws.receive_json, None) if m["type"] == "reply")
        assert reply["ok"] is True
    assert setup.wires["A"].motions() == 0 and setup.wires["B"].motions() == 0


def test_one_operator_holds_control_of_every_arm(client, setup):
    take_control(client, "coordinator")
    other = TestClient(client.app, base_url=LOCAL, raise_server_exceptions=False)
    other.headers["Authorization"] = "Bearer sesame"
    refused(other.post("/api/v1/control/take", json={"name": "second"}), 409, "coordinator",
            "take over")  # never silently
    r = other.post("/api/v1/control/take", json={"name": "second", "take_over": True})
    assert r.status_code == 200
    second = r.json()["client"]
    assert r.json()["holder"]["id"] == second
    # the first lost control on both arms at once
    for arm_id in ("A", "B"):
        refused(client.post(f"/api/v1/arms/{arm_id}/reset"), 409, "second")
    assert client.get("/api/v1/control").json()["holder"]["id"] == second
    assert setup.sessions["A"].control is setup.sessions["B"].control


@pytest.mark.slow  # homes both arms and moves one in real time
def test_commands_act_on_the_arm_they_address_only(client, setup):
    take_control(client)
    for path in ("arm-up", "home"):
        r = client.post(f"/api/v1/arms/B/{path}")
        assert r.status_code == 200, r.text
    a_frames = len(setup.wires["A"].frames)
    before = time.perf_counter()
    r = client.post("/api/v1/arms/B/move/joints", json={"joints": {"j1": 4}})
    assert r.status_code == 200, r.text
    wait_for(lambda: client.get("/api/v1/arms/B/status").json()["activity"] in ("idle", None)
             and abs(client.get("/api/v1/arms/B/status").json()["joints"][0]["position_deg"]
                     - 4) < 0.3, 20)
    assert setup.wires["B"].motions(before) > 0 and setup.wires["A"].motions(before) == 0
    # A was only read (status polls), never commanded
    assert all(data[:1] in (b"\x0a",) for _, _, data, _ in setup.wires["A"].frames[a_frames:]
               if data), "arm A got a command"
    # strict bodies per arm
    refused(client.post("/api/v1/arms/A/move/joints", json={"joints": {"j1": True}}), 422)


BOTH_NUDGE = """\
name: Both nudge
description: both arms start up, a question, A nudges j1 then B does (after A's signal)
steps:
  - parallel:
      - arm: A
        steps: [include: startup.yaml]
      - arm: B
        steps: [include: startup.yaml]
  - confirm: Is the floor between the arms clear?
  - parallel:
      - arm: A
        steps:
          - move: {joints: {j1: 3}, label: A nudges j1}
          - signal: A_done
      - arm: B
        steps:
          - wait_for: {event: A_done, timeout_s: 60}
          - move: {joints: {j1: -3}, label: B nudges j1}
"""


@pytest.mark.slow  # both arms start up and move in real time
def test_a_two_arm_sequence_runs_from_the_console(client, setup):
    (setup.folder / "sequences" / "both_nudge.yaml").write_text(BOTH_NUDGE)
    refused(client.post("/api/v1/run", json={"sequence": "both_nudge.yaml"}), 409,
            "control")  # commands need control
    take_control(client)
    refused(client.post("/api/v1/run", json={"sequence": "both_nudge.yaml", "speed": "1"}),
            422)
    with client.websocket_connect(LIVE) as ws:
        ws.receive_json()
        r = client.post("/api/v1/run", json={"sequence": "both_nudge.yaml"})
        assert r.status_code == 200, r.text
        assert r.json()["arms"] == ["A", "B"]
        # a second run while this one runs: refused
        refused(client.post("/api/v1/run", json={"sequence": "both_nudge.yaml"}), 409, "busy")
        seen: dict[str, set[str]] = {"A": set(), "B": set()}
        question = None
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            message = ws.receive_json()
            if message["type"] != "event":
                continue
            event = message["event"]
            seen[message["arm"]].add(event.get("label") or event["type"])
            if event["type"] == "confirm_requested" and question is None:
                question = (message["arm"], event["question_id"])
                r = client.post(f"/api/v1/arms/{question[0]}/answer",
                                json={"question_id": question[1], "yes": True})
                assert r.status_code == 200, r.text
            if client.get("/api/v1/run").json()["done"]:
                break
    state = client.get("/api/v1/run").json()
    assert state["done"] and state["exit_code"] == 0, state
    assert question is not None
    # the events of both arms were on the live connection, each naming its arm
    assert "A nudges j1" in seen["A"] and "B nudges j1" in seen["B"]
    from pathlib import Path

    folder = Path(state["run_dir"])
    assert all((folder / arm / "events.jsonl.gz").is_file() for arm in ("A", "B"))
    for arm_id, target in (("A", 3), ("B", -3)):
        j1 = client.get(f"/api/v1/arms/{arm_id}/status").json()["joints"][0]["position_deg"]
        assert j1 == pytest.approx(target, abs=0.3)


@pytest.mark.slow  # both arms start up and move in real time
def test_a_two_arm_run_from_the_console_leaves_the_records_of_seqrun_run(client, setup):
    """arms.json (one time base, each arm's start and base) and <run>/run.mcap (/A/...,
    /B/..., /tf_static facility -> each base): read back by the checks of seqrun run's."""
    from pathlib import Path

    from armsrecordkit import (check_b_moves_after_a_signalled, check_one_time_base,
                               check_run_mcap, check_traces_on_the_one_time_base)
    from twoarmskit import SHORT

    (setup.folder / "sequences" / "short.yaml").write_text(SHORT)
    take_control(client)
    r = client.post("/api/v1/run", json={"sequence": "short.yaml"})
    assert r.status_code == 200, r.text
    wait_for(lambda: client.get("/api/v1/run").json()["done"], 90)
    state = client.get("/api/v1/run").json()
    assert state["exit_code"] == 0 and state["warnings"] == [], state
    run = Path(state["run_dir"])
    summary = json.loads((run / "arms.json").read_text())
    assert summary["sequence"] == "Short" and summary["exit_code"] == 0
    assert summary["ros"]["mcap"] == "run.mcap"
    assert {a: s["status"] for a, s in summary["arms"].items()} == {"A": "passed",
                                                                     "B": "passed"}
    check_one_time_base(run)
    check_traces_on_the_one_time_base(run, check_b_moves_after_a_signalled(run))
    check_run_mcap(run)


def test_each_arm_lists_its_own_runs_and_those_of_both(client, setup):
    """A run of B alone is B's; a run of both is each arm's, by its part (its report);
    the console's own list has every run, a run of both with its parts. The sequences say
    which name the arms (POST /run) and which are of one arm (POST /arms/ID/run)."""
    from typer.testing import CliRunner

    from seqrun.cli import app

    (setup.folder / "sequences" / "both_nudge.yaml").write_text(BOTH_NUDGE)
    for args in (["sequences/both_nudge.yaml"], ["sequences/confirm_nudge.yaml", "--arm-id",
                                                  "B"]):
        result = CliRunner().invoke(app, ["run", str(setup.folder / args[0]), *args[1:],
                                          "--virtual-time", "--yes", "--plain"])
        assert result.exit_code == 0, result.output
    of_a = client.get("/api/v1/arms/A/runs").json()
    of_b = client.get("/api/v1/arms/B/runs").json()
    assert [r["sequence"] for r in of_a] == ["Both nudge"]
    assert [r["sequence"] for r in of_b] == ["Confirm then nudge", "Both nudge"]
    assert of_b[0]["arm"] == "B" and of_b[1]["arms"] == ["A", "B"]
    for arm_id, run in (("A", of_a[0]), ("B", of_b[1])):
        assert run["id"].endswith(f"/{arm_id}") and run["report"] is True
        report = client.get(f"/api/v1/arms/{arm_id}/runs/{run['id']}/report.json")
        assert report.status_code == 200, report.text
        assert report.json()["sequence"] == f"Both nudge (arm {arm_id})"
    every = client.get("/api/v1/runs").json()
    assert [r["sequence"] for r in every] == ["Confirm then nudge", "Both nudge"]
    assert every[1]["parts"] == {a: {"id": f"{every[1]['id']}/{a}", "report": True}
                                 for a in "AB"}
    kinds = {s["name"]: s["arms"] for s in client.get("/api/v1/sequences").json()}
    assert kinds["both_nudge.yaml"] is True and kinds["confirm_nudge.yaml"] is False
    assert [client.get(f"/api/v1/arms/{a}/arm").json()["arm_id"] for a in "AB"] == ["A", "B"]


#: Both arms only meet (no motion): a campaign run with nothing to wait for but each other.
MEET = """\
name: Meet
description: A signals, B waits for it; nothing moves
steps:
  - parallel:
      - arm: A
        steps: [signal: here]
      - arm: B
        steps: [wait_for: here]
"""


def test_a_two_arm_run_goes_where_the_consoles_runs_go(setup, tmp_path):
    """Issue 45: the console's run of several arms went to the campaign's runs/ whatever
    the console's --log-dir (its log root), so its own list of runs did not show it; a run
    of one arm went to the log root. Now both do, with arms.json and run.mcap there."""
    elsewhere = tmp_path / "elsewhere"
    for arm_id in setup.sessions.arm_ids:
        setup.sessions[arm_id].log_root = elsewhere   # as `seqrun console --log-dir` sets
    (setup.folder / "sequences" / "meet.yaml").write_text(MEET)
    run = setup.sessions.run_sequence(setup.folder / "sequences" / "meet.yaml",
                                      html_report=False)
    assert run.finished.wait(60)
    assert run.error is None and run.outcome.exit_code == 0, run.as_dict()
    assert run.folder.parent == elsewhere
    assert (run.folder / "arms.json").is_file() and (run.folder / "run.mcap").is_file()
    assert not (setup.folder / "runs").exists() or not any((setup.folder / "runs").iterdir())
