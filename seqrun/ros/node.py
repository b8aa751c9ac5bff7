"""The ROS 2 node of ``seqrun ros``: one arm session on the ROS graph.

What it offers (``<arm>``: the arm file's name, e.g. ``lwa3``; ``~``: the node, ``/seqrun``):

- ``<arm>/joint_states`` (``sensor_msgs/JointState``, radians in user coordinates, every
  joint; relative names: under the node's namespace, ``/<arm>/...`` without one) at the
  ``rate`` parameter from the session's latest measurement (never a bus read of its own),
  each reading once, stamped when the modules answered: the control loop's during a
  motion; while idle the session reads the arm at that rate (the node sets its poll);
- ``robot_description`` (``std_msgs/String``, transient local: a late subscriber gets it):
  the arm as a URDF (``seqrun urdf``), link names the frames of ``/tf``;
- ``/tf`` (``tf2_msgs/TFMessage``: ``<arm>/base``, ``<arm>/j1`` ... ``<arm>/j7``, the
  frames that move) and ``/tf_static`` once (the fixed ones: a locked joint,
  ``<arm>/end_effector``, the tools' TCPs) when ``tf2_msgs`` can be imported (a ROS host:
  Jazzy's wheels on the package index have no ``tf2_msgs``) and ``publish_tf`` is true;
- ``/<arm>/joint_trajectory`` (``trajectory_msgs/JointTrajectory``) accepted: each one one
  continuous motion through its points (as joint_trajectory_controller), checked as a
  sequence from where the arm stands and run through the session
  (:mod:`seqrun.service.trajectories`); a refusal (also: one arriving while one runs) is one
  line on ``~/events`` and the log;
- ``~/stop`` (a Halt, confirmed by reading every module back), ``~/reset`` (Reset and the
  arm file's limits written: the console's Arm), ``~/home`` (``std_srvs/Trigger``:
  ``success`` is what the modules read back);
- ``~/events`` (``std_msgs/String``, one JSON object each): the session's events (a run's
  steps, results, faults, halts; not the per-cycle measurements: ``joint_states`` has them)
  and the node's own (``trajectory_accepted``, ``trajectory_refused``,
  ``trajectory_finished``);
- ``/<arm>/follow_joint_trajectory`` (``control_msgs/FollowJointTrajectory``) when
  ``control_msgs`` can be imported (a ROS host), the same path as the topic.

STOP never waits behind anything: its service has a callback group of its own, and the
session's halt takes no lock a run holds.

Parameters (:data:`PARAMETERS`; ``--ros-args -p NAME:=VALUE`` overrides them at start):
``rate`` and ``publish_tf``; and joint_trajectory_controller's ``constraints.*`` (every
trajectory's path and goal tolerances, :mod:`seqrun.arm.trajectory_tolerances`), which a
FollowJointTrajectory goal's own tolerances override joint by joint. Names follow ROS rules: ``--ros-args -r __ns:=/foo`` puts the
topics and services under ``/foo``, ``-r __node:=NAME`` renames the node, ``-r FROM:=TO``
remaps a topic (``/tf`` and ``/tf_static`` are absolute, as tf2's).

Who commands: the node takes control of its session at start, through the session's
control desk (:mod:`seqrun.service.control`), as every face does; its trajectories,
``~/home`` and ``~/reset`` present the desk's secret, ``~/stop`` needs nothing. One arm is
served by one node: the node refuses to start (:class:`NodeTaken`, one line naming it)
when its name is already on the ROS domain, or the arm's ``joint_states`` already has a
publisher or its ``joint_trajectory`` a subscriber (another node drives that arm: one
trajectory would move both).
"""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path
from typing import Any, Callable

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory as JointTrajectoryMsg

from seqrun.errors import Refused, UserInputError
from seqrun.ros import optional_module, ros_name
from seqrun.service.trajectories import (GOAL_TOLERANCE_VIOLATED, JointTrajectory,
                                         TrajectoryPoint, TrajectoryTolerances,
                                         constraint_parameters, in_trajectory_terms,
                                         run_trajectory, tolerances_from_goal,
                                         tolerances_from_parameters)

__all__ = ["DEFAULT_RATE_HZ", "DISCOVERY_S", "NODE_NAME", "NodeTaken", "PARAMETERS",
           "SeqrunNode", "ros_name"]

