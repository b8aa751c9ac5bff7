"""``seqrun ros``'s node (seqrun/ros/node.py) on the ROS 2 graph, with a client node in the
same process: the simulated arm in real time, discovery on this host only
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and a ROS domain of each test worker's own, so
parallel workers (and other test runs on this machine) do not see each other's nodes.

Each test's node and topics have names of its own too (another test run on this machine may
draw the same domain). A trajectory moves the arm; one through the desk is refused with the
reason and moves nothing; ~/stop halts mid-move and says so only when every module read back HALTED;
~/reset and ~/home; joint_states at 50 Hz or more; without rclpy, one line."""

from __future__ import annotations

import contextlib
import json
import math
import os
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest
import rclpy
from builtin_interfaces.msg import Duration
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from seqrun.arm.description import load_arm
from seqrun.clock import RealClock
from seqrun.powercube.protocol import BROADCAST_ID
from seqrun.ros.node import SeqrunNode
from seqrun.service import ArmSession
from seqrun.service.connection import open_connection

ROOT = Path(__file__).resolve().parents[1]
ARM = ROOT / "arms" / "lwa3.yaml"


def domain_id() -> int:
    """A ROS domain for this test process: the xdist worker's number and the process id
    (another pytest run on the machine), within 1-100 (valid on every host)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw")
    worker_n = int(worker) if worker.isdigit() else 0
    return 1 + (os.getpid() * 7 + worker_n) % 100


class Graph:
    """The node on a real-time simulated arm, a client node, both spun in one executor."""

    def __init__(self, tmp_path: Path) -> None:
        # names of this test's own: other test runs on the machine may share the domain
        token = uuid.uuid4().hex[:8]
        self.arm, self.name = f"lwa3_{token}", f"seqrun_{token}"
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id())
        connection = open_connection(force_sim=True, clock=RealClock())
        self.session = ArmSession(load_arm(ARM), connection, log_root=tmp_path / "runs",
                                  poses_dir=ROOT / "poses")
        self.sent: list = []
        self.session.client.add_frame_listener(self._on_frame)
        self.session.poll_status()
        assert self.session.arm_up().ok and self.session.home().ok
        self.session.poll_status()
        self.seqrun = SeqrunNode(self.session, arm_name=self.arm, context=self.context,
                                 node_name=self.name)
        self.client = Node("seqrun_test_client", context=self.context)
        self.states: list = []
        self.events: list = []
        self.client.create_subscription(JointState, f"/{self.arm}/joint_states",
                                        self.states.append, 100)
        self.client.create_subscription(String, f"/{self.name}/events",
                                        lambda m: self.events.append(json.loads(m.data)), 1000)
        self.trajectories = self.client.create_publisher(JointTrajectory,
                                                         f"/{self.arm}/joint_trajectory", 10)
        self.services = {name: self.client.create_client(Trigger, f"/{self.name}/{name}")
                         for name in ("stop", "home", "reset")}
        # the node as `seqrun ros` spins it; the client on an executor of its own (one
        # thread: appending messages needs no more), as another process's would be
        self.executor = MultiThreadedExecutor(num_threads=4, context=self.context)
        self.executor.add_node(self.seqrun.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        self.client_executor = SingleThreadedExecutor(context=self.context)
        self.client_executor.add_node(self.client)
        self.client_thread = threading.Thread(target=self.client_executor.spin, daemon=True)
        self.client_thread.start()
        self.wait_for(lambda: self.trajectories.get_subscription_count() > 0
                      and all(c.service_is_ready() for c in self.services.values())
                      and len(self.states) > 0, "the node on the graph")

    def _on_frame(self, msg) -> None:
        if not msg.is_rx:
            self.sent.append((msg.arbitration_id, bytes(msg.data)))

    def motion_frames(self) -> list:
        return [f for f in self.sent if f[0] != BROADCAST_ID and f[1][:1] == b"\x0b"]

    def halt_broadcasts(self) -> list:
        return [f for f in self.sent if f[0] == BROADCAST_ID and f[1][:1] == b"\x02"]

    @staticmethod
    def wait_for(condition, what: str, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out waiting for {what}")
            time.sleep(0.01)

    def event(self, type_: str, timeout: float = 30.0) -> dict:
        self.wait_for(lambda: any(e["type"] == type_ for e in self.events), type_, timeout)
        return next(e for e in self.events if e["type"] == type_)

    def send(self, names, *points) -> None:
        """points: (degrees..., seconds from start)."""
        msg = JointTrajectory()
        msg.joint_names = list(names)
        for p in points:
            point = JointTrajectoryPoint()
            point.positions = [math.radians(d) for d in p[:-1]]
            point.time_from_start = Duration(sec=int(p[-1]), nanosec=int(p[-1] % 1 * 1e9))
            msg.points.append(point)
        self.trajectories.publish(msg)

    def call(self, name: str):
        future = self.services[name].call_async(Trigger.Request())
        self.wait_for(future.done, f"~/{name}'s answer")
        return future.result()

    def joints_deg(self) -> dict:
        last = self.states[-1]
        return {n: math.degrees(p) for n, p in zip(last.name, last.position)}

    def close(self) -> None:
        self.executor.shutdown()  # the spins end before the nodes go ...
        self.client_executor.shutdown()
        for thread in (self.thread, self.client_thread):
            thread.join(timeout=10)
            assert not thread.is_alive()
        time.sleep(0.5)  # ... and so do callbacks under way (shutdown does not wait for them)
        self.seqrun.close()
        self.client.destroy_node()
        self.session.close()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def graph(tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    # (each test's names are its own: the node need not listen long for another of them)
    monkeypatch.setattr("seqrun.ros.node.DISCOVERY_S", 0.2, raising=False)
    g = Graph(tmp_path)
    yield g
    g.close()


def test_a_trajectory_moves_the_simulated_arm(graph):
    graph.send(("j1", "j2"), (8, -84, 0.5), (12, -80, 1.0))
    accepted = graph.event("trajectory_accepted")
    assert accepted["points"] == 2
    finished = graph.event("trajectory_finished")
    assert finished["status"] == "passed" and finished["exit_code"] == 0
    assert Path(finished["run_dir"], "events.jsonl.gz").is_file()
    graph.wait_for(lambda: abs(graph.joints_deg()["j1"] - 12) < 0.1, "joint_states at j1 12°")
    assert graph.joints_deg()["j2"] == pytest.approx(-80, abs=0.1)
    assert graph.motion_frames()
    # the run's own events came on ~/events, the per-cycle measurements did not
    types = [e["type"] for e in graph.events]
    assert {"run_started", "step_finished", "run_finished"} <= set(types)
    assert "measurement" not in types and "setpoint" not in types


def test_a_trajectory_through_the_desk_is_refused_with_the_reason_and_moves_nothing(graph):
    before = graph.joints_deg()
    graph.send(("j2",), (-110, 2.0))
    refused = graph.event("trajectory_refused")
    assert refused["reason"].startswith("trajectory point 1/1 (t=2 s): ")
    assert "desk" in refused["reason"]
    time.sleep(0.2)
    assert graph.motion_frames() == [] and graph.session.activity is None
    assert graph.joints_deg() == pytest.approx(before, abs=1e-6)
    assert "trajectory_accepted" not in [e["type"] for e in graph.events]


def test_stop_halts_mid_move_confirmed_on_the_bus_then_reset_and_home(graph):
    graph.send(("j1",), (60, 6.0))
    graph.event("trajectory_accepted")
    graph.wait_for(lambda: graph.joints_deg()["j1"] > 2, "the arm moving")
    answer = graph.call("stop")
    assert answer.success, answer.message
    assert answer.message == "Halt confirmed by every module"
    assert graph.halt_broadcasts()
    finished = graph.event("trajectory_finished")
    assert finished["status"] != "passed" and finished["exit_code"] != 0
    status = graph.session.poll_status()  # read back from the modules
    assert all("HALTED" in flags for flags in status.flags.values())
    stopped_at = status.joints_deg["j1"]
    assert 2 < stopped_at < 50
    time.sleep(0.3)
    assert graph.session.poll_status().joints_deg["j1"] == pytest.approx(stopped_at, abs=0.05)
    # nothing restarts it: a new trajectory is refused while halted ...
    graph.events.clear()
    graph.send(("j1",), (0, 3.0))
    assert "halted" in graph.event("trajectory_refused")["reason"]
    # ... until ~/reset, then ~/home
    reset = graph.call("reset")
    assert reset.success, reset.message
    home = graph.call("home")
    assert home.success, home.message


def test_home_is_refused_in_one_line_while_halted(graph):
    assert graph.call("stop").success
    answer = graph.call("home")
    assert not answer.success and answer.message.startswith("home refused: ")
    assert "halted" in answer.message and "\n" not in answer.message


# ---------------------------------------------------------------------- FollowJointTrajectory
class Codes:
    """control_msgs/FollowJointTrajectory's result codes (no control_msgs wheel exists: the
    action server itself needs a ROS host; what a goal does is tested here)."""

    SUCCESSFUL, INVALID_GOAL, PATH_TOLERANCE_VIOLATED = 0, -1, -4


class Goal:
    """A goal handle as rclpy's action server hands one to its execute callback."""

    def __init__(self) -> None:
        self.is_cancel_requested = False
        self.ended: list[str] = []

    def succeed(self) -> None:
        self.ended.append("succeeded")

    def abort(self) -> None:
        self.ended.append("aborted")

    def canceled(self) -> None:
        self.ended.append("canceled")


