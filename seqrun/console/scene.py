"""What the page's 3D view needs from the arm description: the chain as 4x4 frames.

The page multiplies these frames with Rz(q) per joint (the reference convention, see
:mod:`seqrun.arm.kinematics`), so it never interprets roll/pitch/yaw itself: the frames are
computed here by the same code the validator uses (``Chain.from_arm``).
"""

from __future__ import annotations

from typing import Any

from seqrun.arm.description import ArmDescription


def _rows(matrix: Any) -> list[list[float]]:
    return [[round(float(v), 9) for v in row] for row in matrix]


def arm_scene(arm: ArmDescription) -> dict[str, Any]:
    """The joints (limits, locked value), the chain's frames, guards, link volumes, obstacles."""
    from seqrun.arm.kinematics import Chain

    chain = Chain.from_arm(arm)
    return {
        "name": arm.name,
        "joints": [{"name": j.name, "module": j.module, "limits_deg": list(j.limits_deg),
                    "locked": j.locked, "max_velocity_deg_s": j.max_velocity_deg_s}
                   for j in arm.joints],
        "chain": {"base": _rows(chain.base), "links": [_rows(m) for m in chain.links],
                  "tool": _rows(chain.tool)},
        "guards": [{"name": g.name, "min_z_mm": g.min_z_mm, "points": list(g.points)}
                   for g in arm.workspace.guards],
        "capsules": [{"name": c.name, "start": c.start, "end": c.end,
                      "radius_mm": c.radius_mm} for c in arm.geometry.capsules],
        "obstacles": [o.model_dump(mode="json", exclude_none=True)
                      for o in arm.geometry.obstacles],
    }
