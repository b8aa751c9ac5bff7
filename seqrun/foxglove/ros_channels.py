"""Foxglove live's ROS-typed channels (``--foxglove-types ros``): run.mcap's topics, ROS 2
types and bytes, so that a Foxglove layout made on a recorded run works live.

Every channel is one of run.mcap's (:func:`seqrun.service.mcap_log.bag_topics`): the same
topic, the schema named as the ROS 2 type (``sensor_msgs/msg/JointState``), schema encoding
``ros2msg`` with the definition rosbags' bag writer stores, message encoding ``cdr``; each
message is serialized by the code that writes run.mcap
(:func:`seqrun.service.mcap_log.serialized_record`), never a second copy. An arm of a
campaign of several has the combined run.mcap's names (:mod:`seqrun.service.arms_mcap`:
``/<id>/...``, its events and markers ``/<id>/events`` and ``/<id>/markers``, ``/tf``
shared by every arm).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from seqrun.ros_messages.from_events import Record
from seqrun.ros_messages.names import TF_TOPIC, RosNames
from seqrun.service.arms_mcap import arm_topics
from seqrun.service.mcap_log import (ROBOT_DESCRIPTION_TOPIC, RosSerializer, bag_topics,
                                     robot_description_cdr, serialized_record)

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription

#: The schema and message encodings of run.mcap's channels (rosbag2's MCAP storage).
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"


def ros_channel(context: Any, serializer: RosSerializer, topic: str, msgtype: str) -> Any:
    """A Foxglove channel of ``topic`` carrying ROS 2 ``msgtype`` as run.mcap does."""
    import foxglove

    return foxglove.Channel(topic, schema=foxglove.Schema(
        name=msgtype, encoding=SCHEMA_ENCODING, data=serializer.msgdef(msgtype).encode()),
        message_encoding=MESSAGE_ENCODING, context=context)


class RosChannels:
    """One Foxglove channel per topic of run.mcap, in ``context``: one arm's run.mcap, or
    (``rename``: the arm's own names of seqrun's topics; ``shared``: the channels every arm
    publishes on, by topic, filled by the first) one arm's part of a campaign's."""

    def __init__(self, context: Any, arm: ArmDescription, names: RosNames,
                 distribution: str, *, rename: Mapping[str, str] | None = None,
                 shared: dict[str, Any] | None = None,
                 serializer: RosSerializer | None = None) -> None:
        self.names = names
        self.serializer = serializer or RosSerializer(distribution)
        self.rename = dict(rename or {})
        wanted = bag_topics(names) if rename is None else arm_topics(names)
        shared = {} if shared is None else shared
        self.channels: dict[str, Any] = {}
        for topic, msgtype in wanted.items():
            if topic == TF_TOPIC and topic in shared:
                self.channels[topic] = shared[topic]
                continue
            self.channels[topic] = ros_channel(context, self.serializer, topic, msgtype)
            if topic == TF_TOPIC:
                shared[topic] = self.channels[topic]
        self._description = (robot_description_cdr(arm, names)
                             if ROBOT_DESCRIPTION_TOPIC in self.channels else None)

    @property
    def own(self) -> list[Any]:
        """The channels of this arm alone (the shared ones not twice)."""
        return [c for topic, c in self.channels.items() if topic != TF_TOPIC]

    def publish(self, record: Record) -> None:
        for topic, data in serialized_record(record, self.names, self.serializer):
            self.channels[self.rename.get(topic, topic)].log(bytes(data),
                                                             log_time=record.log_ns)

    def describe(self, log_ns: int) -> None:
        """``/robot_description`` (run.mcap has it once, at the start; live, each new
        subscriber gets it at once, as from a latched publisher); a campaign's run.mcap has
        none."""
        if self._description is None:
            return
        self.channels[ROBOT_DESCRIPTION_TOPIC].log(self._description, log_time=log_ns)


__all__ = ["MESSAGE_ENCODING", "RosChannels", "SCHEMA_ENCODING", "ros_channel"]
