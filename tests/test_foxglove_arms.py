"""Foxglove live for a campaign of several arms (issues 41 item 5 and 45 item 1): one server,
each arm's channels under its arm id as the campaign's run.mcap names them, in Foxglove's
schemas or run.mcap's ROS 2 types; STOP halts every arm; each arm's commands go through
that arm's control desk as one arm's do."""

from __future__ import annotations

import functools
import math
import time

import pytest

pytest.importorskip("foxglove", reason="foxglove-sdk is the test extra's")

from consolekit import READ_OR_HALT, console_setup, wait_for  # noqa: E402
from foxglove_client import FoxgloveClient, joint_states, protobuf_fields  # noqa: E402

from seqrun.arm.between_arms import base_transform  # noqa: E402
from seqrun.foxglove.live import SERVICES, FoxgloveLive, LiveArm  # noqa: E402

#: The example campaign's bases (examples/two-arms/seqrun.toml).
BASES = {"A": ((0, 0, 0), (0, 0, 0)), "B": ((0, 900, 0), (0, 0, 180))}


@pytest.fixture
def setups(tmp_path):
    made = {a: console_setup(tmp_path / a) for a in BASES}
    yield made
    for setup in made.values():
        setup.close()


def commands(wire) -> int:
    """Frames that change a module (not a read, not a Halt) sent so far."""
    return sum(1 for _, _, data, _ in list(wire.frames) if data[:1] and
               data[0] not in READ_OR_HALT)


def serve(setups, types: str = "foxglove") -> FoxgloveLive:
    return FoxgloveLive(arms={a: LiveArm(s.session, s.arm, base_transform(*BASES[a]))
                              for a, s in setups.items()}, port=0, types=types)


@pytest.fixture
def live(setups):
    server = serve(setups)
    yield server
    server.close()


@pytest.fixture
def client(live):
    c = FoxgloveClient(live.port)
    yield c
    c.close()


def test_each_arms_channels_and_services_are_under_its_id(client):
    schemas = {topic: c["schemaName"] for topic, c in client.channels.items()}
    own = {"joint_states": "foxglove.JointStates", "joint_commands": "foxglove.JointStates",
           "scene": "foxglove.SceneUpdate", "log": "foxglove.Log"}
    expected = {f"/{a}/{name}": schema for a in "AB" for name, schema in own.items()}
    expected.update({"/tf": "foxglove.FrameTransforms",
                     "/tf_static": "foxglove.FrameTransforms"})
    assert {t: s for t, s in schemas.items() if not t.endswith("/events")} == expected
    assert {t for t in schemas if t.endswith("/events")} == {"/A/events", "/B/events"}
    assert set(client.services) == {"/seqrun/stop"} | {
        f"/{a}{service}" for a in "AB" for service in SERVICES if service != "/seqrun/stop"}


def test_both_arms_are_seen_live_each_on_its_own_channel(setups, client):
    client.subscribe("/A/joint_states", "/B/joint_states", "/tf", "/tf_static", "/B/scene")
    # each arm's base in the facility frame at once on subscribing
    transforms = [dict(protobuf_fields(value)) for field, value in
                  protobuf_fields(client.messages("/tf_static")[0]) if field == 1]
    frames = {t[3].decode(): (t[2].decode(), dict(protobuf_fields(t[4])))
              for t in transforms}
    assert set(frames) == {"A/base", "B/base"} and frames["B/base"][0] == "facility"
    assert frames["B/base"][1].get(2) == pytest.approx(0.9)   # y, in metres
    scene = client.messages("/B/scene")[0]
    assert b"B/base" in scene   # B's guards and obstacles in B's base frame
    for setup in setups.values():
        for command in (setup.session.arm_up, setup.session.home):
            assert command().ok
    setups["A"].session.move_to_joints({"j1": 4.0}).wait(timeout=30)
    setups["B"].session.move_to_joints({"j1": -3.0}).wait(timeout=30)

    def last(topic: str) -> float:
        return joint_states(client.messages(topic)[-1]).get("j1", 0.0)

    client.pump(lambda: abs(last("/A/joint_states") - math.radians(4.0)) < 1e-3
                and abs(last("/B/joint_states") - math.radians(-3.0)) < 1e-3)
    tf = b"".join(client.messages("/tf"))
    assert b"A/j1" in tf and b"B/j1" in tf   # one /tf, every arm's links


def test_stop_halts_every_arm(setups, client):
    before = time.perf_counter()
    kind, answer = client.call("/seqrun/stop", {"reason": "test"})
    assert kind == "ok", answer
    assert set(answer["arms"]) == {"A", "B"}
    for arm, setup in setups.items():
        assert answer["arms"][arm]["halt_confirmed"] is True, answer
        assert setup.wire.halts(before)


