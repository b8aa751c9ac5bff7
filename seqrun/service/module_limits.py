"""The limits the modules hold beside the arm file's: ``seqrun limits show`` and ``set``.

MinPos/MaxPos (user degrees, through the joint's offset), MaxVel, MaxAcc (deg/s, deg/s^2)
and MaxCur (A) of every joint, read from its module by the arm's driver, each beside the
arm file's value and marked where the two differ (a drive stores float32: equal within
its rounding counts as equal). An arm file that gives no max_current_a for a joint has
nothing to compare its MaxCur with: shown, never marked. ``set`` writes the arm file's
values and the driver reads each one back (a value that reads back different is a fault).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription, Joint
    from seqrun.arm.joint_values import JointLimits
    from seqrun.drivers.base import ArmDriver

__all__ = ["LIMIT_FIELDS", "LimitRow", "compare_limits", "read_module_limits",
           "write_arm_limits"]

#: (key, heading, unit, tolerance): the five limits, in the order shown. Tolerances are
#: the float32 rounding of the value a drive stores (1e-5 rad, 1e-5 A).
LIMIT_FIELDS: tuple[tuple[str, str, str, float], ...] = (
    ("min_deg", "MinPos", "°", math.degrees(1e-5)),
    ("max_deg", "MaxPos", "°", math.degrees(1e-5)),
    ("max_velocity_deg_s", "MaxVel", "°/s", math.degrees(1e-5)),
    ("max_acceleration_deg_s2", "MaxAcc", "°/s²", math.degrees(1e-5)),
    ("max_current_a", "MaxCur", "A", 1e-5),
)


def _arm_values(joint: Joint) -> dict[str, float | None]:
    return {"min_deg": joint.limits_deg[0], "max_deg": joint.limits_deg[1],
            "max_velocity_deg_s": joint.max_velocity_deg_s,
            "max_acceleration_deg_s2": joint.max_acceleration_deg_s2,
            "max_current_a": joint.max_current_a}


@dataclass(frozen=True)
class LimitRow:
    """One joint: each limit as the module holds it and as the arm file says."""

    joint: str
    module: int
    held: dict[str, float | None]
    arm: dict[str, float | None]

    def differs(self, key: str) -> bool:
        tolerance = next(t for k, _, _, t in LIMIT_FIELDS if k == key)
        held, arm = self.held[key], self.arm[key]
        return held is not None and arm is not None and abs(held - arm) > tolerance

    @property
    def differences(self) -> list[str]:
        return [key for key, *_ in LIMIT_FIELDS if self.differs(key)]

    def as_dict(self) -> dict[str, Any]:
        return {"joint": self.joint, "module": self.module,
                "limits": {key: {"module": _rounded(self.held[key]),
                                 "arm_file": _rounded(self.arm[key]),
                                 "differs": self.differs(key)}
                           for key, *_ in LIMIT_FIELDS}}


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(value, 4) + 0.0


def compare_limits(arm: ArmDescription, held: Sequence[JointLimits]) -> list[LimitRow]:
    """The rows of ``limits show``: every joint's held limits beside the arm file's (a
    joint declared absent: none held)."""
    return [LimitRow(joint.name, joint.module,
                     {key: getattr(limits, key) if joint.present else None
                      for key, *_ in LIMIT_FIELDS},   # an absent joint has no module
                     _arm_values(joint))
            for joint, limits in zip(arm.joints, held)]


def read_module_limits(driver: ArmDriver, arm: ArmDescription) -> list[LimitRow]:
    """Read every module's limits (reads only, nothing moves) beside the arm file's."""
    return compare_limits(arm, driver.read_limits())


def write_arm_limits(driver: ArmDriver, arm: ArmDescription,
                     joints: Sequence[str] | None = None) -> int:
    """Write the arm file's limits into the modules of ``joints`` (None: every joint):
    MinPos/MaxPos, MaxVel, MaxAcc, and MaxCur where the arm file gives it. The driver
    reads every value back; one that differs raises
    :class:`~seqrun.errors.RunAborted` (``limits_not_written``). Returns the number of
    values written."""
    from seqrun.arm.joint_values import LimitValues

    names = arm.joint_names if joints is None else list(joints)
    values = {}
    for joint in arm.joints:
        if joint.name in names:
            values[joint.name] = LimitValues(joint.limits_deg[0], joint.limits_deg[1],
                                             joint.max_velocity_deg_s,
                                             joint.max_acceleration_deg_s2,
                                             joint.max_current_a)
    return driver.write_limits(values)
