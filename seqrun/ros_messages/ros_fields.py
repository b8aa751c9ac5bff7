"""The records of :mod:`.from_events` as ROS 2 messages: ``(topic, type, fields)`` with the
fields as nested dicts by their ROS names (a builder for ``rosbags``, rclpy's
``set_message_fields`` or any other ROS library fills in what is left out)."""

from __future__ import annotations

from typing import Any

from seqrun.ros_messages.from_events import (EventLine, Frames, Joints, Planned, Record,
                                             Shapes)
from seqrun.ros_messages.names import EVENTS_TOPIC, MARKERS_TOPIC, TF_TOPIC, RosNames
from seqrun.ros_messages.values import MARKER_TYPES, Shape, joint_state, split_stamp

JOINT_STATE = "sensor_msgs/msg/JointState"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
JOINT_TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
#: /seqrun/events: one ``std_msgs/String`` per event, its ``events.jsonl`` line (JSON).
EVENT_MESSAGE = "std_msgs/msg/String"


Message = tuple[str, str, dict[str, Any]]


def topics(names: RosNames) -> dict[str, str]:
    """Every topic of run.mcap and its message type."""
    return {names.joint_states: JOINT_STATE, names.joint_commands: JOINT_STATE,
            TF_TOPIC: TF_MESSAGE, names.planned: JOINT_TRAJECTORY,
            EVENTS_TOPIC: EVENT_MESSAGE, MARKERS_TOPIC: MARKER_ARRAY}


def _time(ns: int) -> dict[str, int]:
    sec, nanosec = split_stamp(ns)
    return {"sec": sec, "nanosec": nanosec}


def _header(ns: int, frame: str = "") -> dict[str, Any]:
    return {"stamp": _time(ns), "frame_id": frame}


def _xyz(values: Any) -> dict[str, float]:
    return {"x": float(values[0]), "y": float(values[1]), "z": float(values[2])}


def _quaternion(values: Any) -> dict[str, float]:
    return {"x": values[0], "y": values[1], "z": values[2], "w": values[3]}


def marker(shape: Shape, ns: int, frame: str) -> dict[str, Any]:
    r, g, b, a = shape.rgba
    return {"header": _header(ns, frame), "ns": shape.namespace, "id": shape.id,
            "type": MARKER_TYPES[shape.kind], "action": 0,
            "pose": {"position": _xyz(shape.position_m),
                     "orientation": _quaternion(shape.rotation_xyzw)},
            "scale": _xyz(shape.scale_m), "color": {"r": r, "g": g, "b": b, "a": a},
            "frame_locked": False, "text": shape.label}


def _duration(seconds: float) -> dict[str, int]:
    ns = int(round(seconds * 1e9))
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def messages(record: Record, names: RosNames) -> list[Message]:
    """The ROS messages of one record."""
    import math

    if isinstance(record, Joints):
        topic = names.joint_states if record.kind == "joint_states" else names.joint_commands
        return [(topic, JOINT_STATE, {"header": _header(record.stamp_ns),
                                      **joint_state(record.names, record.positions_deg,
                                                    record.velocities_deg_s)})]
    if isinstance(record, Frames):
        return [(TF_TOPIC, TF_MESSAGE, {"transforms": [
            {"header": _header(record.stamp_ns, tf.parent), "child_frame_id": tf.child,
             "transform": {"translation": _xyz(tf.translation_m),
                           "rotation": _quaternion(tf.rotation_xyzw)}}
            for tf in record.transforms]})]
    if isinstance(record, Planned):
        return [(names.planned, JOINT_TRAJECTORY, {
            "header": _header(record.stamp_ns, names.base_frame),
            "joint_names": list(record.names),
            "points": [{"positions": [math.radians(v) for v in pos],
                        "velocities": [math.radians(v) for v in vel],
                        "time_from_start": _duration(t)}
                       for t, pos, vel in zip(record.times_s, record.positions_deg,
                                              record.velocities_deg_s)]})]
    if isinstance(record, Shapes):
        return [(MARKERS_TOPIC, MARKER_ARRAY, {"markers": [
            marker(shape, record.stamp_ns, names.base_frame) for shape in record.shapes]})]
    if isinstance(record, EventLine):
        return [(EVENTS_TOPIC, EVENT_MESSAGE, {"data": record.line})]
    raise TypeError(f"not a record: {record!r}")
