"""set_limits: write MinPos/MaxPos (and MaxVel/MaxAcc where given), then read them back."""

from __future__ import annotations

import math

from seqrun.errors import RunAborted
from seqrun.powercube.codec import GetParam, SetParam
from seqrun.powercube.protocol import ParamId

#: float32 on the wire: a read-back equal within this is the value written.
READBACK_TOLERANCE_RAD = 1e-6


def run(step, ex) -> dict:
    params = step.params
    writes: list[tuple[int, ParamId, float]] = []
    for joint in ex.arm.joints:
        lo, hi = params.limits_deg.get(joint.name, joint.limits_deg)
        writes.append((joint.module, ParamId.MIN_POS, joint.to_module_rad(lo)))
        writes.append((joint.module, ParamId.MAX_POS, joint.to_module_rad(hi)))
        if joint.name in params.max_velocity_deg_s:
            writes.append((joint.module, ParamId.MAX_VEL,
                           math.radians(params.max_velocity_deg_s[joint.name])))
        if joint.name in params.max_acceleration_deg_s2:
            writes.append((joint.module, ParamId.MAX_ACC,
                           math.radians(params.max_acceleration_deg_s2[joint.name])))
    ex.transact([SetParam(m, p, v) for m, p, v in writes])
    acks = ex.transact([GetParam(m, p) for m, p, _ in writes], idempotent=True)
    for (module, param, value), ack in zip(writes, acks):
        if abs(float(ack.value) - value) > READBACK_TOLERANCE_RAD:
            raise RunAborted("limits_not_written",
                             f"module {module}: {param.name} reads back {ack.value:.6f} rad, "
                             f"wrote {value:.6f} rad", module=module)
    # From now on the modules hold these: later moves are planned within them.
    ex.limits_in_force.written(f"set_limits at {step.location}",
                               {n: v for n, v in params.max_velocity_deg_s.items()
                                if ex.arm.joint(n).locked is None},
                               {n: v for n, v in params.max_acceleration_deg_s2.items()
                                if ex.arm.joint(n).locked is None})
    return {"written": len(writes)}
