"""Foxglove live: a client speaking foxglove.sdk.v1 sees the channels and the data, STOP
reaches the bus as a Halt for anybody, commands need control as in the console."""

from __future__ import annotations

import json
import math
import time

import pytest

pytest.importorskip("foxglove", reason="foxglove-sdk is the test extra's")

from consolekit import console_setup, wait_for  # noqa: E402
from foxglove_client import FoxgloveClient, joint_states  # noqa: E402

from seqrun.foxglove.live import FoxgloveLive  # noqa: E402


@pytest.fixture
def setup(tmp_path):
    s = console_setup(tmp_path)
    yield s
    s.close()


@pytest.fixture
def live(setup):
    server = FoxgloveLive(setup.session, setup.arm, port=0)
    yield server
    server.close()


@pytest.fixture
def client(live):
    c = FoxgloveClient(live.port)
    yield c
    c.close()


def test_the_channels_and_services_are_advertised_on_loopback(live, client):
    assert live.port != 0 and live.url == f"ws://127.0.0.1:{live.port}"
    schemas = {topic: c["schemaName"] for topic, c in client.channels.items()}
    assert schemas == {"/lwa3/joint_states": "foxglove.JointStates",
                       "/lwa3/joint_commands": "foxglove.JointStates",
                       "/tf": "foxglove.FrameTransforms",
                       "/seqrun/scene": "foxglove.SceneUpdate",
                       "/seqrun/log": "foxglove.Log",
                       "/seqrun/events": client.channels["/seqrun/events"]["schemaName"]}
    assert client.channels["/seqrun/events"]["encoding"] == "json"
    assert set(client.services) == {"/seqrun/stop", "/seqrun/take_control",
                                    "/seqrun/release_control", "/seqrun/reset",
                                    "/seqrun/home", "/seqrun/move_to_pose"}
    assert "services" in client.info["capabilities"]


def test_a_move_is_seen_live_joint_states_tf_scene_and_events(setup, live, client):
    client.subscribe("/lwa3/joint_states", "/tf", "/seqrun/scene", "/seqrun/events",
                     "/seqrun/log", "/lwa3/joint_commands")
    scene = client.messages("/seqrun/scene")[0]   # at once on subscribing: guards, obstacles
    assert b"guards/desk" in scene and b"obstacles/desk" in scene and b"lwa3/base" in scene
    for command in (setup.session.arm_up, setup.session.home):
        assert command().ok
    setup.session.move_to_joints({"j1": 4.0}).wait(timeout=30)
    def arrived() -> bool:
        states = [joint_states(p) for p in client.messages("/lwa3/joint_states", 20)]
        return abs(states[-1].get("j1", 0.0) - math.radians(4.0)) < math.radians(0.05)

    client.pump(arrived)   # the measured j1 reaches 4 degrees, in radians
    states = [joint_states(p) for p in client.messages("/lwa3/joint_states")]
    assert list(states[-1]) == setup.arm.joint_names
    j1 = [s["j1"] for s in states if "j1" in s]
    assert len(j1) > 20 and j1 == sorted(j1)   # every cycle of the move, one way
    def commanded() -> float:
        return max(joint_states(p).get("j1", 0.0)
                   for p in client.messages("/lwa3/joint_commands", 5))

    client.pump(lambda: commanded() > math.radians(3.9))   # the plan, cycle by cycle
    assert commanded() <= math.radians(4.0) + 1e-9
    tf = client.messages("/tf")[-1]
    for frame in ("lwa3/base", "lwa3/j1", "lwa3/j7", "lwa3/end_effector"):
        assert frame.encode() in tf
    client.pump(lambda: any(b"capsules/" in p for p in client.messages("/seqrun/scene")))
    kinds = [json.loads(p)["type"] for p in client.messages("/seqrun/events", 2)]
    assert "activity_started" in kinds
    assert any(b"activity_started" in p for p in client.messages("/seqrun/log"))


def test_stop_halts_for_any_client_and_is_confirmed(setup, client):
    before = time.perf_counter()
    kind, answer = client.call("/seqrun/stop", {"reason": "from Foxglove"})
    assert kind == "ok", answer
    assert setup.wire.halts(before), "no Halt broadcast on the wire"
    assert answer["halt_confirmed"] is True and answer["reason"] == "from Foxglove"
    assert "confirmed" in answer["message"]
    # a malformed request still halts first, then says what was wrong
    before = time.perf_counter()
    kind, answer = client.call("/seqrun/stop", raw=b"{not json")
    assert kind == "ok" and setup.wire.halts(before)
    assert answer["halt_confirmed"] is True and "refused" in answer["note"]