def joint_trajectory(names, *points):
    from seqrun.service.trajectories import JointTrajectory as Plain, TrajectoryPoint

    return Plain(tuple(names), tuple(TrajectoryPoint(tuple(math.radians(d) for d in p[:-1]),
                                                     p[-1]) for p in points))


def test_a_follow_joint_trajectory_goal_runs_like_the_topic(graph):
    goal = Goal()
    code, text = graph.seqrun.follow_trajectory(joint_trajectory(("j1",), (6, 0.5)), goal,
                                                Codes)
    assert (code, goal.ended) == (Codes.SUCCESSFUL, ["succeeded"]), text
    assert graph.session.poll_status().joints_deg["j1"] == pytest.approx(6, abs=0.1)


def test_a_goal_through_the_desk_is_aborted_as_invalid_with_the_reason(graph):
    goal = Goal()
    code, text = graph.seqrun.follow_trajectory(joint_trajectory(("j2",), (-110, 2.0)), goal,
                                                Codes)
    assert (code, goal.ended) == (Codes.INVALID_GOAL, ["aborted"])
    assert text.startswith("trajectory point 1/1 (t=2 s): ") and "desk" in text
    assert graph.motion_frames() == []


def test_a_cancelled_goal_ends_in_a_controlled_stop(graph):
    goal = Goal()
    outcome: list = []
    worker = threading.Thread(target=lambda: outcome.append(graph.seqrun.follow_trajectory(
        joint_trajectory(("j1",), (60, 6.0)), goal, Codes)))
    worker.start()
    graph.wait_for(lambda: graph.session.status().joints_deg["j1"] > 2, "the arm moving")
    goal.is_cancel_requested = True
    worker.join(timeout=30)
    assert goal.ended == ["canceled"] and outcome[0][1].startswith("cancelled: ")
    stopped = graph.session.poll_status()
    assert graph.session.activity is None and 2 < stopped.joints_deg["j1"] < 50
    assert not graph.halt_broadcasts()  # a controlled stop, not a Halt
    time.sleep(0.3)
    assert graph.session.poll_status().joints_deg["j1"] == pytest.approx(
        stopped.joints_deg["j1"], abs=0.05)


