"""The console's HTTP and WebSocket API without a browser (FastAPI's test client), on a real
arm session over the simulated arm (real time): every command and every refusal.

A refusal is one line (``{"error": ...}``) and sends no motion command to the bus; a page
that goes away stops the motion it started (tests/test_console_hardening.py: attacks).
"""

from __future__ import annotations

import math
import time

import pytest
from consolekit import LIVE, LOCAL, console_setup, refused, take_control, wait_for
from fastapi.testclient import TestClient

from seqrun.errors import Refused


@pytest.fixture
def setup(tmp_path):
    s = console_setup(tmp_path)
    yield s
    s.close()


@pytest.fixture
def client(setup):
    with TestClient(setup.app(), base_url=LOCAL, raise_server_exceptions=False) as c:
        take_control(c)
        yield c


def armed(client) -> None:
    """Reset, home and limits (the thesis' Arm), so that motion is allowed."""
    for path in ("/api/v1/arm-up", "/api/v1/home"):
        r = client.post(path)
        assert r.status_code == 200, r.text


def joint(client, name: str) -> float:
    status = client.get("/api/v1/status").json()
    return next(j["position_deg"] for j in status["joints"] if j["name"] == name)


def idle(client, timeout: float = 20.0) -> dict:
    return wait_for(lambda: (s := client.get("/api/v1/status").json())["activity"]
                    not in ("moving", "jogging", "running", "paused") and s, timeout)


# ------------------------------------------------------------------------- reading
def test_status_arm_poses_sequences_and_openapi(client, setup):
    status = wait_for(lambda: (s := client.get("/api/v1/status").json())["updated_at"]
                      is not None and s)  # the session's first reading
    assert status["simulator"] is True
    assert [j["name"] for j in status["joints"]] == setup.arm.joint_names
    assert status["joints"][1]["position_deg"] == pytest.approx(-90.0, abs=0.05)  # Park
    scene = client.get("/api/v1/arm").json()
    assert len(scene["chain"]["links"]) == 6 and scene["guards"][0]["name"] == "desk"
    assert {"opsafe", "park", "totem"} <= {p["name"] for p in client.get("/api/v1/poses").json()}
    names = [s["name"] for s in client.get("/api/v1/sequences").json()]
    assert "opsafe.yaml" in names and "confirm_nudge.yaml" in names
    paths = client.get("/api/v1/openapi.json").json()["paths"]
    for path in ("/api/v1/halt", "/api/v1/reset", "/api/v1/home", "/api/v1/arm-up",
                 "/api/v1/move/pose", "/api/v1/move/joints", "/api/v1/velocities",
                 "/api/v1/jog", "/api/v1/jog/stop", "/api/v1/run", "/api/v1/run/pause",
                 "/api/v1/run/resume", "/api/v1/run/step", "/api/v1/run/abort",
                 "/api/v1/answer", "/api/v1/poses", "/api/v1/shutdown", "/api/v1/status"):
        assert path in paths, path


def test_the_page_and_the_vendored_three_js_are_served(client):
    page = client.get("/")
    assert page.status_code == 200 and 'id="stop"' in page.text
    three = client.get("/static/vendor/three/three.module.min.js")
    assert three.status_code == 200 and 'const t="170"' in three.text[:400]
    assert "MIT License" in client.get("/static/vendor/three/LICENSE").text


def test_the_scene_frames_are_the_validators_kinematics(client, setup):
    """The page multiplies the served frames by Rz(q): the same product as seqrun.arm.kinematics."""
    import numpy as np

    from seqrun.arm.kinematics import Chain, frame_transforms

    scene = client.get("/api/v1/arm").json()["chain"]
    q = np.radians([10, -20, 0, 35, -40, 50, 60])
    current = np.array(scene["base"])
    for k, link in enumerate([None] + scene["links"]):
        if link is not None:
            current = current @ np.array(link)
        c, s = math.cos(q[k]), math.sin(q[k])
        current = current @ np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    current = current @ np.array(scene["tool"])
    expected = frame_transforms(Chain.from_arm(setup.arm), q)[-1]
    assert np.allclose(current, expected, atol=1e-6)