def test_stop_halts_a_move_in_progress(setup, client):
    for command in (setup.session.arm_up, setup.session.home):
        assert command().ok
    activity = setup.session.move_to_joints({"j1": 40.0})
    wait_for(lambda: setup.wire.motions() > 5, 10)
    before = time.perf_counter()
    kind, answer = client.call("/seqrun/stop")
    assert kind == "ok" and answer["halt_confirmed"] is True
    assert setup.wire.halts(before)
    result = activity.wait(timeout=10)
    assert result.exit_code != 0   # the move ended by the Halt, not at its target


def take(client, name=None, take_over=False) -> str:
    """``client`` subscribes (how the server sees it connected) and takes control: the
    secret its commands carry."""
    client.subscribe("/seqrun/events")
    kind, answer = client.call("/seqrun/take_control",
                               {"take_over": take_over} | ({"name": name} if name else {}))
    assert kind == "ok", answer
    return answer["token"]


def test_commands_need_control_and_nothing_is_sent_without_it(setup, client, live):
    sent = len(setup.wire.frames)
    for service, body in (("/seqrun/home", {}), ("/seqrun/reset", {}),
                          ("/seqrun/move_to_pose", {"name": "totem"})):
        kind, message = client.call(service, body)
        assert kind == "failure" and "token" in message, message
    assert len(setup.wire.frames) == sent
    token = take(client, "Foxglove at the floor")
    holder = setup.session.control.state().holder
    assert holder.kind == "foxglove" and holder.name.startswith("Foxglove at the floor (")
    kind, result = client.call("/seqrun/reset", {"token": token})
    assert kind == "ok" and result["status"] == "passed", result
    # another client may not take control silently; taking over, the first one's secret
    # is worth nothing and its commands are refused, naming the new holder
    other = FoxgloveClient(live.port)
    try:
        other.subscribe("/seqrun/events")
        kind, message = other.call("/seqrun/take_control", {"name": "second"})
        assert kind == "failure" and "take over" in message, message
        other_token = take(other, "second", take_over=True)
        kind, message = client.call("/seqrun/home", {"token": token})
        assert kind == "failure" and "second" in message and "holds control" in message
        assert other.call("/seqrun/release_control", {"token": other_token})[0] == "ok"
        assert setup.session.control.state().holder is None
    finally:
        other.close()


def test_no_token_no_motion_and_stop_needs_none(setup, client, live):
    """Issue 43: the --foxglove server had no token: any client commanded the arm."""
    for command in (setup.session.arm_up, setup.session.home):
        assert command().ok
    take(client)   # someone holds control; another client without its secret ...
    intruder = FoxgloveClient(live.port)
    try:
        sent = len(setup.wire.frames)
        for body in ({"name": "totem"}, {"name": "totem", "token": "guess"},
                     {"name": "totem", "token": setup.session.control.state().holder.id}):
            kind, message = intruder.call("/seqrun/move_to_pose", body)
            assert kind == "failure", message
        assert len(setup.wire.frames) == sent   # ... moves nothing
        before = time.perf_counter()
        kind, answer = intruder.call("/seqrun/stop", raw=b"")   # ... but may STOP
        assert kind == "ok" and answer["halt_confirmed"] is True
        assert setup.wire.halts(before)
    finally:
        intruder.close()


