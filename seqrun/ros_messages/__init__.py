"""seqrun's state as ROS 2 message field values: one translation for every ROS face.

Pure (numpy and the arm's kinematics, no I/O, no ROS import): the run folder's
``run.mcap`` (:mod:`seqrun.service.mcap_log`, written with ``rosbags``), the live
Foxglove server (:mod:`seqrun.foxglove`) and the ``seqrun ros`` node (rclpy) all turn
these plain values into their own message objects, so the three say the same thing.

- :mod:`.names`: topic and frame names (``/<arm>/joint_states``, ``<arm>/j1`` ...);
- :mod:`.values`: joint states, the FK frames as transforms, the link capsules, guards and
  obstacles as shapes, stamps (nanoseconds of the epoch);
- :mod:`.from_events`: seqrun's events (as ``events.jsonl`` lines) to messages by topic.

Units are ROS's (REP 103): radians, metres, seconds; angles are seqrun's user joint
coordinates (the kinematics' convention, Totem = zeros) in radians.
"""

from __future__ import annotations

from seqrun.ros_messages.names import RosNames, ros_name
from seqrun.ros_messages.values import (Shape, Transform, joint_state, marker_shapes,
                                        quaternion_xyzw, stamp_ns, transforms)

__all__ = ["RosNames", "Shape", "Transform", "joint_state", "marker_shapes",
           "quaternion_xyzw", "ros_name", "stamp_ns", "transforms"]
