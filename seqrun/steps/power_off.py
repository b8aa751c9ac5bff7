"""power_off: check the arm stands in a power-off pose, then record the zero reference.

The modules take the position they are switched off in as their encoder zero, so the
next power-on needs to know where that was (:mod:`seqrun.zero`). Nothing is sent to the
modules: the step measures, compares and records. The record is written through
``ex.record_zero(pose)`` (set by whoever runs the sequence); a dry run records nothing.
"""

from __future__ import annotations

from seqrun.errors import RunAborted


def run(step, ex) -> dict:
    pose = step.params.pose
    target = ex.arm.power_off_joints_deg(pose)  # user degrees: every module reads 0 there
    tolerance = step.params.tolerance_deg or ex.arm.control.position_tolerance_deg
    measured = ex.monitor()
    away = {j.name: float(measured.user_deg[i]) - target[j.name]
            for i, j in enumerate(ex.arm.joints) if j.locked is None}
    off = {name: d for name, d in away.items() if abs(d) > tolerance}
    detail = {"pose": pose, "tolerance_deg": tolerance,
              "deviation_deg": {n: round(d, 4) for n, d in away.items()}}
    if off:
        worst = ", ".join(f"{n} {d:+.2f}°" for n, d in off.items())
        raise RunAborted("power_off", f"power_off: the arm is not in {pose} ({worst} away; "
                                      f"tolerance {tolerance:g}°): nothing recorded",
                         detail=detail)
    recorder = getattr(ex, "record_zero", None)
    if ex.dry_run or recorder is None:
        ex.not_verified.append(f"step {step.number}: the zero reference '{pose}' is not "
                               "recorded (a dry run, or the built-in simulator, whose zero "
                               "is its power-on pose)")
        return {**detail, "recorded": None}
    record = recorder(pose)
    ex.emit("zero_recorded", pose=pose, text=str(record))
    return {**detail, "recorded": str(record)}