def test_a_page_of_another_site_cannot_connect(live):
    """Issue 43: a web page on another origin, open in the operator's browser, took control
    of the --foxglove server and started a move. The console's Origin and Host rules."""
    import socket

    from websockets.exceptions import InvalidStatus

    with pytest.raises(InvalidStatus) as refused:
        FoxgloveClient(live.port, origin="http://evil.example")
    assert refused.value.response.status_code == 403
    assert b"origin 'http://evil.example' refused" in refused.value.response.body
    with socket.create_connection(("127.0.0.1", live.port), timeout=5) as raw:
        raw.sendall(b"GET / HTTP/1.1\r\nHost: evil.example:80\r\nUpgrade: websocket\r\n"
                    b"Connection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
                    b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n")
        answer = raw.recv(4096)
    assert answer.startswith(b"HTTP/1.1 403") and b"host 'evil.example:80' refused" in answer
    FoxgloveClient(live.port, origin=f"http://127.0.0.1:{live.port}").close()   # its own


def test_bad_requests_are_one_line_and_move_nothing(setup, client):
    sent = len(setup.wire.frames)
    client.subscribe("/seqrun/events")
    for service, raw, words in (("/seqrun/take_control", b'{"name": 5}', "name"),
                                ("/seqrun/take_control", b'{"nme": "x"}', "nme"),
                                ("/seqrun/take_control", b"[1]", "JSON object"),
                                ("/seqrun/move_to_pose", b'{"name": "totem", "token": "x", '
                                 b'"velocity_scale": true}', "velocity_scale")):
        kind, message = client.call(service, raw=raw)
        assert kind == "failure" and words in message and "\n" not in message, message
    assert len(setup.wire.frames) == sent


def test_a_holder_that_leaves_frees_control(setup, live):
    client = FoxgloveClient(live.port)
    take(client)
    assert setup.session.control.state().holder is not None
    client.close()
    wait_for(lambda: setup.session.control.state().holder is None, 5)
    assert setup.session.control.state().clients == ()


def test_a_holder_that_disconnects_mid_move_ends_it_with_a_controlled_stop(setup, live):
    """Issue 43: the move went on after its client disconnected, and it stayed the holder."""
    for command in (setup.session.arm_up, setup.session.home):
        assert command().ok
    client = FoxgloveClient(live.port)
    token = take(client)
    kind, answer = client.call("/seqrun/move_to_pose", {"token": token, "name": "totem",
                                                        "velocity_scale": 0.2})
    assert kind == "ok", answer
    activity = setup.session.activity
    wait_for(lambda: setup.wire.motions() > 5, 10)
    client.close()
    result = activity.wait(timeout=30)
    assert result.status != "passed", result   # stopped short of Totem ...
    assert not setup.wire.halts()              # ... by a controlled stop, not a Halt
    wait_for(lambda: setup.session.control.state().holder is None, 5)


def test_arm_up_makes_a_powered_on_arm_movable(setup, client):
    """Issue 43: /seqrun/reset did not write the limits, so after power-on a Foxglove user
    could not make the arm movable, and the refusal blamed Home. Reset is the console's
    Arm: Reset and the arm file's limits; then Home; then the arm moves."""
    token = take(client)
    for service in ("/seqrun/reset", "/seqrun/home"):
        kind, answer = client.call(service, {"token": token})
        assert kind == "ok" and answer["status"] == "passed", (service, answer)
    kind, answer = client.call("/seqrun/move_to_pose", {"token": token, "name": "opsafe"})
    assert kind == "ok", answer
    assert setup.session.activity.wait(timeout=60).ok
    # a refusal says its own cause: after a STOP, Home is refused because the arm is
    # halted, not because it was never homed
    assert client.call("/seqrun/stop")[0] == "ok"
    kind, message = client.call("/seqrun/move_to_pose", {"token": token, "name": "totem"})
    assert kind == "failure" and "halted" in message and "Home" not in message, message


def test_nothing_is_translated_while_nobody_watches(setup, live, monkeypatch):
    calls = []
    monkeypatch.setattr(live.translator, "translate", lambda e: calls.append(e) or [])
    setup.session.publish("activity_started", kind="test")
    time.sleep(0.3)
    assert calls == []


def test_seqrun_run_serves_foxglove_while_it_runs(tmp_path):
    from typer.testing import CliRunner

    from projecttree import ROOT
    from seqrun.cli import app

    result = CliRunner().invoke(app, [
        "run", str(ROOT / "sequences" / "opsafe.yaml"), "--virtual-time", "--plain", "-y",
        "--no-report", "--log-dir", str(tmp_path / "run"), "--foxglove=0"])
    assert result.exit_code == 0, result.output
    assert "Foxglove live on ws://127.0.0.1:" in result.output
    assert (tmp_path / "run" / "run.mcap").is_file()


def test_foxglove_alone_takes_the_default_port_and_never_the_next_word():
    from seqrun.cli.argv import expand_bus_kwargs
    from seqrun.foxglove import DEFAULT_PORT

    assert expand_bus_kwargs(["run", "--foxglove", "s.yaml"]) == [
        "run", f"--foxglove={DEFAULT_PORT}", "s.yaml"]
    assert expand_bus_kwargs(["run", "--foxglove=0", "s.yaml"]) == [
        "run", "--foxglove=0", "s.yaml"]


@pytest.mark.parametrize("command", ["run", "console"])
def test_without_foxglove_sdk_the_option_is_one_line(command, monkeypatch, tmp_path):
    from typer.testing import CliRunner

    import seqrun.foxglove
    from projecttree import ROOT
    from seqrun.cli import app

    monkeypatch.setattr(seqrun.foxglove, "available", lambda: False)
    args = [command, "--foxglove=0"] + (
        [str(ROOT / "sequences" / "opsafe.yaml"), "--virtual-time", "-y", "--log-dir",
         str(tmp_path / "run")] if command == "run" else ["--port", "0"])
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2
    assert result.output.strip() == ("error: --foxglove needs foxglove-sdk, an optional part "
                                     "of seqrun: pip install 'seqrun[foxglove]'")
    assert not (tmp_path / "run").exists()   # nothing opened, nothing written