NODE_NAME = "seqrun"
#: joint_states (and /tf) rate; the issue asks for at least 50 Hz.
DEFAULT_RATE_HZ = 100.0
#: Session events not forwarded to ~/events: per control cycle (joint_states carries them).
HIGH_RATE_EVENTS = frozenset({"measurement", "setpoint"})
#: The node's parameters: name -> what it is (docs/ros2-node.md lists them).
PARAMETERS = {
    "rate": "joint_states (and /tf) rate, Hz, 50-1000 (seqrun ros --rate): while idle the "
            "arm is read at this rate, every message is a new reading",
    "publish_tf": "publish /tf and /tf_static from seqrun's own forward kinematics (false: "
                  "a robot_state_publisher on robot_description and joint_states does)",
}
#: No new reading for this long (s) while the arm was at rest (a run checking itself before
#: it moves holds the bus): the last reading is sent again at the rate, stamped when sent.
REPEAT_AFTER_S = 0.1
#: Every joint slower than this (deg/s) in the last reading: the arm was at rest.
AT_REST_DEG_S = 0.01
#: robot_description and /tf_static: sent once, kept for late subscribers (RViz, a
#: robot_state_publisher started later), as robot_state_publisher does.
LATCHED_DEPTH = 1
#: How long a starting node listens for another node of its name or arm (s): discovery on
#: the domain is not instantaneous (~0.1 s on an idle host, over a second on a busy one).
DISCOVERY_S = 3.0


class NodeTaken(Refused):
    """Another node already serves this node's name or arm on the domain."""



def _seconds(duration: Any) -> float:
    return float(duration.sec) + float(duration.nanosec) * 1e-9


def trajectory_of(msg: Any) -> JointTrajectory:
    """A ``trajectory_msgs/JointTrajectory`` as the service layer's plain data."""
    return JointTrajectory(
        tuple(str(n) for n in msg.joint_names),
        tuple(TrajectoryPoint(tuple(float(x) for x in p.positions),
                              _seconds(p.time_from_start),
                              tuple(float(x) for x in p.velocities),
                              tuple(float(x) for x in p.accelerations)) for p in msg.points))