@pytest.mark.slow
def test_joint_states_come_with_every_reading_of_the_session(graph):
    """Counted against the publisher's own stamps over 3 s (the subscriber's delays under
    load do not count), idle and during a move: a message for each reading the session
    took in the same seconds (its rate, 100 Hz asked, is the host's: on a busy host it
    falls below 50 Hz, and a rate goal belongs in a benchmark), and far more than the idle
    poll's 10 a second that the node once published at."""
    readings: list[float] = []
    graph.session.events.add_listener(
        lambda e: readings.append(time.monotonic()) if e.type == "measurement" else None,
        "reading clock")
    graph.states.clear()
    time.sleep(1.5)
    graph.send(("j1",), (10, 1.0))
    time.sleep(1.5)
    stamps = [s.header.stamp.sec + s.header.stamp.nanosec * 1e-9 for s in graph.states]
    span = stamps[-1] - stamps[0]
    assert span > 2.0   # (a window long enough to count in; its ends vary with the host)
    rate = (len(stamps) - 1) / span
    session_rate = (len(readings) - 1) / (readings[-1] - readings[0])
    assert rate >= 0.8 * session_rate, f"{rate:.1f} Hz published, {session_rate:.1f} read"
    assert rate >= 25, f"{rate:.1f} Hz"


def test_the_tf_body_is_the_chain_at_the_measured_joints(graph):
    """/tf itself needs tf2_msgs (a ROS host); its TransformStamped list is built here."""
    from builtin_interfaces.msg import Time

    joints = list(graph.session.status().joints_deg.values())
    frames = graph.seqrun.transforms(joints, Time(sec=5, nanosec=7))
    first = (frames[0].header.frame_id, frames[0].child_frame_id)
    assert first == (f"{graph.arm}/base", f"{graph.arm}/j1")
    assert frames[-1].child_frame_id == f"{graph.arm}/end_effector" and len(frames) == 8
    assert all(t.header.stamp.sec == 5 and t.header.stamp.nanosec == 7 for t in frames)
    # Park: the end effector's frame sits on the last joint's z axis, metres
    assert frames[-1].transform.translation.x == pytest.approx(0, abs=1e-9)