# ------------------------------------------------------------------------- refusals
@pytest.mark.parametrize("body, status, words", [
    ({"joints": {"j9": 10}}, 409, ["j9"]),
    ({"joints": {"j1": 500}}, 409, ["j1"]),
    ({"joints": {}}, 422, ["joints"]),
    ({"joints": {"j1": "ten"}}, 422, ["joints.j1"]),
    ({"joints": {"j1": 5}, "speed": 2}, 422, ["speed"]),
])
def test_bad_move_targets_are_refused_and_nothing_moves(client, setup, body, status, words):
    armed(client)
    before = time.perf_counter()
    refused(client.post("/api/v1/move/joints", json=body), status, *words)
    assert setup.wire.motions(before) == 0
    assert client.get("/api/v1/status").json()["activity"] == "idle"


def test_nan_and_malformed_json_are_refused(client, setup):
    armed(client)
    before = time.perf_counter()
    headers = {"Content-Type": "application/json"}
    refused(client.post("/api/v1/move/joints", content='{"joints": {"j1": NaN}}',
                        headers=headers), 422, "finite")
    refused(client.post("/api/v1/move/joints", content='{"joints": {"j1": Infinity}}',
                        headers=headers), 422, "finite")
    refused(client.post("/api/v1/move/joints", content='{"joints": {', headers=headers), 422)
    refused(client.post("/api/v1/move/joints", content='{"joints": {"j1": 5}}'), 422,
            "JSON object")
    refused(client.post("/api/v1/jog", json={"joint": "j1", "speed_scale": 1.5}), 422,
            "speed_scale")
    assert setup.wire.motions(before) == 0


def test_unknown_pose_and_sequence_are_refused(client, setup):
    armed(client)
    before = time.perf_counter()
    refused(client.post("/api/v1/move/pose", json={"name": "nowhere"}), 409, "nowhere")
    refused(client.post("/api/v1/run", json={"sequence": "../arms/lwa3.yaml"}), 409,
            "unknown sequence")
    refused(client.post("/api/v1/run", json={"sequence": "missing.yaml"}), 409,
            "unknown sequence")
    refused(client.post("/api/v1/run", json={"sequence": "too_far.yaml"}), 409)
    refused(client.post("/api/v1/sequences/%2E%2E/%2E%2E/etc/passwd/check"), 409)
    assert setup.wire.motions(before) == 0


def test_a_move_while_halted_is_refused_until_reset(client, setup):
    armed(client)
    halt = client.post("/api/v1/halt").json()
    assert halt["halt_sent"] and halt["halt_confirmed"], halt
    before = time.perf_counter()
    refused(client.post("/api/v1/move/joints", json={"joints": {"j1": 2}}), 409)
    refused(client.post("/api/v1/jog", json={"joint": "j1", "speed_scale": 0.5}), 409)
    assert setup.wire.motions(before) == 0


def test_a_second_activity_while_one_runs_is_refused(client, setup):
    armed(client)
    first = client.post("/api/v1/move/joints", json={"joints": {"j1": 8}})
    assert first.status_code == 200, first.text
    refused(client.post("/api/v1/move/joints", json={"joints": {"j1": -8}}), 409)
    refused(client.post("/api/v1/run", json={"sequence": "opsafe.yaml"}), 409)
    idle(client)
    assert joint(client, "j1") == pytest.approx(8, abs=0.3)


# ------------------------------------------------------------------------- commands
def test_halt_sends_the_broadcast_and_confirms(client, setup):
    armed(client)
    before = time.perf_counter()
    body = client.post("/api/v1/halt", json={"reason": "test STOP"}).json()
    assert setup.wire.halts(before), "no Halt broadcast on the wire"
    assert body["halt_confirmed"] is True and "confirmed" in body["message"]
    again = client.post("/api/v1/halt").json()  # safe twice
    assert again["halt_confirmed"] is True
    assert client.get("/api/v1/status").json()["activity"] == "halted"
    assert client.post("/api/v1/reset").status_code == 200