class SeqrunNode:
    """The node on ``session`` (an :class:`~seqrun.service.session.ArmSession`), in the rclpy
    ``context`` (None: the default one), named ``node_name`` (its services and events are
    ``/<node_name>/stop`` ...: two arms on one graph need two names). Add :attr:`node` to a
    multi-threaded executor."""

    def __init__(self, session: Any, *, arm_name: str, rate_hz: float = DEFAULT_RATE_HZ,
                 context: Any = None, log_dir: Path | None = None,
                 node_name: str = NODE_NAME, discovery_s: float | None = None) -> None:
        self.session = session
        self.arm = ros_name(arm_name)
        self.log_dir = log_dir
        self.node = Node(ros_name(node_name), context=context)
        try:
            self._refuse_if_taken(DISCOVERY_S if discovery_s is None else discovery_s)
            #: The node's control of its session: its commands present this secret.
            self._control = session.control.join_and_take(
                f"ros-{self.node.get_name()}", f"ROS node {self.node.get_fully_qualified_name()}",
                "ros")
        except BaseException:
            self.node.destroy_node()
            raise
        self._names = list(session.arm.joint_names)
        self._closed = False
        # held while publishing: close() destroys no publisher under a callback using it
        self._publishing = threading.Lock()
        rate_hz, self.publish_tf = self._parameters(rate_hz)
        #: JTC's constraints.* parameters: every trajectory's default tolerances.
        self.tolerances = self._constraints()
        self._published_reading: float | None = None
        self._fresh_at = -math.inf
        # while idle the session reads the arm at this rate: every message a new reading
        self._status_hz_before = session.set_status_rate(rate_hz)
        self._stop_group = MutuallyExclusiveCallbackGroup()
        self._command_group = MutuallyExclusiveCallbackGroup()
        self._state_group = MutuallyExclusiveCallbackGroup()
        node = self.node
        self.joint_states = node.create_publisher(JointState, f"{self.arm}/joint_states", 10)
        self.events = node.create_publisher(String, "~/events", 100)
        self.robot_description = self._publish_robot_description()
        tf2_msgs = optional_module("tf2_msgs.msg")
        self._tf_message = getattr(tf2_msgs, "TFMessage", None) if self.publish_tf else None
        self.tf = (node.create_publisher(self._tf_message, "/tf", 100)
                   if self._tf_message is not None else None)
        self._fixed_children = self._publish_tf_static()
        node.create_subscription(JointTrajectoryMsg, f"{self.arm}/joint_trajectory",
                                 self._on_trajectory, 10, callback_group=self._command_group)
        node.create_service(Trigger, "~/stop", self._stop, callback_group=self._stop_group)
        node.create_service(Trigger, "~/home", self._home, callback_group=self._command_group)
        node.create_service(Trigger, "~/reset", self._reset,
                            callback_group=self._command_group)
        self.action_server = self._follow_joint_trajectory()
        # twice the reading rate, so that no reading waits a whole period or is passed over
        self._timer = node.create_timer(0.5 / rate_hz, self.publish_state,
                                        callback_group=self._state_group)
        self._listener = session.events.add_listener(self._forward, "ros ~/events",
                                                     maxsize=10_000)
        log = node.get_logger()
        log.info(f"{self.joint_states.topic_name} at {rate_hz:g} Hz; "
                 f"{self.robot_description.topic_name} (URDF); "
                 f"{self.arm}/joint_trajectory accepted; ~/stop ~/home ~/reset")
        if self.tf is None and self.publish_tf:
            log.warning("/tf not published: tf2_msgs is not installed (a ROS 2 host has it)")
        if self.action_server is None:
            log.info("FollowJointTrajectory not offered: control_msgs is not installed")

    def _refuse_if_taken(self, discovery_s: float) -> None:
        """:class:`NodeTaken` if another node has this node's name or serves its arm (the
        graph watched for ``discovery_s``, before this node publishes anything)."""
        import time

        node, me = self.node, self.node.get_fully_qualified_name()
        states, trajectories = f"/{self.arm}/joint_states", f"/{self.arm}/joint_trajectory"
        deadline = time.monotonic() + discovery_s
        while True:
            same = [n for n, ns in node.get_node_names_and_namespaces()
                    if f"{ns.rstrip('/')}/{n}" == me]
            if len(same) > 1:  # (this node is one of them)
                raise NodeTaken(f"ROS node {me} is already on the ROS domain "
                                f"{self._domain()}: one node per arm (--node-name, "
                                "ROS_DOMAIN_ID)")
            if node.count_publishers(states) or node.count_subscribers(trajectories):
                raise NodeTaken(f"arm /{self.arm} is already served on the ROS domain "
                                f"{self._domain()} ({states} has a publisher or "
                                f"{trajectories} a subscriber): one node per arm "
                                "(--arm-name, ROS_DOMAIN_ID)")
            if time.monotonic() >= deadline:
                return
            time.sleep(0.05)

    def _domain(self) -> Any:
        try:
            return self.node.context.get_domain_id()
        except Exception:  # noqa: BLE001 - only for the message
            return "?"

    def _holder(self, what: str) -> Any:
        """The node's control, checked at the desk (it may have been taken over)."""
        return self.session.control.require(self._control.secret, what)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        with self._publishing:
            if self._closed:
                return
            self._closed = True
        self.session.control.leave(self._control.client.id)
        self._timer.cancel()
        self.session.set_status_rate(self._status_hz_before)
        self._listener.close(timeout=1.0)
        if self.action_server is not None:
            self.action_server.destroy()
        self.node.destroy_node()

    # ------------------------------------------------------------------ parameters
    def _parameters(self, rate_hz: float) -> tuple[float, bool]:
        """Declare :data:`PARAMETERS` (read-only: set at start, by the command's options or
        ``--ros-args -p``); their values, checked (UserInputError in one line)."""
        from rcl_interfaces.msg import ParameterDescriptor

        from rclpy.exceptions import ParameterException

        def declare(name: str, value: Any, **kinds: Any) -> Any:
            descriptor = ParameterDescriptor(description=PARAMETERS[name], read_only=True,
                                             **kinds)
            try:
                return self.node.declare_parameter(name, value, descriptor).value
            except ParameterException as exc:  # an override of the wrong type
                raise UserInputError(f"parameter {name}: {exc}") from None

        # -p rate:=50 is an integer to ROS: a number of either kind is checked below
        rate = declare("rate", float(rate_hz), dynamic_typing=True)
        publish_tf = declare("publish_tf", True)
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) \
                or not 50 <= rate <= 1000:
            raise UserInputError(f"parameter rate must be a number of Hz in 50-1000, "
                                 f"got {rate!r}")
        if not isinstance(publish_tf, bool):
            raise UserInputError(f"parameter publish_tf must be true or false, "
                                 f"got {publish_tf!r}")
        return float(rate), publish_tf

    def _constraints(self) -> TrajectoryTolerances:
        """Declare JTC's ``constraints.*`` parameters (read-only; radians and seconds, 0:
        not set) for the joints not locked; the tolerances they give, checked against the
        arm file (UserInputError in one line: not a number, looser than its bound)."""
        from rcl_interfaces.msg import ParameterDescriptor

        arm = self.session.arm
        values = {}
        for name, what in constraint_parameters(arm).items():
            # dynamic: -p constraints.j2.goal:=0 is an integer to ROS; checked below
            descriptor = ParameterDescriptor(description=what, read_only=True,
                                             dynamic_typing=True)
            values[name] = self.node.declare_parameter(name, 0.0, descriptor).value
        try:
            return tolerances_from_parameters(arm, values)
        except Refused as exc:
            raise UserInputError(str(exc)) from None

    # ------------------------------------------------------------------ the model
    def _latched(self) -> Any:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        return QoSProfile(depth=LATCHED_DEPTH, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                          reliability=ReliabilityPolicy.RELIABLE)

    def _publish_robot_description(self) -> Any:
        """``robot_description``: the URDF, once (transient local)."""
        from seqrun.service.kinematics import robot_description

        publisher = self.node.create_publisher(String, "robot_description", self._latched())
        publisher.publish(String(data=robot_description(self.session.arm, f"{self.arm}/")))
        return publisher

    def _publish_tf_static(self) -> set[str]:
        """The fixed frames on ``/tf_static``, once (where /tf is published); the names of
        their child frames, which ``/tf`` then leaves out."""
        from seqrun.service.kinematics import fixed_transforms

        if self._tf_message is None:
            return set()
        stamp = self.node.get_clock().now().to_msg()
        transforms = [_transform(stamp, *frame)
                      for frame in fixed_transforms(self.session.arm, f"{self.arm}/")]
        self.tf_static = self.node.create_publisher(self._tf_message, "/tf_static",
                                                    self._latched())
        self.tf_static.publish(self._tf_message(transforms=transforms))
        return {t.child_frame_id for t in transforms}

    # ------------------------------------------------------------------ state
    def _stamp(self, measured_at: float | None) -> Any:
        """The stamp of a reading taken at ``measured_at`` (the session's clock) in ROS time
        (the system clock): shifted by the clocks' difference now."""
        from builtin_interfaces.msg import Time

        clock = self.session.clock
        if measured_at is None or getattr(clock, "is_virtual", False):
            return self.node.get_clock().now().to_msg()
        # the largest of three back-to-back differences: a pair the scheduler splits only
        # comes out smaller
        offset = max(time.time() - clock.now() for _ in range(3))
        ns = int(round((measured_at + offset) * 1e9))
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def publish_state(self) -> None:
        """``joint_states`` (and ``/tf``) of the latest reading, each reading once, stamped
        when the modules answered."""
        with self._publishing:
            if not self._closed:
                self._publish_state()

    def _publish_state(self) -> None:
        status = self.session.status()
        if status.updated_at is None:
            return  # nothing measured yet
        degrees = [j.position_deg for j in status.joints]
        if any(d is None for d in degrees):
            return
        measured = status.measured_at if status.measured_at is not None else status.updated_at
        now = time.monotonic()
        speeds = [j.velocity_deg_s for j in status.joints]
        if measured == self._published_reading:
            # sent already: a reading is published once, unless none comes while a run
            # checks itself before moving (it holds the bus): the arm, at rest when last
            # read and not yet commanded, is sent again, stamped when sent
            at_rest = all(v is not None and abs(v) < AT_REST_DEG_S for v in speeds)
            if status.stale or not at_rest or now - self._fresh_at < REPEAT_AFTER_S:
                return
            stamp = self.node.get_clock().now().to_msg()
        else:
            stamp = self._stamp(measured)
            self._published_reading, self._fresh_at = measured, now
        msg = JointState()
        msg.header.stamp = stamp
        msg.name = self._names
        msg.position = [math.radians(d) for d in degrees]
        if all(v is not None for v in speeds):
            msg.velocity = [math.radians(v) for v in speeds]
        self.joint_states.publish(msg)
        if self.tf is not None and self._tf_message is not None:
            self.tf.publish(self._tf_message(transforms=[
                t for t in self.transforms(degrees, msg.header.stamp)
                if t.child_frame_id not in self._fixed_children]))

    def transforms(self, degrees: list, stamp: Any) -> list:
        """``geometry_msgs/TransformStamped`` of every frame of the chain at ``degrees``
        (user degrees, every joint): ``/tf``'s message body."""
        from seqrun.service.kinematics import link_transforms

        out = []
        for parent, child, xyz, quaternion in link_transforms(self.session.arm, degrees,
                                                              f"{self.arm}/"):
            t = TransformStamped()
            t.header.stamp = stamp
            t.header.frame_id = parent
            t.child_frame_id = child
            t.transform.translation.x, t.transform.translation.y, \
                t.transform.translation.z = xyz
            (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
             t.transform.rotation.w) = quaternion
            out.append(t)
        return out

    # ------------------------------------------------------------------ events
    def announce(self, type_: str, **data: Any) -> None:
        """One of the node's own events on ``~/events``."""
        self._send({"type": type_, **data})

    def _send(self, record: dict) -> None:
        with self._publishing:
            if not self._closed:
                self.events.publish(String(data=json.dumps(record, default=str)))

    def _forward(self, event: Any) -> None:
        if event.type not in HIGH_RATE_EVENTS:
            self._send(event.as_dict())

    # ------------------------------------------------------------------ trajectories
    def start_trajectory(self, trajectory: JointTrajectory, by: str,
                         tolerances: TrajectoryTolerances | None = None) -> Any:
        """Check and start ``trajectory`` (Refused with one line) with ``tolerances`` (None:
        the ``constraints.*`` parameters'); announces the outcome and, in a thread of its
        own, the run's end."""
        points = len(trajectory.points)
        try:
            holder = self._holder("trajectory")
            activity = run_trajectory(self.session, trajectory, by=holder.name,
                                      log_dir=self.log_dir,
                                      tolerances=self.tolerances if tolerances is None
                                      else tolerances)
        except Refused as exc:
            self.node.get_logger().error(f"trajectory refused: {exc}")
            self.announce("trajectory_refused", reason=str(exc), points=points, by=by)
            raise
        self.announce("trajectory_accepted", points=points, by=by)

        def finished() -> None:
            result = activity.wait()
            self.announce("trajectory_finished", status=result.status,
                          exit_code=result.exit_code,
                          message=in_trajectory_terms(result.message),
                          run_dir=str(result.run_dir) if result.run_dir else None, by=by)

        threading.Thread(target=finished, name="ros trajectory end", daemon=True).start()
        return activity

    def _on_trajectory(self, msg: Any) -> None:
        try:
            self.start_trajectory(trajectory_of(msg), "ros topic")
        except Refused:
            pass  # announced

    # ------------------------------------------------------------------ services
    def _stop(self, request: Any, response: Any) -> Any:
        try:
            result = self.session.halt("ROS ~/stop")
        except Exception as exc:  # noqa: BLE001 - a STOP that could not be confirmed says so
            response.success, response.message = False, f"halt failed: {exc}"
            return response
        response.success = bool(result.confirmed)
        response.message = ("Halt confirmed by every module" if result.confirmed else
                            f"Halt NOT confirmed: {result.describe_unconfirmed()}"
                            + (f" ({result.error})" if result.error else ""))
        return response

    def _command(self, what: str, response: Any) -> Any:
        try:
            self._holder(what.replace("arm_up", "reset"))
            result = getattr(self.session, what)()
        except Refused as exc:
            response.success = False
            response.message = f"{what.replace('arm_up', 'reset')} refused: {exc}"
            return response
        response.success = bool(result.ok)
        response.message = f"{what.replace('arm_up', 'reset')}: " \
            f"{result.message or result.status}"
        return response

    def _home(self, request: Any, response: Any) -> Any:
        return self._command("home", response)

    def _reset(self, request: Any, response: Any) -> Any:
        """Reset, then the arm file's limits written to the drives (the console's Arm):
        after a STOP, ~/reset is what makes the arm movable again (the modules keep their
        Home)."""
        return self._command("arm_up", response)

    # ------------------------------------------------------------------ the action
    def follow_trajectory(self, trajectory: JointTrajectory, goal: Any, codes: Any,
                          given: Any = None) -> tuple[int, str]:
        """What a FollowJointTrajectory goal does (:func:`_follow`); the action server (on a
        ROS host) calls it with its goal handle. ``given``: the goal's tolerances
        (:func:`tolerances_of`), over the parameters' as JTC (the goal's fields override,
        joint by joint)."""
        if given is None:
            return _follow(self, trajectory, goal, codes, self.tolerances)
        try:
            tolerances = tolerances_from_goal(self.tolerances, *given)
        except Refused as exc:
            goal.abort()
            return codes.INVALID_GOAL, str(exc)
        return _follow(self, trajectory, goal, codes, tolerances)

    def _follow_joint_trajectory(self) -> Any:
        """``control_msgs/FollowJointTrajectory`` on ``/<arm>/follow_joint_trajectory`` when
        control_msgs can be imported; None otherwise."""
        control_msgs = optional_module("control_msgs.action")
        if control_msgs is None:
            return None
        from rclpy.action import ActionServer, CancelResponse, GoalResponse

        action = control_msgs.FollowJointTrajectory

        def execute(goal_handle: Any) -> Any:
            result = action.Result()
            result.error_code, result.error_string = self.follow_trajectory(
                trajectory_of(goal_handle.request.trajectory), goal_handle, action.Result,
                tolerances_of(goal_handle.request))
            return result

        return ActionServer(self.node, action, f"{self.arm}/follow_joint_trajectory",
                            execute_callback=execute,
                            goal_callback=lambda goal: GoalResponse.ACCEPT,
                            cancel_callback=lambda goal: CancelResponse.ACCEPT,
                            callback_group=ReentrantCallbackGroup())