@contextlib.contextmanager
def ros_command(*args: str, cwd: Path, env: dict):
    """``seqrun ros ARGS`` as a process, read until it serves: ``(proc, printed)``; killed
    on the way out if the test did not end it."""
    proc = subprocess.Popen([sys.executable, "-m", "seqrun", "ros", *args], cwd=cwd, env=env,
                            text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    printed: list[str] = []
    try:
        for line in proc.stdout:
            printed.append(line)
            if line.startswith("seqrun ros on SIMULATOR"):
                break
        yield proc, printed
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.slow
def test_the_command_serves_the_arm_and_halts_on_sigterm(tmp_path, monkeypatch):
    """``seqrun ros --sim`` as a process: ~/reset and ~/home, a trajectory, then SIGTERM
    ends it with a confirmed Halt (exit 130)."""
    import signal as signals

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    domain = domain_id()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    token = uuid.uuid4().hex[:8]
    arm, name = f"lwa3_{token}", f"seqrun_{token}"
    with ros_command("--sim", "--log-dir", str(tmp_path / "runs"), "--arm-name", arm,
                     "--node-name", name, cwd=ROOT, env=env) as (proc, printed):
        assert f"/{arm}/joint_trajectory" in printed[-1], "".join(printed)
        assert f"/{name}/stop" in printed[-1]
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        client = Node("seqrun_command_client", context=context)
        states: list = []
        events: list = []
        client.create_subscription(JointState, f"/{arm}/joint_states", states.append, 100)
        client.create_subscription(String, f"/{name}/events",
                                   lambda m: events.append(json.loads(m.data)), 100)
        publisher = client.create_publisher(JointTrajectory, f"/{arm}/joint_trajectory", 10)
        spinner = MultiThreadedExecutor(num_threads=2, context=context)
        spinner.add_node(client)
        thread = threading.Thread(target=spinner.spin, daemon=True)
        thread.start()
        try:
            for what in ("reset", "home"):
                service = client.create_client(Trigger, f"/{name}/{what}")
                Graph.wait_for(service.service_is_ready, f"~/{what}")
                future = service.call_async(Trigger.Request())
                Graph.wait_for(future.done, f"~/{what}'s answer")
                assert future.result().success, future.result().message
            Graph.wait_for(lambda: states and publisher.get_subscription_count() > 0,
                           "joint_states")
            msg = JointTrajectory(joint_names=["j1"], points=[JointTrajectoryPoint(
                positions=[math.radians(5)], time_from_start=Duration(sec=1))])
            publisher.publish(msg)
            Graph.wait_for(lambda: any(e["type"] == "trajectory_finished" for e in events),
                           "the trajectory's end")
            finished = [e for e in events if e["type"] == "trajectory_finished"][0]
            assert finished["exit_code"] == 0, finished
            assert math.degrees(states[-1].position[0]) == pytest.approx(5, abs=0.1)
        finally:
            spinner.shutdown()
            thread.join(timeout=10)
            client.destroy_node()
            rclpy.shutdown(context=context)
        proc.send_signal(signals.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 130, "".join(printed) + out
    assert "seqrun ros: ended by SIGTERM; " in out and "Traceback" not in out


@pytest.mark.slow
def test_one_arm_of_several_serves_under_its_id(tmp_path, monkeypatch):
    """``seqrun ros --arm-id B`` in a campaign with several arms: B's topics under /B/ and
    its node seqrun_B (each arm's node its own, as /A/, /B/ in the campaign's run.mcap)."""
    import shutil
    import signal as signals

    campaign = tmp_path / "two-arms"
    shutil.copytree(ROOT / "examples" / "two-arms", campaign)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id()),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", HOME=str(tmp_path),
               SEQRUN_STATE_DIR=str(tmp_path / "state"))
    refused = subprocess.run([sys.executable, "-m", "seqrun", "ros", "--sim"], cwd=campaign,
                             env=env, capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and "name one (--arm-id ID)" in refused.stderr
    with ros_command("--sim", "--arm-id", "B", cwd=campaign, env=env) as (proc, printed):
        assert printed and printed[0].startswith("arm B: "), "".join(printed)
        assert "/B/joint_states, /B/joint_trajectory, /seqrun_B/stop" in printed[-1], \
            "".join(printed)
        proc.send_signal(signals.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 130, "".join(printed) + out


def test_a_second_node_for_the_same_name_or_arm_refuses_to_start(graph, tmp_path,
                                                                  monkeypatch):
    """Issue 43: two ``seqrun ros`` nodes with the same arm name on one domain started
    without a word; one trajectory ran on both arms. Another context on the domain (as
    another process would be) and another simulated arm: the graph refuses, not the desk."""
    import seqrun.ros.node

    NodeTaken = getattr(seqrun.ros.node, "NodeTaken", RuntimeError)  # (before it: no such)
    monkeypatch.setattr("seqrun.ros.node.DISCOVERY_S", 20.0, raising=False)  # (until seen)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id())
    connection = open_connection(force_sim=True, clock=RealClock())
    other = ArmSession(load_arm(ARM), connection, log_root=tmp_path / "other",
                       poses_dir=ROOT / "poses")
    try:
        with pytest.raises(NodeTaken) as taken:
            SeqrunNode(other, arm_name=f"{graph.arm}_other", context=context,
                       node_name=graph.name)
        assert f"/{graph.name} is already on the ROS domain" in str(taken.value)
        with pytest.raises(NodeTaken) as taken:
            SeqrunNode(other, arm_name=graph.arm, context=context,
                       node_name=f"{graph.name}_other")
        assert f"arm /{graph.arm} is already served" in str(taken.value)
        assert other.control.state().clients == ()   # nothing of it stayed on the desk
    finally:
        other.close()
        rclpy.shutdown(context=context)


def test_the_node_commands_through_the_desk(graph):
    """The node holds its session's control; a client that takes it over leaves the node's
    commands refused, naming the holder (STOP still works)."""
    holder = graph.session.control.state().holder
    assert holder.kind == "ros" and holder.name == f"ROS node /{graph.name}"
    graph.session.control.join_and_take("api-x", "console script (api-x)", "api",
                                        take_over=True)
    answer = graph.call("home")
    assert answer.success is False and "console script (api-x) holds control" in \
        answer.message
    assert graph.call("stop").success is True


@pytest.mark.slow
def test_the_command_refuses_a_second_node_in_one_line(monkeypatch):
    """``seqrun ros`` where a node of its name is on the domain: exit 2, one line."""
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    token = uuid.uuid4().hex[:8]
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id())
    there = Node(f"seqrun_{token}", context=context)
    try:
        # (watched until seen: on a busy host discovery takes longer than the default 3 s,
        # and a node that did not see the other would serve)
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id()), SEQRUN_ROS_DISCOVERY_S="60")
        refused = subprocess.run([sys.executable, "-m", "seqrun", "ros", "--sim",
                                  "--arm-name", f"lwa3_{token}", "--node-name",
                                  f"seqrun_{token}"], cwd=ROOT, env=env, capture_output=True,
                                 text=True, timeout=120, stdin=subprocess.DEVNULL)
    finally:
        there.destroy_node()
        rclpy.shutdown(context=context)
    assert refused.returncode == 2, refused.stdout + refused.stderr
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: ROS node /seqrun_{token} is "
                                                   "already on the ROS domain"), lines