@pytest.mark.slow  # real-time motion for several seconds
def test_move_to_joints_and_pose_with_velocities(client, setup):
    armed(client)
    r = client.post("/api/v1/velocities", json={"joints": {"j1": 20}})
    assert r.status_code == 200, r.text
    refused(client.post("/api/v1/velocities", json={"joints": {"j1": 1000}}), 409, "j1")
    r = client.post("/api/v1/move/joints", json={"joints": {"j1": 5}})
    assert r.status_code == 200 and r.json()["accepted"], r.text
    idle(client)
    assert joint(client, "j1") == pytest.approx(5, abs=0.3)
    r = client.post("/api/v1/move/pose", json={"name": "totem", "velocity_scale": 1.0})
    assert r.status_code == 200, r.text
    status = idle(client, 30)
    assert all(abs(j["position_deg"]) < 0.3 for j in status["joints"]), status


def test_jog_over_http_moves_then_stops(client, setup):
    armed(client)
    start = joint(client, "j1")
    for _ in range(8):  # renewed every 100 ms: the deadman is 200 ms
        assert client.post("/api/v1/jog", json={"joint": "j1", "speed_scale": 1}).status_code \
            == 200
        time.sleep(0.1)
    assert client.post("/api/v1/jog/stop").status_code == 200
    stopped = idle(client)
    moved = joint(client, "j1") - start
    assert moved > 1.0, moved
    time.sleep(0.3)
    assert joint(client, "j1") == pytest.approx(start + moved, abs=0.2)  # it stays stopped
    assert stopped["activity"] == "idle"
    assert not setup.wire.halts()  # a controlled stop, never a Halt (and a Reset)


def test_save_pose_writes_a_pose_file(client, setup):
    wait_for(lambda: client.get("/api/v1/status").json()["updated_at"] is not None)
    r = client.post("/api/v1/poses", json={"name": "bench_spot"})
    assert r.status_code == 200, r.text
    assert (setup.folder / "poses" / "bench_spot.yaml").is_file()
    refused(client.post("/api/v1/poses", json={"name": "bench_spot"}), 409)  # exists
    assert "bench_spot" in {p["name"] for p in client.get("/api/v1/poses").json()}


def test_sequence_check_shows_findings_and_the_dry_run(client):
    good = client.post("/api/v1/sequences/opsafe.yaml/check").json()
    assert good["valid"] is True and good["dry_run"]["passed"] is True
    assert len(good["steps"]) == len(good["dry_run"]["steps"])
    bad = client.post("/api/v1/sequences/too_far.yaml/check").json()
    assert bad["valid"] is False and bad["dry_run"] is None
    assert bad["errors"][0]["text"].startswith(bad["errors"][0]["file"] + ":4:")


