"""Foxglove live's ROS-typed channels (``--foxglove-types ros``): run.mcap's topics, ROS 2
types and bytes, so that a Foxglove layout made on a recorded run works live.

Every channel is one of run.mcap's (:func:`seqrun.service.mcap_log.bag_topics`): the same
topic, the schema named as the ROS 2 type (``sensor_msgs/msg/JointState``), schema encoding
``ros2msg`` with the definition rosbags' bag writer stores, message encoding ``cdr``; each
message is serialized by the code that writes run.mcap
(:func:`seqrun.service.mcap_log.serialized_record`), never a second copy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from seqrun.ros_messages.from_events import Record
from seqrun.ros_messages.names import RosNames
from seqrun.service.mcap_log import (ROBOT_DESCRIPTION_TOPIC, RosSerializer, bag_topics,
                                     robot_description_cdr, serialized_record)

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription

#: The schema and message encodings of run.mcap's channels (rosbag2's MCAP storage).
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"


class RosChannels:
    """One Foxglove channel per topic of run.mcap, in ``context``."""

    def __init__(self, context: Any, arm: ArmDescription, names: RosNames,
                 distribution: str) -> None:
        import foxglove

        self.names = names
        self.serializer = RosSerializer(distribution)
        self.channels = {
            topic: foxglove.Channel(topic, schema=foxglove.Schema(
                name=msgtype, encoding=SCHEMA_ENCODING,
                data=self.serializer.msgdef(msgtype).encode()),
                message_encoding=MESSAGE_ENCODING, context=context)
            for topic, msgtype in bag_topics(names).items()}
        self._description = robot_description_cdr(arm, names)

    def publish(self, record: Record) -> None:
        for topic, data in serialized_record(record, self.names, self.serializer):
            self.channels[topic].log(bytes(data), log_time=record.log_ns)

    def describe(self, log_ns: int) -> None:
        """``/robot_description`` (run.mcap has it once, at the start; live, each new
        subscriber gets it at once, as from a latched publisher)."""
        self.channels[ROBOT_DESCRIPTION_TOPIC].log(self._description, log_time=log_ns)


__all__ = ["MESSAGE_ENCODING", "RosChannels", "SCHEMA_ENCODING"]
