"""set_limits: write MinPos/MaxPos and MaxCur (and MaxVel/MaxAcc where given), then read
them back."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from pydantic import Field, model_validator

from seqrun.steps.kind import StepKind
from seqrun.steps.params import JointName, LimitPair, Positive, StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep



class SetLimitsParams(StepParams):
    """Write the position limits (MinPos/MaxPos) and the current limit (MaxCur, where the
    arm file gives one) into every joint's module, and the velocity and acceleration limits
    (MaxVel/MaxAcc) of the joints named here. Values default to the arm file's; overrides
    may only narrow them."""

    kind: ClassVar[str] = "set_limits"
    yaml_name: ClassVar[str] = "set_limits"
    limits_deg: dict[JointName, LimitPair] = Field(
        default_factory=dict,
        description="Per-joint [min, max] in user degrees, e.g. {j1: [-170, 170]}; inside the "
                    "arm file's limits. Joints not named get the arm file's limits.")
    max_velocity_deg_s: dict[JointName, Positive] = Field(
        default_factory=dict,
        description="Per-joint MaxVel in deg/s, at most the arm file's maximum; written only "
                    "for the joints named.")
    max_acceleration_deg_s2: dict[JointName, Positive] = Field(
        default_factory=dict,
        description="Per-joint MaxAcc in deg/s^2, at most the arm file's maximum; written "
                    "only for the joints named.")
    max_current_a: dict[JointName, Positive] = Field(
        default_factory=dict,
        description="Per-joint MaxCur in A, at most the arm file's max_current_a (which the "
                    "joints not named get, where it is given).")

    @model_validator(mode="after")
    def _ordered(self) -> SetLimitsParams:
        bad = [f"{name}: min {lo:g} is not below max {hi:g}"
               for name, (lo, hi) in self.limits_deg.items() if not lo < hi]
        if bad:
            raise ValueError("limits_deg " + "; ".join(bad))
        return self

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls()


def describe(params: SetLimitsParams) -> str:
    return "write joint limits"


def check(checker: CheckContext,
          step: ResolvedStep[SetLimitsParams], params: SetLimitsParams) -> None:
    from seqrun.formatting import format_number as f, format_range

    joints = checker.joints
    unlocked = [s for s in joints.values() if not s.locked]
    not_reset = [s.joint.name for s in unlocked if not s.reset]
    if not_reset and not checker.incomplete:
        checker.errors.append(step.error(
            f"set_limits before reset{checker.which(not_reset)}: the modules accept "
            "parameters only after Reset"))
    for name in checker.names(step, params.limits_deg, ("limits_deg",), as_keys=True,
                              what="writing limits to"):
        lo, hi = params.limits_deg[name]
        alo, ahi = joints[name].joint.limits_deg
        if lo < alo or hi > ahi:
            checker.errors.append(step.error(
                f"limits_deg of {name} {format_range(lo, hi)} go beyond the arm's limits "
                f"{format_range(alo, ahi)}; an override may only narrow them",
                "limits_deg", name))
    for key, attr in (("max_velocity_deg_s", "max_velocity_deg_s"),
                      ("max_acceleration_deg_s2", "max_acceleration_deg_s2")):
        values = getattr(params, key)
        for name in checker.names(step, values, (key,), as_keys=True,
                                  what="writing limits to"):
            maximum = getattr(joints[name].joint, attr)
            if values[name] > maximum:
                unit = "deg/s" if key.endswith("_s") else "deg/s^2"
                checker.errors.append(step.error(
                    f"{key} of {name} {f(values[name])} {unit} is above the arm's "
                    f"maximum {f(maximum)} {unit}", key, name))
    for name in checker.names(step, params.max_current_a, ("max_current_a",), as_keys=True,
                              what="writing limits to"):
        maximum = joints[name].joint.max_current_a
        if maximum is None:
            checker.errors.append(step.error(
                f"max_current_a of {name}: the arm file gives no max_current_a for {name} "
                "(add it there first: a step may only lower it)", "max_current_a", name))
        elif params.max_current_a[name] > maximum:
            checker.errors.append(step.error(
                f"max_current_a of {name} {f(params.max_current_a[name])} A is above the "
                f"arm's maximum {f(maximum)} A", "max_current_a", name))
    for state in unlocked:
        name = state.joint.name
        override = params.limits_deg.get(name)
        state.limits = (tuple(override) if override is not None  # type: ignore[assignment]
                        else tuple(state.joint.limits_deg))
    written = {key: {n: v for n, v in getattr(params, key).items()
                     if n in joints and not joints[n].locked}
               for key in ("max_velocity_deg_s", "max_acceleration_deg_s2")}
    for limits in (checker.file_limits, checker.limits):
        limits.written(f"set_limits at {step.location}", written["max_velocity_deg_s"],
                       written["max_acceleration_deg_s2"])


def run(step: ResolvedStep[SetLimitsParams], ex: StepContext) -> dict:
    from seqrun.arm.joint_values import LimitValues

    params = step.params
    values = {}
    for joint in ex.arm.joints:
        lo, hi = params.limits_deg.get(joint.name, joint.limits_deg)
        values[joint.name] = LimitValues(lo, hi,
                                         params.max_velocity_deg_s.get(joint.name),
                                         params.max_acceleration_deg_s2.get(joint.name),
                                         params.max_current_a.get(joint.name,
                                                                  joint.max_current_a))
    # The driver reads every value back: one that differs is a fault (limits_not_written).
    written = ex.write_limits(values)
    # From now on the modules hold these: later moves are planned within them.
    ex.limits_in_force.written(f"set_limits at {step.location}",
                               {n: v for n, v in params.max_velocity_deg_s.items()
                                if ex.arm.joint(n).locked is None},
                               {n: v for n, v in params.max_acceleration_deg_s2.items()
                                if ex.arm.joint(n).locked is None})
    return {"written": written}


KIND = StepKind(
    name="set_limits", params=SetLimitsParams, describe=describe, check=check, run=run,
    value=one_key_value("set_limits", SetLimitsParams, none="default"),
    shorthand=" Shorthand: '- set_limits' (the arm file's values).", bare=True)
