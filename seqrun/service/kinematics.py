"""The arm's kinematics as the faces ask for it: where the end effector of a reading is.

``seqrun status``, the session's status and a run's status over its control socket all
show the end-effector pose of the measured joints; they ask here (the pure maths is
:mod:`seqrun.arm.kinematics`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription

__all__ = ["end_effector"]


def end_effector(arm: ArmDescription, joints_deg: Sequence[float]) -> dict[str, list[float]]:
    """``{"position_mm": [x, y, z], "rpy_deg": [roll, pitch, yaw]}`` (rounded to 1 µm and
    0.001°) of the end effector with every joint at ``joints_deg`` (user degrees)."""
    import numpy as np

    from seqrun.arm.kinematics import Chain, fk, rpy_from_matrix

    frame = fk(Chain.from_arm(arm), np.radians(np.asarray(joints_deg, dtype=float)))
    return {"position_mm": [round(float(x), 3) for x in frame[:3, 3]],
            "rpy_deg": [round(float(x), 3)
                        for x in np.degrees(rpy_from_matrix(frame[:3, :3]))]}
