"""set_limits: write MinPos/MaxPos (and MaxVel/MaxAcc where given), then read them back."""

from __future__ import annotations

from seqrun.drivers.base import LimitValues


def run(step, ex) -> dict:
    params = step.params
    values = {}
    for joint in ex.arm.joints:
        lo, hi = params.limits_deg.get(joint.name, joint.limits_deg)
        values[joint.name] = LimitValues(lo, hi,
                                         params.max_velocity_deg_s.get(joint.name),
                                         params.max_acceleration_deg_s2.get(joint.name))
    # The driver reads every value back: one that differs is a fault (limits_not_written).
    written = ex.write_limits(values)
    # From now on the modules hold these: later moves are planned within them.
    ex.limits_in_force.written(f"set_limits at {step.location}",
                               {n: v for n, v in params.max_velocity_deg_s.items()
                                if ex.arm.joint(n).locked is None},
                               {n: v for n, v in params.max_acceleration_deg_s2.items()
                                if ex.arm.joint(n).locked is None})
    return {"written": written}
