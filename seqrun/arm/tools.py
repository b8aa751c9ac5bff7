"""The volumes of the tools on the flange (pure numpy, no I/O).

A tool's volume is made of capsules given in the end-effector frame (``tools[].capsules``
of the arm file); a tool that gives none is its tip line, the segment from the end-effector
to its TCP with no thickness, so that a 400 mm probe can never be taken through the desk
unseen; ``capsules: []`` says the TCP is a point in the air (nothing to check). The link
volumes (:mod:`seqrun.arm.geometry`) carry these parts along with the links' capsules, and
the workspace guards that watch the end-effector watch them too (:meth:`ToolVolumes.lowest`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from seqrun.arm.description import ArmDescription

__all__ = ["ToolPart", "ToolVolumes"]


@dataclass(frozen=True)
class ToolPart:
    """One capsule of a tool, in the end-effector frame (radius 0: a tip line)."""

    label: str        # "tool probe", "tool gripper/finger"
    tool: str
    start_mm: tuple[float, float, float]
    end_mm: tuple[float, float, float]
    radius_mm: float

    def names(self) -> set[str]:
        """What an obstacle's ignore_links or an allowed pair may call it."""
        return {self.tool, self.label, self.label.removeprefix("tool ")}


def _xyz(values) -> tuple[float, float, float]:
    return float(values[0]), float(values[1]), float(values[2])


def tool_parts(arm: ArmDescription) -> list[ToolPart]:
    """Every tool's volume, in the order of the arm file."""
    parts: list[ToolPart] = []
    for tool in arm.tools:
        if tool.capsules is None:
            parts.append(ToolPart(f"tool {tool.name}", tool.name, (0.0, 0.0, 0.0),
                                  _xyz(tool.xyz_mm), 0.0))
            continue
        for capsule in tool.capsules:
            label = f"tool {tool.name}" + (f"/{capsule.name}" if capsule.name else "")
            parts.append(ToolPart(label, tool.name, _xyz(capsule.start_mm),
                                  _xyz(capsule.end_mm), float(capsule.radius_mm)))
    return parts


class ToolVolumes:
    """The tools' parts of an arm as points of the end-effector frame: ``points_mm``
    ``(2m, 3)`` holds each part's start and end in turn."""

    def __init__(self, arm: ArmDescription) -> None:
        self.parts = tool_parts(arm)
        self.points_mm = (np.array([p for part in self.parts
                                    for p in (part.start_mm, part.end_mm)], dtype=float)
                          .reshape(-1, 3))
        self.point_radii = np.repeat([part.radius_mm for part in self.parts], 2).astype(float)
        self._point_part = np.repeat(np.arange(len(self.parts)), 2)
        self._radii_list = self.point_radii.tolist()

    @property
    def empty(self) -> bool:
        return not self.parts

    def lowest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The lowest surface point of the tools, ``(..., 3)``, and which part it is on
        ``(...)``, from the parts' points in the base frame ``(..., 2m, 3)``. A capsule's
        lowest point lies a radius below its lower end."""
        z = points[..., 2] - self.point_radii
        k = np.argmin(z, axis=-1)
        lowest = np.take_along_axis(points, k[..., None, None], axis=-2)[..., 0, :].copy()
        lowest[..., 2] = np.take_along_axis(z, k[..., None], axis=-1)[..., 0]
        return lowest, self._point_part[k]

    def lowest_z(self, heights: list[float]) -> tuple[float, str]:
        """:meth:`lowest` of one configuration from the z of the parts' points (plain
        floats, for the run-time check every control cycle): height and part label."""
        best, best_k = float("inf"), 0
        for k, (z, r) in enumerate(zip(heights, self._radii_list)):
            if z - r < best:
                best, best_k = z - r, k
        return best, self.parts[best_k // 2].label
