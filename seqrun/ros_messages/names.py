"""Topic and frame names of one arm, shared by run.mcap, Foxglove and the ROS node."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription

#: Topics that belong to seqrun rather than to one arm.
EVENTS_TOPIC = "/seqrun/events"
MARKERS_TOPIC = "/seqrun/markers"
TF_TOPIC = "/tf"


def ros_name(text: str, fallback: str = "arm") -> str:
    """``text`` as one ROS name token: lower-case letters, digits and underscores, starting
    with a letter ("Schunk LWA 3 (RV&D)" -> "schunk_lwa_3_rv_d")."""
    token = re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_")
    if not token:
        return fallback
    return token if token[0].isalpha() else f"{fallback}_{token}"


@dataclass(frozen=True)
class RosNames:
    """The names of one arm: ``namespace`` (the arm file's stem: ``lwa3``) and the joints."""

    namespace: str
    joints: tuple[str, ...]

    @classmethod
    def of(cls, arm: ArmDescription, namespace: str | None = None) -> RosNames:
        return cls(namespace or arm_namespace(arm), tuple(arm.joint_names))

    @property
    def joint_states(self) -> str:
        return f"/{self.namespace}/joint_states"

    @property
    def joint_commands(self) -> str:
        return f"/{self.namespace}/joint_commands"

    @property
    def planned(self) -> str:
        return f"/{self.namespace}/planned"

    @property
    def base_frame(self) -> str:
        return f"{self.namespace}/base"

    @property
    def end_effector_frame(self) -> str:
        return f"{self.namespace}/end_effector"

    def joint_frame(self, joint: str) -> str:
        return f"{self.namespace}/{joint}"

    def frame_of_point(self, point: str) -> str:
        """The frame whose origin a capsule's end names (base, a joint, end_effector)."""
        if point == "base":
            return self.base_frame
        if point == "end_effector":
            return self.end_effector_frame
        return self.joint_frame(point)

    @property
    def frames(self) -> list[str]:
        """Every frame of the chain, root first: base, the joints, the end-effector."""
        return [self.base_frame, *map(self.joint_frame, self.joints), self.end_effector_frame]


def arm_namespace(arm: ArmDescription) -> str:
    """The arm's ROS namespace: its file's stem (arms/lwa3.yaml -> lwa3), else its name."""
    source = getattr(arm, "source_file", "") or ""
    return ros_name(Path(source).stem if source else arm.name)
