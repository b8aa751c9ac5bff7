"""``seqrun ros`` as a ROS 2 user expects it (issue 41, items 2 and 4): the URDF on
``robot_description`` (transient local), ``joint_states`` stamped when the modules answered,
each reading once, the node's parameters declared and documented, ``--ros-args`` handed to
rclpy (namespace, node name, parameters). Run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
and a domain of this test process (tests/test_ros_node.py's)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
import uuid

import pytest
import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rcl_interfaces.srv import GetParameters
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from test_ros_node import ARM, ROOT, Graph, domain_id, ros_command
from seqrun.arm.description import load_arm
from seqrun.cli.ros import split_ros_args
from seqrun.ros.node import PARAMETERS
from seqrun.service.kinematics import robot_description

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture
def graph(tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    g = Graph(tmp_path)
    yield g
    g.close()


def late_subscriber(graph: Graph, topic: str) -> list:
    """A subscriber made after the node published: only transient local reaches it."""
    got: list = []
    graph.client.create_subscription(String, topic, got.append, LATCHED)
    graph.wait_for(lambda: got, f"{topic} (transient local)")
    return got


def test_the_urdf_is_on_robot_description_for_a_late_subscriber(graph):
    time.sleep(0.5)  # well after the node published it
    got = late_subscriber(graph, "/robot_description")
    assert got[0].data == robot_description(load_arm(ARM), f"{graph.arm}/")
    assert f'<link name="{graph.arm}/j7"' in got[0].data


def wall_minus_monotonic() -> float:
    """The system clock less the monotonic one (the largest of a few back-to-back
    differences: a pair the scheduler splits only comes out smaller)."""
    return max(time.time() - time.monotonic() for _ in range(5))


def test_joint_states_are_stamped_when_the_modules_answered_each_reading_once(graph):
    """Idle, each message is a reading the session took (its measurement event's
    ``read_clock_s``), stamped at that time (ROS time = wall clock), never the same one
    twice: main stamped a repeated reading at every publish. (A starved host may leave the
    node without a reading for 0.1 s: then it sends the last one again, stamped when sent;
    at most a tenth of them here.)"""
    readings: list[float] = []

    def on_event(event) -> None:
        if event.type == "measurement" and event.read_clock_s is not None:
            readings.append(event.read_clock_s)

    listener = graph.session.events.add_listener(on_event, "test readings", maxsize=10_000)
    try:
        time.sleep(2.0)  # (past the node's first seconds: the session's poll settles)
        graph.states.clear()
        # (how many a second is test_joint_states_come_at_50_hz_or_more's: here, enough
        # of them to judge their stamps, however slowly a loaded host delivers them)
        deadline = time.monotonic() + 10.0
        while len(graph.states) <= 10 and time.monotonic() < deadline:
            time.sleep(0.05)
        states = list(graph.states)
    finally:
        listener.close(timeout=1.0)
    assert len(states) > 10
    offset = wall_minus_monotonic()
    stamps = [s.header.stamp.sec + s.header.stamp.nanosec * 1e-9 - offset for s in states]
    assert len(set(stamps)) == len(stamps), "a stamp was published twice"
    at_a_reading = [any(abs(r - stamp) < 1e-3 for r in readings) for stamp in stamps]
    assert sum(at_a_reading) >= 0.9 * len(stamps), (sum(at_a_reading), len(stamps))


def test_the_parameters_are_declared_and_documented(graph):
    node = graph.seqrun.node
    assert set(PARAMETERS) == {"rate", "publish_tf"}
    assert node.get_parameter("rate").value == 100.0
    assert node.get_parameter("publish_tf").value is True
    for name in PARAMETERS:
        assert node.describe_parameter(name).read_only
    doc = (ROOT / "docs" / "ros2-node.md").read_text(encoding="utf-8")
    table = doc[doc.index("## Parameters"):]
    for name in PARAMETERS:
        assert re.search(rf"^\| `{name}` \|", table, re.M), f"{name} not in the docs' table"


def test_ros_args_are_split_from_the_commands_own():
    assert split_ros_args(["--sim", "--ros-args", "-r", "__ns:=/a", "-p", "rate:=50"]) == (
        ["--sim"], ["--ros-args", "-r", "__ns:=/a", "-p", "rate:=50"])
    assert split_ros_args(["--ros-args", "-p", "rate:=50", "--", "--sim", "-i", "x"]) == (
        ["--sim", "-i", "x"], ["--ros-args", "-p", "rate:=50"])
    assert split_ros_args(["--sim"]) == (["--sim"], [])


@pytest.mark.slow
def test_ros_args_set_namespace_node_name_and_parameters(tmp_path):
    """``seqrun ros --sim --ros-args -r __ns:=/NS -r __node:=NODE -p rate:=50``: the topics
    and services under /NS, the node renamed, its rate 50 Hz; a parameter out of range is
    refused in one line."""
    token = uuid.uuid4().hex[:8]
    namespace, node_name = f"/cell_{token}", f"arm_node_{token}"
    domain = domain_id()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    refused = subprocess.run([sys.executable, "-m", "seqrun", "ros", "--sim", "--log-dir",
                              str(tmp_path / "runs"), "--ros-args", "-p", "rate:=5"],
                             cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert refused.returncode == 2, refused.stdout + refused.stderr
    assert "error: parameter rate must be a number of Hz in 50-1000, got 5" in refused.stderr
    assert "Traceback" not in refused.stderr + refused.stdout
    with ros_command("--sim", "--log-dir", str(tmp_path / "runs"), "--ros-args", "-r",
                     f"__ns:={namespace}", "-r", f"__node:={node_name}", "-p", "rate:=50",
                     cwd=ROOT, env=env) as (proc, printed):
        line = printed[-1]
        assert f"{namespace}/lwa3/joint_states" in line, "".join(printed)
        assert f"{namespace}/{node_name}/stop" in line
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        client = Node("conventions_client", context=context)
        states: list = []
        described: list = []
        client.create_subscription(JointState, f"{namespace}/lwa3/joint_states",
                                   states.append, 100)
        client.create_subscription(String, f"{namespace}/robot_description", described.append,
                                   LATCHED)
        parameters = client.create_client(GetParameters,
                                          f"{namespace}/{node_name}/get_parameters")
        spinner = MultiThreadedExecutor(num_threads=2, context=context)
        spinner.add_node(client)
        thread = threading.Thread(target=spinner.spin, daemon=True)
        thread.start()
        try:
            Graph.wait_for(lambda: states and described, "joint_states and robot_description")
            Graph.wait_for(parameters.service_is_ready, "the parameter service")
            future = parameters.call_async(GetParameters.Request(names=["rate", "publish_tf"]))
            Graph.wait_for(future.done, "the parameters")
            rate, publish_tf = future.result().values
            # -p rate:=50 is ROS's integer 50 (taken as 50 Hz); the default is 100.0
            assert (rate.integer_value, publish_tf.bool_value) == (50, True)
            assert described[0].data.startswith('<?xml version="1.0"?>\n<robot name="lwa3">')
        finally:
            spinner.shutdown()
            thread.join(timeout=10)
            client.destroy_node()
            rclpy.shutdown(context=context)
        proc.terminate()
        proc.communicate(timeout=60)