@pytest.mark.slow  # real-time motion for several seconds
def test_a_sequence_with_a_confirm_runs_to_the_end_and_is_listed(client, setup):
    with client.websocket_connect(LIVE) as ws:
        hello = ws.receive_json()
        assert hello["type"] == "hello" and hello["status"]["simulator"] is True
        take_control(client, ws=ws)  # the page's secret on the page's commands
        r = client.post("/api/v1/run", json={"sequence": "confirm_nudge.yaml"})
        assert r.status_code == 200, r.text
        question = None
        while question is None:
            message = ws.receive_json()
            if message["type"] == "event" and message["event"]["type"] == "confirm_requested":
                question = message["event"]
        refused(client.post("/api/v1/answer", json={"question_id": "nope", "yes": True}), 409)
        r = client.post("/api/v1/answer", json={"question_id": question["question_id"],
                                                 "yes": True})
        assert r.status_code == 200, r.text
        finished = None
        while finished is None:
            message = ws.receive_json()
            if message["type"] == "event" and message["event"]["type"] == "run_finished":
                finished = message["event"]
        assert finished["status"] == "passed", finished
    assert joint(client, "j1") == pytest.approx(3, abs=0.3)
    # run_finished is published before the run folder is closed (report.json, run.mcap):
    # the listing says "running" until then.
    runs = wait_for(lambda: (r := client.get("/api/v1/runs").json())[0]["result"] != "running"
                    and r, 20)
    assert runs[0]["sequence"] == "Confirm then nudge" and runs[0]["result"] == "passed"
    report = client.get(f"/api/v1/runs/{runs[0]['id']}/report.json")
    assert report.status_code == 200 and report.json()["status"] == "passed"
    refused(client.get(f"/api/v1/runs/{runs[0]['id']}/%2E%2E"), 409)
    catalog = setup.catalog()
    for run_id, name in ((runs[0]["id"], "../../arms/lwa3.yaml"), ("..", "arms/lwa3.yaml"),
                         (".", "x"), (runs[0]["id"], "/etc/passwd")):
        with pytest.raises(Refused):
            catalog.run_file(run_id, name)


@pytest.mark.slow  # real-time motion for several seconds
def test_pause_resume_and_abort_a_run(client, setup):
    r = client.post("/api/v1/run", json={"sequence": "opsafe.yaml"})
    assert r.status_code == 200, r.text
    question = wait_for(lambda: [e for e in client.get("/api/v1/events").json()
                                 if e["type"] == "confirm_requested"])[0]
    client.post("/api/v1/answer", json={"question_id": question["question_id"], "yes": True})
    wait_for(lambda: client.get("/api/v1/status").json()["activity"] == "running"
             and any(e["type"] == "move_planned" for e in client.get("/api/v1/events").json()))
    assert client.post("/api/v1/run/pause").status_code == 200
    # (the move under way ends first: up to Totem at half speed, several seconds)
    wait_for(lambda: client.get("/api/v1/status").json()["activity"] == "paused", 60)
    assert client.post("/api/v1/run/resume").status_code == 200
    wait_for(lambda: client.get("/api/v1/status").json()["activity"] == "running")
    assert client.post("/api/v1/run/abort").status_code == 200
    idle(client)
    finished = [e for e in client.get("/api/v1/events").json() if e["type"] == "run_finished"]
    assert finished and finished[-1]["exit_code"] == 130, finished


# ------------------------------------------------------------------------- WebSocket
def test_websocket_pushes_status_and_takes_stop(client, setup):
    armed(client)
    with client.websocket_connect(LIVE) as ws:
        assert ws.receive_json()["type"] == "hello"
        status = next(m for m in iter(ws.receive_json, None) if m["type"] == "status")
        assert len(status["status"]["joints"]) == 7
        before = time.perf_counter()
        ws.send_json({"op": "halt", "id": 7})
        reply = next(m for m in iter(ws.receive_json, None) if m["type"] == "reply")
        assert reply == {"type": "reply", "id": 7, "ok": True, "result": reply["result"]}
        assert reply["result"]["halt_confirmed"] is True
        assert setup.wire.halts(before)


def test_websocket_refuses_malformed_messages(client, setup):
    armed(client)
    before = time.perf_counter()
    with client.websocket_connect(LIVE) as ws:
        ws.receive_json()  # hello
        take_control(client, ws=ws)
        for text, words in (("not json", "malformed"), ('["halt"]', "malformed"),
                            ('{"op": "fly", "id": 1}', "unknown op"),
                            ('{"op": "jog", "joint": "j1", "speed_scale": 9, "id": 2}',
                             "speed_scale"),
                            ('{"op": "jog", "joint": "j42", "speed_scale": 0.5, "id": 3}',
                             "j42")):
            ws.send_text(text)
            reply = next(m for m in iter(ws.receive_json, None) if m["type"] == "reply")
            assert reply["ok"] is False and all(w in reply["error"] for w in words.split()), \
                (text, reply)
    assert setup.wire.motions(before) == 0


