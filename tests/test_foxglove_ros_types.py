"""Foxglove live with ``--foxglove-types ros``: the channels of run.mcap (topics, ROS 2
schema names, ros2msg definitions, CDR), so one Foxglove layout serves live and recorded.

Checked from the outside: a client written from the Foxglove WebSocket spec
(tests/foxglove_client.py), the ``mcap`` reader for run.mcap, and rosbags' CDR
deserializer for the messages; none of them is seqrun's own code."""

from __future__ import annotations

import math
import threading

import pytest

pytest.importorskip("foxglove", reason="foxglove-sdk is the test extra's")

from consolekit import console_setup  # noqa: E402
from foxglove_client import FoxgloveClient  # noqa: E402

from seqrun.events import Measurement  # noqa: E402
from seqrun.foxglove.live import FoxgloveLive  # noqa: E402


@pytest.fixture
def setup(tmp_path):
    s = console_setup(tmp_path)
    yield s
    s.close()


@pytest.fixture
def live(setup):
    server = FoxgloveLive(setup.session, setup.arm, port=0, types="ros")
    yield server
    server.close()


@pytest.fixture
def client(live):
    c = FoxgloveClient(live.port)
    yield c
    c.close()


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)   # the campaign's default distribution


def _mcap_channels(path):
    """topic -> (schema name, schema encoding, message encoding, schema text) of run.mcap,
    and every message's bytes per topic."""
    from mcap.reader import make_reader

    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        channels = {c.topic: (summary.schemas[c.schema_id].name,
                              summary.schemas[c.schema_id].encoding, c.message_encoding,
                              summary.schemas[c.schema_id].data.decode())
                    for c in summary.channels.values()}
        messages: dict[str, list[bytes]] = {}
        for _, channel, message in reader.iter_messages():
            messages.setdefault(channel.topic, []).append(message.data)
    return channels, messages


def test_live_channels_are_the_recordings_and_joint_states_are_the_measurements(
        setup, live, client, tmp_path):
    from seqrun.sequence.loader import load_sequence

    measured: list[tuple[float, ...]] = []
    lock = threading.Lock()

    def keep(event) -> None:
        if isinstance(event, Measurement) and all(v is not None for v in event.joints_deg):
            with lock:
                measured.append(tuple(float(v) for v in event.joints_deg))

    listener = setup.session.events.add_listener(keep, "test measurements", maxsize=100_000)
    client.subscribe(*client.channels)
    loaded = load_sequence(setup.folder / "sequences" / "confirm_nudge.yaml")
    outcome = setup.session.run_loaded(loaded, log_dir=tmp_path / "run",
                                       confirm=lambda prompt: True, html_report=False)
    assert outcome.result.exit_code == 0, outcome.result.message
    store = _typestore()
    state = "sensor_msgs/msg/JointState"

    def nudged() -> bool:   # j1 measured at its target, 3 degrees
        last = store.deserialize_cdr(client.messages(live.names.joint_states)[-1], state)
        return abs(last.position[0] - math.radians(3.0)) < math.radians(0.05)

    client.pump(nudged)
    client.messages(live.names.planned)   # the move's plan arrived too
    listener.close(timeout=5.0)

    # the same topics, ROS 2 types, definitions and encodings as the run's run.mcap
    recorded, recorded_messages = _mcap_channels(tmp_path / "run" / "run.mcap")
    advertised = {topic: (c["schemaName"], c["schemaEncoding"], c["encoding"], c["schema"])
                  for topic, c in client.channels.items()}
    assert advertised == recorded
    assert recorded[live.names.joint_states][:3] == ("sensor_msgs/msg/JointState", "ros2msg",
                                                     "cdr")

    # every joint_states message is one of the session's readings, in radians
    received = [store.deserialize_cdr(p, state)
                for p in client.messages(live.names.joint_states)]
    readings = set(measured)
    assert len(received) > 20
    for message in received:
        assert list(message.name) == setup.arm.joint_names
        degrees = tuple(math.degrees(v) for v in message.position)
        assert any(all(abs(a - b) < 1e-9 for a, b in zip(degrees, reading))
                   for reading in readings), degrees
        assert len(message.velocity) in (0, len(message.name))
    # the readings of the move carry the measured velocity (as the recording's)
    assert sum(len(m.velocity) == len(m.name) for m in received) > 20
    j1 = [m.position[0] for m in received]
    assert max(j1) - min(j1) > math.radians(2.9)    # the whole nudge was seen live

    # the last reading at rest: live and recorded agree
    recorded_last = store.deserialize_cdr(recorded_messages[live.names.joint_states][-1], state)
    assert list(recorded_last.position) == pytest.approx(list(received[-1].position),
                                                         abs=math.radians(0.01))

    # the move's plan: the same points as the recording's
    trajectory = "trajectory_msgs/msg/JointTrajectory"
    live_plan = store.deserialize_cdr(client.messages(live.names.planned)[-1], trajectory)
    recorded_plan = store.deserialize_cdr(recorded_messages[live.names.planned][-1], trajectory)
    assert len(live_plan.points) == len(recorded_plan.points) > 10
    assert [list(p.positions) for p in live_plan.points] == \
        [list(p.positions) for p in recorded_plan.points]

    # the URDF: byte for byte the recording's
    assert client.messages("/robot_description")[0] == recorded_messages["/robot_description"][0]


