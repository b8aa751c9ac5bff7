"""User degrees <-> PowerCube module radians: the one place the arm's offsets apply.

A PRL module counts its position from where it was powered on; the arm file (with the
zero reference in force, :mod:`seqrun.service.zero`) says per joint how far that is from
the user's zero (Totem = zeros): ``module_rad = radians(user_deg + offset_deg)``. Rates
(deg/s, deg/s²) have no offset. Above the driver everything is user degrees; below it
(requests, acknowledges, the simulator's encoders) module radians.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from seqrun.arm.description import ArmDescription, Joint


def to_module_rad(joint: Joint, user_deg: float) -> float:
    """One joint: user degrees -> module radians."""
    return math.radians(user_deg + joint.offset_deg)


def to_user_deg(joint: Joint, module_rad: float) -> float:
    """One joint: module radians -> user degrees."""
    return math.degrees(module_rad) - joint.offset_deg


class ModuleUnits:
    """The conversions of one arm (with its zero reference) in joint order, or for one
    joint by its module id."""

    def __init__(self, arm: ArmDescription) -> None:
        self.offsets_deg = np.array([j.offset_deg for j in arm.joints])
        self._offsets_rad = np.radians(self.offsets_deg)
        self._joint = {j.module: j for j in arm.joints}

    # -- every joint, joint order
    def user_deg(self, module_rad: np.ndarray) -> np.ndarray:
        """Module radians -> user degrees."""
        return np.degrees(np.asarray(module_rad)) - self.offsets_deg

    def module_rad(self, user_deg: np.ndarray) -> np.ndarray:
        """User degrees -> module radians."""
        return np.radians(np.asarray(user_deg) + self.offsets_deg)

    def module_rad_of_user_rad(self, user_rad: np.ndarray) -> np.ndarray:
        """User radians (a plan's) -> module radians."""
        return np.asarray(user_rad) + self._offsets_rad

    # -- one joint, by module id
    def joint_user_deg(self, module: int, module_rad: float) -> float:
        return to_user_deg(self._joint[module], module_rad)

    def joint_module_rad(self, module: int, user_deg: float) -> float:
        return to_module_rad(self._joint[module], user_deg)


def module_positions(arm: ArmDescription, joints_deg: Mapping[str, float]) -> dict[int, float]:
    """What the modules' encoders read (module radians, by module id) while the arm stands
    at ``joints_deg`` (user degrees, every joint): a simulated arm's start. A joint
    declared absent has no module, so no entry."""
    return {j.module: to_module_rad(j, joints_deg[j.name]) for j in arm.joints if j.present}