def test_websocket_jog_hold_and_release(client, setup):
    armed(client)
    start = joint(client, "j2")
    with client.websocket_connect(LIVE) as ws:
        ws.receive_json()  # hello
        take_control(client, ws=ws)
        for k in range(8):
            ws.send_json({"op": "jog", "joint": "j2", "speed_scale": 0.8, "id": k})
            time.sleep(0.1)
        ws.send_json({"op": "jog_stop", "id": 99})
        replies = {}
        while 99 not in replies:
            m = ws.receive_json()
            if m["type"] == "reply":
                replies[m["id"]] = m
        assert all(r["ok"] for r in replies.values()), replies
    assert idle(client)["activity"] == "idle"
    assert joint(client, "j2") - start > 1.0
    assert not setup.wire.halts()


def test_a_page_that_goes_away_stops_its_move(client, setup):
    armed(client)
    with client.websocket_connect(LIVE) as ws:
        page = ws.receive_json()["client"]
        take_control(client, ws=ws)
        r = client.post("/api/v1/move/joints", json={"joints": {"j1": 60}})
        assert r.status_code == 200, r.text
        wait_for(lambda: abs(joint(client, "j1")) > 1.0)
    # the page is gone: a controlled stop, far short of the target
    status = idle(client)
    assert status["activity"] == "idle", status
    assert 1.0 < joint(client, "j1") < 50
    events = client.get("/api/v1/events").json()
    assert any(e["type"] == "controlled_stop" for e in events), [e["type"] for e in events]
    assert not setup.wire.halts()  # a controlled stop, not a Halt


def test_a_page_gone_silent_during_its_move_is_taken_as_gone(client, setup):
    """No TCP close (a tablet off the Wi-Fi): 2 s without a message during its move."""
    from seqrun.console.app import PAGE_SILENCE_S

    armed(client)
    with client.websocket_connect(LIVE) as ws:
        page = ws.receive_json()["client"]
        take_control(client, ws=ws)
        r = client.post("/api/v1/move/joints", json={"joints": {"j1": 120}})
        assert r.status_code == 200, r.text
        started = time.monotonic()
        status = wait_for(lambda: (s := client.get("/api/v1/status").json())["activity"]
                          == "idle" and s, timeout=PAGE_SILENCE_S + 5)
        assert time.monotonic() - started < PAGE_SILENCE_S + 3
    assert 1.0 < status["joints"][0]["position_deg"] < 100  # stopped, far from 120


def test_a_move_from_a_script_without_a_page_is_not_tied_to_a_connection(client, setup):
    armed(client)
    with client.websocket_connect(LIVE) as ws:
        ws.receive_json()
        r = client.post("/api/v1/move/joints", json={"joints": {"j1": 6}})  # no page id
        assert r.status_code == 200
    idle(client)
    assert joint(client, "j1") == pytest.approx(6, abs=0.3)


# ------------------------------------------------------------------------- crashes, access
def test_with_a_token_every_request_and_websocket_needs_it(setup):
    from starlette.testclient import WebSocketDenialResponse

    with TestClient(setup.app(token="s3cret", local_only=False)) as client:
        refused(client.get("/api/v1/status"), 401, "token")
        refused(client.post("/api/v1/control/take"), 401, "token")
        refused(client.post("/api/v1/run/abort"), 401, "token")
        opened = client.get("/")  # a person: where the token is, and a STOP without it
        assert opened.status_code == 401 and "token required" in opened.text
        assert 'id="stop"' in opened.text
        refused(client.get("/api/v1/status", headers={"Authorization": "Bearer wrong"}), 401)
        assert client.get("/api/v1/status",
                          headers={"Authorization": "Bearer s3cret"}).status_code == 200
        with pytest.raises(WebSocketDenialResponse) as denied:
            with client.websocket_connect("/api/v1/live") as ws:
                ws.receive_json()
        assert denied.value.status_code == 401
        page = client.get("/?token=s3cret")  # the printed URL: sets the cookie
        assert page.status_code == 200
        assert client.get("/api/v1/status").status_code == 200  # now by cookie
        with client.websocket_connect("/api/v1/live") as ws:
            assert ws.receive_json()["type"] == "hello"