def test_markers_tf_and_events_decode_as_ros_messages(setup, live, client):
    import json

    store = _typestore()
    client.subscribe("/seqrun/markers", "/tf", "/seqrun/events")
    markers = store.deserialize_cdr(client.messages("/seqrun/markers")[0],
                                    "visualization_msgs/msg/MarkerArray")
    # at once on subscribing: the guards and obstacles, cubes (Marker.CUBE = 1)
    assert {(m.ns, m.text, m.type) for m in markers.markers} >= {("guards", "desk", 1),
                                                                 ("obstacles", "desk", 1)}
    assert {m.header.frame_id for m in markers.markers} == {"lwa3/base"}
    assert setup.session.arm_up().ok
    tf = store.deserialize_cdr(client.messages("/tf")[-1], "tf2_msgs/msg/TFMessage")
    children = [t.child_frame_id for t in tf.transforms]
    assert "lwa3/j1" in children and "lwa3/end_effector" in children
    lines = [json.loads(store.deserialize_cdr(p, "std_msgs/msg/String").data)
             for p in client.messages("/seqrun/events")]
    assert "activity_started" in {line["type"] for line in lines}


def test_the_campaigns_distribution_gives_the_definitions(tmp_path):
    """A campaign whose run.mcap is written for Humble is served with Humble's message
    definitions (its Marker differs from Jazzy's), as its bag."""
    from rosbags.typesys import Stores, get_typestore

    (tmp_path / "seqrun.toml").write_text('[ros]\ndistribution = "humble"\n')
    setup = console_setup(tmp_path)
    server = FoxgloveLive(setup.session, setup.arm, port=0, types="ros")
    client = FoxgloveClient(server.port)
    try:
        humble = get_typestore(Stores.ROS2_HUMBLE)
        markers = "visualization_msgs/msg/MarkerArray"
        advertised = client.channels["/seqrun/markers"]["schema"]
        assert advertised == humble.generate_msgdef(markers, ros_version=2)[0]
        assert advertised != _typestore().generate_msgdef(markers, ros_version=2)[0]
        client.subscribe("/seqrun/markers")
        decoded = humble.deserialize_cdr(client.messages("/seqrun/markers")[0], markers)
        assert {m.ns for m in decoded.markers} >= {"guards", "obstacles"}
    finally:
        client.close()
        server.close()
        setup.close()


def test_services_and_stop_stay_as_they_are(setup, live, client):
    assert set(client.services) == {"/seqrun/stop", "/seqrun/take_control",
                                    "/seqrun/release_control", "/seqrun/reset",
                                    "/seqrun/home", "/seqrun/move_to_pose"}
    before = len(setup.wire.halts())
    kind, answer = client.call("/seqrun/stop", {})
    assert kind == "ok" and answer["halt_confirmed"] is True, answer
    assert len(setup.wire.halts()) > before
    kind, message = client.call("/seqrun/home", {"token": "guess"})
    assert kind == "failure" and setup.wire.motions() == 0


def test_the_default_is_foxglove_schemas_and_unknown_types_are_refused(setup):
    from seqrun.foxglove.live import DEFAULT_TYPES

    assert DEFAULT_TYPES == "foxglove"
    with pytest.raises(ValueError, match="unknown Foxglove channel types 'ros2'"):
        FoxgloveLive(setup.session, setup.arm, port=0, types="ros2")


def test_seqrun_run_serves_ros_types_and_the_option_needs_foxglove(tmp_path):
    from typer.testing import CliRunner

    from projecttree import ROOT
    from seqrun.cli import app

    sequence = str(ROOT / "sequences" / "opsafe.yaml")
    result = CliRunner().invoke(app, [
        "run", sequence, "--virtual-time", "--plain", "-y", "--no-report", "--log-dir",
        str(tmp_path / "run"), "--foxglove=0", "--foxglove-types", "ros"])
    assert result.exit_code == 0, result.output
    assert "run.mcap's ROS 2 types" in result.output
    alone = CliRunner().invoke(app, ["run", sequence, "--virtual-time", "-y", "--log-dir",
                                     str(tmp_path / "alone"), "--foxglove-types", "ros"])
    assert alone.exit_code == 2
    assert alone.output.strip().startswith("error: --foxglove-types ros: only with --foxglove")
    assert not (tmp_path / "alone").exists()
    console = CliRunner().invoke(app, ["console", "--port", "0", "--foxglove-types", "ros"])
    assert console.exit_code == 2 and "only with --foxglove" in console.output


@pytest.mark.slow
def test_seqrun_console_serves_ros_types(tmp_path):
    """The console's face starts the same server: ``--foxglove-types ros`` there too."""
    import os
    import re
    import subprocess
    import sys

    from projecttree import ROOT

    proc = subprocess.Popen([sys.executable, "-m", "seqrun", "console", "--sim", "--port", "0",
                             "--yes", "--log-dir", str(tmp_path / "runs"), "--foxglove=0",
                             "--foxglove-types", "ros"], cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)},
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:
            lines.append(line)
            found = re.search(r"Foxglove live on ws://127\.0\.0\.1:(\d+) \(run\.mcap's ROS 2",
                              line)
            if found:
                break
        else:
            raise AssertionError("no Foxglove line:\n" + "".join(lines))
        client = FoxgloveClient(int(found.group(1)))
        try:
            assert client.channels["/lwa3/joint_states"]["schemaName"] == \
                "sensor_msgs/msg/JointState"
            assert {c["encoding"] for c in client.channels.values()} == {"cdr"}
            client.subscribe("/lwa3/joint_states")
            reading = _typestore().deserialize_cdr(client.messages("/lwa3/joint_states")[-1],
                                                   "sensor_msgs/msg/JointState")
            assert list(reading.name) == ["j1", "j2", "j3", "j4", "j5", "j6", "j7"]
        finally:
            client.close()
    finally:
        proc.terminate()
        proc.wait(timeout=30)
