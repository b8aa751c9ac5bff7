"""run.mcap: every run folder holds the run as a ROS 2 bag, read back with rosbags and with
the MCAP reference reader, and checked against events.jsonl and the CAN trace."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from projecttree import ROOT
from runfolder import RunFolder
from seqrun.arm.description import load_arm
from seqrun.arm.kinematics import pose_from_user_deg
from seqrun.ros_messages import cdr
from seqrun.ros_messages.from_events import EventLine, Frames, Joints, Shapes
from seqrun.ros_messages.names import RosNames
from seqrun.ros_messages.ros_fields import messages
from seqrun.ros_messages.values import marker_shapes, quaternion_xyzw, transforms
from seqrun.service import mcap_log
from seqrun.service.mcap_log import MessageBuilder, typestore_of
from simrun import run_on_sim

ARM = load_arm(ROOT / "arms" / "lwa3.yaml")
NAMES = RosNames.of(ARM)


@pytest.fixture(scope="module")
def opsafe(tmp_path_factory) -> RunFolder:
    """One Op-safe run on the simulator (virtual time): moves, a checkpoint, the start-up."""
    tmp = tmp_path_factory.mktemp("mcap")
    run = run_on_sim("opsafe", tmp)
    assert run.outcome.result.exit_code == 0
    return RunFolder(tmp / "run")


def read_bag(path: Path) -> dict[str, list[tuple[int, object]]]:
    """Every message of run.mcap by topic: (log time ns, message), with rosbags."""
    out: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, stamp, raw in reader.messages():
            out.setdefault(conn.topic, []).append((stamp, reader.deserialize(raw, conn.msgtype)))
    return out


def ns(epoch_s: float) -> int:
    return int(round(epoch_s * 1e9))


def test_the_run_folder_holds_run_mcap_with_every_topic(opsafe):
    path = opsafe.path / "run.mcap"
    assert path.is_file() and not (opsafe.path / "run.mcap.partial").exists()
    with open(path, "rb") as f:   # the MCAP reference reader: summary, schemas, counts
        summary = make_reader(f).get_summary()
    assert summary is not None
    by_topic = {c.topic: c for c in summary.channels.values()}
    types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert types == {"/lwa3/joint_states": "sensor_msgs/msg/JointState",
                     "/lwa3/joint_commands": "sensor_msgs/msg/JointState",
                     "/tf": "tf2_msgs/msg/TFMessage",
                     "/lwa3/planned": "trajectory_msgs/msg/JointTrajectory",
                     "/seqrun/events": "std_msgs/msg/String",
                     "/seqrun/markers": "visualization_msgs/msg/MarkerArray",
                     "/robot_description": "std_msgs/msg/String"}
    assert all(c.message_encoding == "cdr" for c in by_topic.values())
    counts = {t: summary.statistics.channel_message_counts[c.id] for t, c in by_topic.items()}
    events = opsafe.events()
    setpoints = [e for e in events if e["type"] == "setpoint"]
    measurements = [e for e in events if e["type"] == "measurement"]
    assert counts["/lwa3/joint_commands"] == len(setpoints) > 500
    assert counts["/lwa3/joint_states"] == len(setpoints) + len(measurements)
    assert counts["/tf"] == counts["/lwa3/joint_states"]
    assert counts["/lwa3/planned"] == len([e for e in events if e["type"] == "move_planned"]) == 2
    assert counts["/seqrun/events"] == len(events) - len(setpoints) - len(measurements)
    assert counts["/robot_description"] == 1
    start = ns(opsafe.report()["start_epoch_s"])
    assert summary.statistics.message_start_time == start   # the zero reference, t = 0
    assert summary.statistics.message_end_time == ns(
        opsafe.report()["start_epoch_s"] + events[-1]["t"])
    # the reference reader decodes what rosbags wrote, message by message, in log order
    with open(path, "rb") as f:
        times = [m.log_time for _, _, m in make_reader(f).iter_messages(log_time_order=True)]
    assert len(times) == sum(counts.values()) and times == sorted(times)


def test_joint_states_are_the_measured_joints_at_the_modules_time_stamps(opsafe):
    bag = read_bag(opsafe.path / "run.mcap")
    epoch = opsafe.report()["start_epoch_s"]
    readings = [e for e in opsafe.events() if e["type"] in ("setpoint", "measurement")]
    states = bag["/lwa3/joint_states"]
    assert len(states) == len(readings)
    # the CAN trace's answers (the modules' acknowledges, ids 0xA0+): a reading's stamp is
    # when the modules answered, on the trace's own time base
    answered = np.array([m.timestamp for m in opsafe.trace_frames()
                         if 0xA0 <= m.arbitration_id < 0xC0])
    for (log_time, msg), event in zip(states, readings):
        assert list(msg.name) == ARM.joint_names
        joints = event.get("measured_deg", event.get("joints_deg"))
        np.testing.assert_allclose(msg.position, np.radians(joints), rtol=0, atol=1e-12)
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        assert log_time == ns(epoch + event["t"])
        if event["type"] == "setpoint":
            assert stamp == pytest.approx(epoch + event["read_t"], abs=1e-6)
            assert np.min(np.abs(answered - stamp)) < 0.5e-3
            assert stamp <= epoch + event["t"] + 1e-6
        else:
            assert stamp == pytest.approx(epoch + event["t"], abs=1e-6)


def test_joint_commands_and_the_planned_trajectories_are_what_was_streamed(opsafe):
    bag = read_bag(opsafe.path / "run.mcap")
    epoch = opsafe.report()["start_epoch_s"]
    setpoints = opsafe.events("setpoint")
    for (log_time, msg), event in zip(bag["/lwa3/joint_commands"], setpoints):
        assert log_time == ns(epoch + event["t"])
        np.testing.assert_allclose(msg.position, np.radians(event["planned_deg"]), atol=1e-12)
        np.testing.assert_allclose(msg.velocity, np.radians(event["planned_vel_deg_s"]),
                                   atol=1e-12)
    moves = opsafe.events("move_planned")
    plans = bag["/lwa3/planned"]
    streamed = 0
    for (log_time, plan), move in zip(plans, moves):
        assert log_time == ns(epoch + move["t"])
        assert plan.joint_names == ARM.joint_names and plan.header.frame_id == "lwa3/base"
        mine = [e for e in setpoints if e["step"] == move["step"]]
        assert len(plan.points) == len(mine) > 100
        for point, event in zip(plan.points, mine):
            t = point.time_from_start.sec + point.time_from_start.nanosec * 1e-9
            assert t == pytest.approx(event["plan_t"], abs=1e-9)
            np.testing.assert_allclose(point.positions, np.radians(event["planned_deg"]),
                                       atol=1e-12)
        np.testing.assert_allclose(plan.points[-1].positions, np.radians(move["target_deg"]),
                                   atol=1e-6)
        streamed += len(mine)
    assert streamed == len(setpoints)


def test_tf_holds_every_link_and_composes_to_seqruns_fk(opsafe):
    bag = read_bag(opsafe.path / "run.mcap")
    readings = [e for e in opsafe.events() if e["type"] in ("setpoint", "measurement")]
    frames = NAMES.frames
    for (_, tf), (_, state), event in list(zip(bag["/tf"], bag["/lwa3/joint_states"],
                                               readings))[::97]:
        assert [t.header.frame_id for t in tf.transforms] == frames[:-1]
        assert [t.child_frame_id for t in tf.transforms] == frames[1:]
        assert all(t.header.stamp == state.header.stamp for t in tf.transforms)
        total = np.eye(4)
        for t in tf.transforms:
            r, q = t.transform.translation, t.transform.rotation
            m = np.eye(4)
            m[:3, :3] = quaternion_matrix(q.x, q.y, q.z, q.w)
            m[:3, 3] = (r.x, r.y, r.z)
            total = total @ m
        pose = pose_from_user_deg(ARM, event.get("measured_deg", event.get("joints_deg")))
        np.testing.assert_allclose(total[:3, 3] * 1000.0, pose.position_mm, atol=1e-6)
        np.testing.assert_allclose(total[:3, :3], pose.rotation, atol=1e-9)


def test_events_one_string_each_and_markers_draw_guards_obstacles_capsules(opsafe):
    bag = read_bag(opsafe.path / "run.mcap")
    logged = [e for e in opsafe.events() if e["type"] not in ("setpoint", "measurement")]
    lines = [json.loads(msg.data) for _, msg in bag["/seqrun/events"]]
    assert lines == logged
    markers = bag["/seqrun/markers"]
    first = {(m.ns, m.text) for m in markers[0][1].markers}
    assert ("guards", "desk") in first and ("obstacles", "desk") in first
    with_capsules = [msg for _, msg in markers if any(m.ns == "capsules" for m in msg.markers)]
    assert len(with_capsules) > 50    # at most every 0.1 s of motion
    capsules = [m for m in with_capsules[-1].markers if m.ns == "capsules"]
    assert {m.text for m in capsules} == {c.name for c in ARM.geometry.capsules}
    guard = next(m for m in markers[0][1].markers if m.ns == "guards")
    assert guard.pose.position.z == pytest.approx(ARM.workspace.guards[0].min_z_mm / 1000)
    assert all(m.header.frame_id == "lwa3/base" for _, msg in markers for m in msg.markers)


def test_report_mcap_writes_it_anew_from_events_jsonl(opsafe, tmp_path):
    from typer.testing import CliRunner

    from seqrun.cli import app

    folder = tmp_path / "old-run"
    shutil.copytree(opsafe.path, folder)
    (folder / "run.mcap").unlink()
    report = json.loads((folder / "report.json").read_text())
    del report["ros"]   # a run of an older version: namespace from its arm file
    (folder / "report.json").write_text(json.dumps(report))
    result = CliRunner().invoke(app, ["report", str(folder), "--mcap"])
    assert result.exit_code == 0, result.output
    assert "run.mcap" in result.output and not (folder / "report.html").exists()
    rebuilt, live = read_bag(folder / "run.mcap"), read_bag(opsafe.path / "run.mcap")
    assert rebuilt.keys() == live.keys()
    for topic in live:
        assert [t for t, _ in rebuilt[topic]] == [t for t, _ in live[topic]], topic
        assert repr([m for _, m in rebuilt[topic]]) == repr([m for _, m in live[topic]]), topic


def test_report_mcap_on_a_folder_without_events_is_one_line(tmp_path):
    from typer.testing import CliRunner

    from seqrun.cli import app

    result = CliRunner().invoke(app, ["report", str(tmp_path), "--mcap"])
    assert result.exit_code == 2
    assert result.output.strip().count("\n") == 0 and "no events.jsonl" in result.output


def test_a_failing_mcap_writer_never_disturbs_the_run(tmp_path, monkeypatch):
    def full_disk(self, topic, log_ns, data):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(mcap_log.BagWriter, "_put", full_disk)
    warned: list[str] = []
    run = run_on_sim("opsafe", tmp_path, warn=warned.append)
    assert run.outcome.result.exit_code == 0
    folder = RunFolder(tmp_path / "run")
    assert folder.report()["status"] == "passed"
    assert any("run.mcap" in e and "No space left" in e for e in folder.report()["log_errors"])
    assert len(warned) == 1 and "the run goes on" in warned[0]
    assert not (folder.path / "run.mcap").exists()


def test_a_full_queue_drops_and_says_so(tmp_path):
    log = mcap_log.McapLog(tmp_path, ARM, queue_size=1)
    for n in range(200):   # far faster than the thread converts them
        log.put({"t": 0.0, "type": "step_started", "step": n})
    log.close()
    assert log.dropped > 0


@pytest.mark.parametrize("ros, written", [('[ros]\nmcap = false\n', None),
                                           ('[ros]\ndistribution = "humble"\n', "humble")])
def test_the_campaign_switches_run_mcap_off_or_picks_the_distribution(tmp_path, ros, written):
    from projecttree import CONFIG, make_project

    root = make_project(tmp_path / "campaign", sequences=("startup.yaml",))
    (root / "seqrun.toml").write_text(CONFIG + ros, encoding="utf-8")
    run = run_on_sim("startup", tmp_path, root=root)
    assert run.outcome.result.exit_code == 0
    folder = RunFolder(tmp_path / "run")
    if written is None:
        assert not (folder.path / "run.mcap").exists() and "ros" not in folder.report()
        return
    assert folder.report()["ros"] == {"namespace": "lwa3", "distribution": written}
    with AnyReader([folder.path / "run.mcap"],
                   default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        assert {c.topic for c in reader.connections} >= {"/lwa3/joint_states", "/tf"}
        assert sum(1 for _ in reader.messages()) > 0


def test_a_bad_distribution_in_seqrun_toml_is_one_line(tmp_path):
    from projecttree import CONFIG, make_project
    from seqrun.sequence.project import ConfigInvalid, load_config

    root = make_project(tmp_path / "campaign")
    (root / "seqrun.toml").write_text(CONFIG + '[ros]\ndistribution = "noetic"\n')
    with pytest.raises(ConfigInvalid) as info:
        load_config(root / "seqrun.toml")
    assert "seqrun.toml:5" in str(info.value.errors[0])


def quaternion_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


# -- the fast encoders write rosbags' bytes -------------------------------------------------
angles = st.lists(st.floats(-180, 180, allow_nan=False), min_size=7, max_size=7)


@settings(max_examples=40, deadline=None)
@given(joints=angles, velocities=st.one_of(st.none(), angles),
       stamp=st.integers(0, (2**31 - 1) * 10**9), label=st.text(max_size=12))
def test_cdr_encoders_write_the_bytes_of_rosbags_serializer(joints, velocities, stamp, label):
    records = [Joints("joint_states", stamp, 0, tuple(ARM.joint_names), tuple(joints),
                      None if velocities is None else tuple(velocities)),
               Frames(stamp, 0, tuple(transforms(ARM, joints, NAMES))),
               Shapes(stamp, 0, tuple(marker_shapes(ARM, joints))),
               EventLine(stamp, 0, "x", json.dumps({"label": label}), "info", label)]
    for distribution in mcap_log.DISTRIBUTIONS:
        store = typestore_of(distribution)
        builder = MessageBuilder(store)
        for record in records:
            ((topic, msgtype, fields),) = messages(record, NAMES)
            expected = bytes(store.serialize_cdr(builder.build(msgtype, fields), msgtype))
            assert mcap_log.encoded_record(record, NAMES) == (topic, expected), (distribution, msgtype)


@settings(max_examples=200, deadline=None)
@given(rpy=st.lists(st.floats(-math.pi, math.pi, allow_nan=False), min_size=3, max_size=3))
def test_quaternions_turn_as_the_matrices_do(rpy):
    from seqrun.arm.kinematics import matrix_from_rpy

    rotation = matrix_from_rpy(rpy)
    x, y, z, w = quaternion_xyzw(rotation)
    assert w >= 0 and math.isclose(x * x + y * y + z * z + w * w, 1.0, abs_tol=1e-12)
    np.testing.assert_allclose(quaternion_matrix(x, y, z, w), rotation, atol=1e-9)


def test_cdr_string_is_utf8_with_its_terminator():
    data = cdr.string("ü")
    assert data == b"\x00\x01\x00\x00" + (3).to_bytes(4, "little") + "ü".encode() + b"\x00"


def test_robot_description_is_the_urdf_once_at_the_start(opsafe):
    """run.mcap carries the arm's URDF (what `seqrun urdf` writes, links named as the
    frames of /tf), so a bag played into RViz or opened in Foxglove draws the model."""
    from seqrun.service.kinematics import robot_description

    bag = read_bag(opsafe.path / "run.mcap")
    (stamp, message), = bag["/robot_description"]
    assert message.data == robot_description(ARM, "lwa3/")
    assert f'<link name="{NAMES.base_frame}"' in message.data
    assert stamp == ns(opsafe.report()["start_epoch_s"])


# -- a standard, compact bag (issue 41.3) ------------------------------------------------------
def test_channels_offer_the_qos_rosbag2_records(opsafe):
    """rosbag2 records each publisher's offered QoS in the channel metadata; run.mcap said
    nothing (``offered_qos_profiles: []``), so a player made /tf_static volatile."""
    import yaml

    with open(opsafe.path / "run.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    for channel in summary.channels.values():
        profiles = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert len(profiles) == 1, channel.topic
        (qos,) = profiles
        assert qos["reliability"] == "reliable" and qos["history"] == "keep_last"
        latched_topic = channel.topic in ("/tf_static", "/robot_description")
        assert qos["durability"] == ("transient_local" if latched_topic else "volatile"), \
            channel.topic
        assert qos["deadline"] == {"sec": 9223372036, "nsec": 854775807}
    latched = {name: mcap_log.offered_qos(name) for name in
               ("/tf_static", "/lwa3/robot_description", "/tf", "/lwa3/joint_states")}
    assert [q.durability.name for q in latched.values()] == [
        "TRANSIENT_LOCAL", "TRANSIENT_LOCAL", "VOLATILE", "VOLATILE"]
    assert latched["/tf_static"].depth == 1


def test_chunks_are_zstd_and_the_rosbag2_metadata_names_run_mcap(opsafe):
    """zstd chunks (as rosbag2's zstd presets write them); the bag's own metadata gave its
    file as ``run.mcap.partial.mcap``."""
    import yaml

    with open(opsafe.path / "run.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.chunk_indexes
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        packed = sum(c.compressed_size for c in summary.chunk_indexes)
        assert packed * 3 < sum(c.uncompressed_size for c in summary.chunk_indexes)
        (record,) = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
    metadata = yaml.safe_load(record.metadata["serialized_metadata"])
    assert metadata["relative_file_paths"] == ["run.mcap"]
    assert [f["path"] for f in metadata["files"]] == ["run.mcap"]
    assert metadata["compression_mode"] == "" and metadata["storage_identifier"] == "mcap"
    assert sum(t["message_count"] for t in metadata["topics_with_message_count"]) == \
        metadata["message_count"] > 1000


def test_joint_states_carry_the_measured_velocity(opsafe):
    """The bag's joint_states had positions only; the node and Foxglove publish the
    windowed velocity estimate: the same estimate, in rad/s, over the readings' times.
    Effort stays empty (the streamed cycle does not read the modules' current)."""
    from seqrun.arm.tracking import sample_time, velocity_window, windowed_velocity

    bag = read_bag(opsafe.path / "run.mcap")
    readings = [e for e in opsafe.events() if e["type"] in ("setpoint", "measurement")]
    states = [msg for _, msg in bag["/lwa3/joint_states"]]
    assert len(states) == len(readings)
    t = np.array([sample_time(e["read_t"]) if e["type"] == "setpoint" else e["t"]
                  for e in readings])
    q = np.array([e.get("measured_deg", e.get("joints_deg")) for e in readings])
    expected = windowed_velocity(t, q, velocity_window(1.0 / ARM.control.cycle_hz))
    with_velocity = 0
    for msg, row in zip(states, expected):
        assert len(msg.effort) == 0
        if len(msg.velocity) == 0:
            continue
        with_velocity += 1
        np.testing.assert_allclose(msg.velocity, np.radians(row), atol=np.radians(1e-3))
    assert with_velocity > 0.9 * len(states)
    assert max(float(np.max(np.abs(m.velocity))) for m in states if len(m.velocity)) > 0.1


def test_the_bag_converts_to_a_ros1_bag_and_a_db3_bag_with_every_message(opsafe, tmp_path):
    """rosbags' converter (what ``rosbags-convert`` runs) reads run.mcap, zstd chunks and
    all, into a ROS 1 bag and a rosbag2 SQLite bag with the same messages per topic."""
    from rosbags.convert import convert

    def counts(path: Path) -> dict[str, int]:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            out: dict[str, int] = {}
            for conn, _, _ in reader.messages():
                out[conn.topic] = out.get(conn.topic, 0) + 1
            return out

    source = counts(opsafe.path / "run.mcap")
    assert source["/tf"] > 1000
    for dst, storage, version in ((tmp_path / "run.bag", "sqlite3", 2),
                                  (tmp_path / "run_db3", "sqlite3", 9)):
        convert([opsafe.path / "run.mcap"], dst, storage, version, None, "file", None, None,
                [], [], [], [])
        assert counts(dst) == source, dst
    assert (tmp_path / "run.bag").is_file()
    assert list((tmp_path / "run_db3").glob("*.db3"))