def _transform(stamp: Any, parent: str, child: str, xyz: Any, quaternion: Any) -> Any:
    """One ``geometry_msgs/TransformStamped``."""
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id = parent
    t.child_frame_id = child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = xyz
    (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
     t.transform.rotation.w) = quaternion
    return t


def tolerances_of(request: Any) -> tuple[list, list, float]:
    """A FollowJointTrajectory goal's ``path_tolerance``, ``goal_tolerance`` (as (name,
    position, velocity, acceleration)) and ``goal_time_tolerance`` (s)."""
    def rows(tolerances: Any) -> list:
        return [(t.name, float(t.position), float(t.velocity), float(t.acceleration))
                for t in tolerances]

    return (rows(request.path_tolerance), rows(request.goal_tolerance),
            _seconds(request.goal_time_tolerance))


def _follow(node: SeqrunNode, trajectory: JointTrajectory, goal: Any,
            codes: Any, tolerances: TrajectoryTolerances | None = None) -> tuple[int, str]:
    """FollowJointTrajectory's execution: the trajectory through :meth:`start_trajectory`,
    then the run watched until it ends or the client cancels (a controlled stop; a Halt if
    that does not end it). ``goal``: the goal handle (``is_cancel_requested``, ``succeed``,
    ``abort``, ``canceled``); ``codes``: the result's error codes. Returns (error_code,
    error_string)."""
    try:
        activity = node.start_trajectory(trajectory, "ros action", tolerances)
    except Refused as exc:
        goal.abort()
        return codes.INVALID_GOAL, str(exc)
    while not activity.done:
        if goal.is_cancel_requested:
            node.session.abort("FollowJointTrajectory cancelled")
            try:
                ended = activity.wait(timeout=30.0)
            except TimeoutError:
                node.session.halt("FollowJointTrajectory cancelled: no controlled stop")
                ended = activity.wait()
            goal.canceled()
            return codes.SUCCESSFUL, f"cancelled: {in_trajectory_terms(ended.message)}"
        try:
            activity.wait(timeout=0.05)
        except TimeoutError:
            pass
    ended = activity.wait()
    message = in_trajectory_terms(ended.message or ended.status)
    if ended.ok:
        goal.succeed()
        return codes.SUCCESSFUL, message
    goal.abort()
    if GOAL_TOLERANCE_VIOLATED in message:
        return codes.GOAL_TOLERANCE_VIOLATED, message
    return codes.PATH_TOLERANCE_VIOLATED, message


def spin(node: SeqrunNode, *, threads: int = 4, context: Any = None,
         until: Callable[[], bool] = lambda: False, poll_s: float = 0.1) -> None:
    """Serve ``node`` until the context shuts down (Ctrl-C) or ``until()`` is true (asked
    at least every ``poll_s``: SIGTERM sets a flag, it raises nothing into the executor)."""
    from rclpy.executors import MultiThreadedExecutor

    spinner = MultiThreadedExecutor(num_threads=threads, context=context)
    spinner.add_node(node.node)
    try:
        while spinner.context.ok() and not until():
            spinner.spin_once(timeout_sec=poll_s)
    finally:
        spinner.shutdown()