def test_stop_needs_no_token(setup):
    with TestClient(setup.app(token="s3cret"), base_url=LOCAL) as client:
        before = time.perf_counter()
        r = client.post("/api/v1/halt")
        assert r.status_code == 200 and r.json()["halt_confirmed"] is True, r.text
        assert setup.wire.halts(before)
        refused(client.post("/api/v1/halt", headers={"Origin": "http://evil.example"}), 403)


def test_other_hosts_and_origins_are_refused(client):
    refused(client.get("/api/v1/status", headers={"Host": "evil.example:8765"}), 403, "host")
    refused(client.post("/api/v1/halt", headers={"Origin": "http://evil.example"}), 403,
            "origin")
    refused(client.post("/api/v1/halt", headers={"Origin": "null"}), 403, "origin")
    ok = client.get("/api/v1/status", headers={"Origin": LOCAL})
    assert ok.status_code == 200


def test_a_symlinked_sequence_is_listed_and_runnable_or_not_listed(client, setup, tmp_path):
    folder = setup.folder / "sequences"
    (folder / "inside.yaml").symlink_to(folder / "confirm_nudge.yaml")
    elsewhere = tmp_path / "elsewhere.yaml"
    elsewhere.write_text((folder / "confirm_nudge.yaml").read_text())
    (folder / "outside.yaml").symlink_to(elsewhere)
    listed = {s["name"] for s in client.get("/api/v1/sequences").json()}
    assert "inside.yaml" in listed and "outside.yaml" not in listed
    check = client.post("/api/v1/sequences/inside.yaml/check")
    assert check.status_code == 200 and check.json()["valid"] is True, check.text[:300]
    refused(client.post("/api/v1/run", json={"sequence": "outside.yaml"}), 409,
            "unknown sequence")


def test_poses_say_whether_a_move_may_go_there(client, setup):
    from seqrun.arm.poses import pose_document, pose_yaml

    # a pose 0.68° beyond j4's lower limit (Park's -120.32, arms/lwa3.yaml)
    beyond = {"j1": 0, "j2": -90, "j3": 0, "j4": -121, "j5": 0, "j6": 115.74, "j7": 0}
    (setup.folder / "poses" / "beyond.yaml").write_text(
        pose_yaml(pose_document("beyond", setup.arm, beyond, "beyond j4's travel", "manual")),
        encoding="utf-8")
    poses = {p["name"]: p for p in client.get("/api/v1/poses").json()}
    assert poses["totem"]["move_target"] is True and "why" not in poses["totem"]
    assert poses["park"]["move_target"] is True and "why" not in poses["park"]
    outside = poses["beyond"]
    assert outside["move_target"] is False
    assert outside["why"].startswith(outside["file"] + ": j4 -121° is outside its limits")
    armed(client)
    message = refused(client.post("/api/v1/move/pose", json={"name": "beyond"}), 409)
    assert "beyond.yaml:" in message and ": j4 -121°" in message
    assert "seqrun-session" not in message


def test_the_park_button_moves_the_arm_to_park(client):
    """Park's j4 (-120.32) is j4's lower limit: the console's Park gets there (issue 42)."""
    armed(client)
    r = client.post("/api/v1/move/joints", json={"joints": {"j4": -116}})
    assert r.status_code == 200, r.text
    idle(client)
    assert joint(client, "j4") == pytest.approx(-116, abs=0.3)
    r = client.post("/api/v1/move/pose", json={"name": "park", "velocity_scale": 1.0})
    assert r.status_code == 200 and r.json()["accepted"], r.text
    status = idle(client)
    assert status["activity"] == "idle", status
    park = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
    for j in status["joints"]:
        assert j["position_deg"] == pytest.approx(park[j["name"]], abs=0.2), j