def test_an_arms_commands_need_that_arms_control(setups, client):
    sent = {a: commands(s.wire) for a, s in setups.items()}
    kind, message = client.call("/A/seqrun/home", {})
    assert kind == "failure" and "token" in message, message
    assert {a: commands(s.wire) for a, s in setups.items()} == sent
    client.subscribe("/A/events")
    kind, answer = client.call("/A/seqrun/take_control", {"name": "floor"})
    assert kind == "ok", answer
    assert setups["A"].session.control.state().holder is not None
    assert setups["B"].session.control.state().holder is None
    # A's secret is not B's: B's desk refuses it
    kind, message = client.call("/B/seqrun/home", {"token": answer["token"]})
    assert kind == "failure"
    assert commands(setups["B"].wire) == sent["B"]
    kind, done = client.call("/A/seqrun/reset", {"token": answer["token"]})
    assert kind == "ok" and done["status"] == "passed", done
    assert commands(setups["A"].wire) > sent["A"] and commands(setups["B"].wire) == sent["B"]
    client.close()   # it left: A's control is free again
    wait_for(lambda: setups["A"].session.control.state().holder is None, 5)


@pytest.mark.slow
def test_ros_types_are_the_campaign_run_mcaps_topics_and_types(setups, tmp_path,
                                                              monkeypatch):
    """The same topics and ROS 2 types as a recorded two-arm run.mcap: one layout serves
    the live run and the bag."""
    from mcap.reader import make_reader
    from typer.testing import CliRunner

    from seqrun.cli import app
    from twoarmskit import two_arm_campaign

    two_arm_campaign(tmp_path / "campaign", monkeypatch)
    result = CliRunner().invoke(app, ["run", "sequences/short.yaml", "--virtual-time", "--yes",
                                      "--no-report", "--log-dir", str(tmp_path / "run")])
    assert result.exit_code == 0, result.output
    with (tmp_path / "run" / "run.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    recorded = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    live = serve(setups, "ros")
    try:
        client = FoxgloveClient(live.port)
        try:
            served = {t: c["schemaName"] for t, c in client.channels.items()}
            assert served == recorded
            assert {c["encoding"] for c in client.channels.values()} == {"cdr"}
            client.subscribe("/B/joint_states", "/tf_static")
            store = _typestore()
            static = store.deserialize_cdr(client.messages("/tf_static")[0],
                                           "tf2_msgs/msg/TFMessage")
            assert [t.child_frame_id for t in static.transforms] == ["A/base", "B/base"]
            reading = store.deserialize_cdr(client.messages("/B/joint_states")[-1],
                                            "sensor_msgs/msg/JointState")
            assert list(reading.name)[:2] == ["j1", "j2"]
        finally:
            client.close()
    finally:
        live.close()


def test_one_arm_keeps_its_topic_names(setups):
    setup = setups["A"]
    live = FoxgloveLive(setup.session, setup.arm, port=0)
    try:
        client = FoxgloveClient(live.port)
        try:
            assert "/lwa3/joint_states" in client.channels
            assert "/seqrun/scene" in client.channels and "/tf_static" not in client.channels
            assert "/seqrun/home" in client.services
        finally:
            client.close()
    finally:
        live.close()


def test_a_server_is_for_one_arm_or_for_a_campaign(setups):
    setup = setups["A"]
    with pytest.raises(ValueError):
        FoxgloveLive(setup.session, setup.arm, port=0,
                     arms={"A": LiveArm(setup.session, setup.arm, None)})
    with pytest.raises(ValueError):
        FoxgloveLive(port=0, arms={})


#: Both arms start up, stand a while (a viewer connects), turn and turn back.
WATCHED = """\
name: Watched
steps:
  - parallel:
      - arm: A
        steps: [include: startup.yaml, wait: 3, {move: {joints: {j1: 6}}}, wait: 2]
      - arm: B
        steps: [include: startup.yaml, wait: 3, {move: {joints: {j1: -6}}}, wait: 2]
"""


@pytest.mark.slow
@pytest.mark.parametrize("types", ["foxglove", "ros"])
def test_seqrun_run_of_two_arms_serves_both(tmp_path, monkeypatch, types):
    """``seqrun run --foxglove`` of a campaign of two arms (examples/two-arms): one server,
    both arms' joint states under their ids, each arm's motion on its own channel."""
    import os
    import re
    import subprocess
    import sys

    from projecttree import ROOT
    from twoarmskit import two_arm_campaign

    campaign = two_arm_campaign(tmp_path / "c", monkeypatch)
    (campaign / "sequences" / "watched.yaml").write_text(WATCHED)
    proc = subprocess.Popen(
        [sys.executable, "-m", "seqrun", "run", "sequences/watched.yaml", "--yes", "--plain",
         "--no-report", "--log-dir", str(tmp_path / "run"), "--foxglove=0",
         "--foxglove-types", types], cwd=campaign,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:
            lines.append(line)
            found = re.search(r"Foxglove live on ws://127\.0\.0\.1:(\d+) .*arms A, B", line)
            if found:
                break
        else:
            raise AssertionError("no Foxglove line:\n" + "".join(lines))
        client = FoxgloveClient(int(found.group(1)))
        try:
            schema = ("sensor_msgs/msg/JointState" if types == "ros"
                      else "foxglove.JointStates")
            for arm in "AB":
                assert client.channels[f"/{arm}/joint_states"]["schemaName"] == schema
            assert "/lwa3/joint_states" not in client.channels
            client.subscribe("/A/joint_states", "/B/joint_states")
            client.messages("/A/joint_states")   # A's run has begun (its first reading)
            # read-only while the run goes on: a command through A's control is refused by
            # A's session, as for one arm's run
            kind, answer = client.call("/A/seqrun/take_control", {"name": "test"})
            assert kind == "ok", answer
            kind, message = client.call("/A/seqrun/home", {"token": answer["token"]})
            assert kind == "failure", message
            turned = {"A": 6.0, "B": -6.0}

            def j1(arm: str) -> list[float]:
                sub = client._subs[f"/{arm}/joint_states"]
                return [_j1(payload, types) for _, payload in client.data.get(sub, [])]

            client.pump(lambda: all(any(abs(v - math.radians(turned[a])) < 1e-3
                                        for v in j1(a)) for a in "AB"), timeout=60)
        finally:
            client.close()
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == 0, "".join(lines) + out
        assert "arm A: PASSED" in out and "arm B: PASSED" in out
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _j1(payload: bytes, types: str) -> float:
    if types == "foxglove":
        return joint_states(payload).get("j1", 0.0)
    reading = _typestore().deserialize_cdr(payload, "sensor_msgs/msg/JointState")
    return float(reading.position[0])


@functools.lru_cache(maxsize=1)
def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def test_closing_with_a_client_connected_prints_no_traceback(setups, caplog):
    """A run ends while a Foxglove client is still connected: the gate closes its
    connection quietly (asyncio printed "Exception in callback ... CancelledError")."""
    import logging

    live = serve(setups)
    client = FoxgloveClient(live.port)
    client.subscribe("/A/joint_states")
    with caplog.at_level(logging.ERROR, logger="asyncio"):
        live.close()
        time.sleep(0.2)
    assert not [r for r in caplog.records if r.name == "asyncio"], caplog.text
    with pytest.raises(Exception):   # the connection has ended
        client.pump(lambda: False, timeout=2)


@pytest.mark.slow
def test_seqrun_console_of_two_arms_serves_both(tmp_path, monkeypatch):
    """``seqrun console --foxglove`` in a campaign of two arms: the same server on the
    console's sessions (their polls live on each arm's channel); STOP halts both."""
    import os
    import re
    import signal
    import subprocess
    import sys

    from projecttree import ROOT
    from twoarmskit import two_arm_campaign

    campaign = two_arm_campaign(tmp_path / "c", monkeypatch)
    proc = subprocess.Popen(
        [sys.executable, "-m", "seqrun", "console", "--port", "0", "--sim",
         "--zero-confirmed", "park", "--foxglove=0"], cwd=campaign,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:
            lines.append(line)
            found = re.search(r"Foxglove live on ws://127\.0\.0\.1:(\d+) .*arms A, B", line)
            if found:
                break
        else:
            raise AssertionError("no Foxglove line:\n" + "".join(lines))
        client = FoxgloveClient(int(found.group(1)))
        try:
            client.subscribe("/A/joint_states", "/B/joint_states")
            for arm in "AB":
                assert "j1" in joint_states(client.messages(f"/{arm}/joint_states")[-1])
            kind, answer = client.call("/seqrun/stop")
            assert kind == "ok", answer
            assert {a: answer["arms"][a]["halt_confirmed"] for a in "AB"} == \
                {"A": True, "B": True}, answer
        finally:
            client.close()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            out, _ = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
    assert "Traceback" not in out, "".join(lines) + out