# ---------------------------------------------------------------------- without the extra
def test_without_rclpy_seqrun_ros_says_in_one_line_how_to_install_it(tmp_path):
    """rclpy made unimportable the public way: a package of that name that raises
    ImportError, first on PYTHONPATH."""
    shadow = tmp_path / "shadow" / "rclpy"
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text("raise ImportError('rclpy is not installed')\n")
    env = dict(os.environ, PYTHONPATH=str(shadow.parent))
    done = subprocess.run([sys.executable, "-m", "seqrun", "ros", "--sim"], env=env,
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 2
    assert done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert "pip install 'seqrun[ros]'" in lines[0] and "Traceback" not in done.stderr


def test_a_messages_velocities_and_accelerations_reach_the_service_layer():
    from seqrun.ros.node import trajectory_of

    msg = JointTrajectory(joint_names=["j1"], points=[
        JointTrajectoryPoint(positions=[0.1], velocities=[0.2], accelerations=[0.3],
                             time_from_start=Duration(sec=1, nanosec=500_000_000))])
    (point,) = trajectory_of(msg).points
    assert point.positions_rad == (0.1,) and point.time_from_start_s == 1.5
    assert point.velocities_rad_s == (0.2,) and point.accelerations_rad_s2 == (0.3,)
    bare = trajectory_of(JointTrajectory(joint_names=["j1"], points=[
        JointTrajectoryPoint(positions=[0.1], time_from_start=Duration(sec=1))]))
    assert bare.points[0].velocities_rad_s == ()
