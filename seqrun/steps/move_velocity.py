"""move_velocity: joints at given velocities for a given time, inside a position envelope.

The thesis GUI's velocity mode (FVEL), made safe the way Schunk's own ROS driver does it:
never open-ended. Each joint ramps to its velocity, holds it for ``duration_s`` and brakes
to rest (:class:`seqrun.arm.velocity.VelocityPlan`), so where it stops is known before
anything moves. The file must say where the joints may go (``envelope_deg``); validation
refuses a move whose stop lies outside it (a wrong sign, too long a duration), and every
cycle of the run checks that the measured position plus the stopping distance at the
measured velocity stays inside the envelope and the joint's limits (else Halt). The driver
arms the modules' watchdog before the first FVEL: if seqrun stops talking, the joints stop
by themselves within the watchdog's timeout (docs/sequence-format.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from pydantic import Field, model_validator
from pydantic_core import PydanticCustomError

from seqrun.steps.kind import StepKind
from seqrun.steps.params import (Finite, HazardKey, JointName, LimitPair, Positive, Scale,
                                 StepParams, one_key_value)

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.arm.velocity import VelocityPlan
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep

__all__ = ["MoveVelocityParams", "plan_velocity_move"]


class MoveVelocityParams(StepParams):
    """Move joints at constant velocities (FVEL) for a fixed time, then stop: each joint
    ramps to its velocity, holds it until duration_s after the start and brakes to rest.
    Never open-ended: duration_s and the position envelope of every moving joint are
    required; validation refuses a move whose stop leaves the envelope, and the run halts
    the arm if a joint (with its stopping distance) would leave it."""

    kind: ClassVar[str] = "move_velocity"
    yaml_name: ClassVar[str] = "move_velocity"
    velocity_deg_s: dict[JointName, Finite] = Field(
        ..., min_length=1,
        description="Per-joint velocity in deg/s, signed, e.g. {j1: 5, j4: -2}; at most the "
                    "arm's maximum. Joints not named do not move.")
    duration_s: Positive = Field(
        ..., description="Seconds the velocities are held from the start (required: a "
                         "velocity move never runs without one); the joints then brake to "
                         "rest.")
    envelope_deg: dict[JointName, LimitPair] = Field(
        ..., min_length=1,
        description="Per moving joint the [min, max] it must stay within, in user degrees "
                    "(required for every joint in velocity_deg_s; inside the limits in "
                    "force). The stop, and every cycle's position plus stopping distance, "
                    "must lie inside.")
    acceleration_scale: Scale = Field(
        1.0, description="Fraction [0.01, 1] of the arm's acceleration limits used to reach "
                         "and leave the velocities (and to brake).")
    tolerance_deg: Positive | None = Field(
        None, description="In-position tolerance at the stop in degrees (default: the arm "
                          "file's control.position_tolerance_deg).")
    hazard: HazardKey = None

    @model_validator(mode="after")
    def _envelope(self) -> MoveVelocityParams:
        missing = [n for n in self.velocity_deg_s if n not in self.envelope_deg]
        if missing:
            raise PydanticCustomError(
                "velocity_envelope", "envelope_deg has no [min, max] for {joints}: every "
                "joint of velocity_deg_s needs one", {"joints": ", ".join(missing)})
        inverted = [f"{n}: min {lo:g} is not below max {hi:g}"
                    for n, (lo, hi) in self.envelope_deg.items() if not lo < hi]
        if inverted:
            raise PydanticCustomError("velocity_envelope", "envelope_deg {bad}",
                                      {"bad": "; ".join(inverted)})
        return self


def describe(params: MoveVelocityParams) -> str:
    joints = ", ".join(f"{j} {v:+g}°/s" for j, v in params.velocity_deg_s.items())
    return f"move {joints} for {params.duration_s:g} s"


def plan_velocity_move(arm: ArmDescription, start_deg: Any, params: MoveVelocityParams, *,
                       speed: float = 1.0,
                       max_acceleration_deg_s2: dict[str, float] | None = None
                       ) -> VelocityPlan:
    """The plan of a velocity move from ``start_deg`` (user degrees, every joint): the
    velocities times the run's speed override, ramps at the arm's acceleration (narrowed
    by the limits in force) times ``acceleration_scale``."""
    import numpy as np

    from seqrun.arm.planner import Limits
    from seqrun.arm.velocity import VelocityPlan

    limits = Limits.from_arm(arm, acceleration_scale=params.acceleration_scale, speed=speed,
                             max_acceleration_deg_s2=max_acceleration_deg_s2)
    velocity = np.zeros(arm.dof)
    for name, value in params.velocity_deg_s.items():
        if arm.joint(name).locked is None:
            velocity[arm.index(name)] = np.radians(value) * speed
    return VelocityPlan.plan(np.radians(np.asarray(start_deg, dtype=float)), velocity,
                             limits.acceleration, params.duration_s)


def bounds(arm: ArmDescription, params: MoveVelocityParams, name: str,
           limits: tuple[float, float] | None = None) -> tuple[float, float]:
    """Where ``name`` may be: its envelope within its limits (``limits``: those in force)."""
    lo, hi = params.envelope_deg[name]
    alo, ahi = limits if limits is not None else arm.joint(name).limits_deg
    return max(lo, alo), min(hi, ahi)


# --------------------------------------------------------------------------- static checks
def check(checker: CheckContext, step: ResolvedStep[MoveVelocityParams],
          params: MoveVelocityParams) -> None:
    import numpy as np

    from seqrun.arm.velocity import stop_position
    from seqrun.formatting import format_number as f, format_range

    joints = checker.joints
    names = checker.names(step, params.velocity_deg_s, ("velocity_deg_s",), as_keys=True,
                          what="moving")
    checker.names(step, params.envelope_deg, ("envelope_deg",), as_keys=True,
                  what="an envelope for")
    if params.duration_s > checker.arm.control.max_wait_s:
        checker.errors.append(step.error(
            f"duration_s {f(params.duration_s)} s is longer than the arm file allows "
            f"(control.max_wait_s = {f(checker.arm.control.max_wait_s)} s)", "duration_s"))
    if not names:
        return
    if not checker.incomplete:
        checker.motion_allowed(step, names)
    if checker.powered_off is not None:
        checker.errors.append(step.error(
            f"move_velocity after power_off (at {checker.powered_off.location}): nothing may "
            "move after it"))
    bad = False
    for name in names:
        value = params.velocity_deg_s[name]
        bound = checker.file_limits.velocity(name)
        if abs(value) > bound.value:
            bad = True
            checker.errors.append(step.error(
                f"velocity_deg_s of {name} {f(value)} deg/s is above its maximum "
                f"{f(bound.value)} deg/s (from {bound.source})", "velocity_deg_s", name))
        state = joints[name]
        lo, hi = params.envelope_deg[name]
        llo, lhi = state.limits or state.joint.limits_deg
        if lo < llo or hi > lhi:
            bad = True
            checker.errors.append(step.error(
                f"envelope_deg of {name} {format_range(lo, hi)} goes beyond the limits in "
                f"force {format_range(llo, lhi)}", "envelope_deg", name))
    if bad or checker.position_unknown or checker.lost_at is not None:
        return  # where the joints start (or may go) is not known well enough to say more
    _, acceleration = checker.limits.maxima()
    start = checker.tracked()
    plan = plan_velocity_move(checker.arm, start, params, speed=checker.speed,
                              max_acceleration_deg_s2=acceleration)
    tolerance = params.tolerance_deg or checker.arm.control.position_tolerance_deg
    end = np.degrees(plan.target)
    refused = False
    for name in names:
        i = checker.arm.index(name)
        lo, hi = params.envelope_deg[name]
        if not lo <= start[i] <= hi:
            refused = True
            checker.errors.append(step.error(
                f"{name} starts at {f(start[i])}°, outside its envelope "
                f"{format_range(lo, hi)}", "envelope_deg", name))
            continue
        # The braking distance at full speed (the plan's own), for the message.
        peak = float(np.degrees(plan.profiles[i].velocity))
        accel = abs(float(np.degrees(plan.profiles[i].acceleration))) or 1.0
        if not lo + tolerance <= end[i] <= hi - tolerance:
            refused = True
            moved = end[i] - start[i]
            checker.errors.append(step.error(
                f"{name} at {f(params.velocity_deg_s[name])} deg/s for "
                f"{f(params.duration_s)} s comes to rest at {f(end[i])}° "
                f"({f(start[i])}° {'+' if moved >= 0 else '-'} {f(abs(moved))}°, braking "
                f"from {f(abs(peak))} deg/s takes "
                f"{f(abs(stop_position(0.0, peak, accel)))}°), outside its envelope "
                f"{format_range(lo, hi)} (margin {f(tolerance)}°): check the sign and the "
                "duration", "velocity_deg_s", name))
    if refused:
        return
    times = np.linspace(0.0, plan.duration, max(2, int(plan.duration * 20) + 1))
    checker.check_path_guards(step, times, plan.sample(times), what="the velocity move")
    for name in names:
        state = joints[name]
        value = float(end[checker.arm.index(name)])
        if value != state.position:
            state.at_start = False
        state.position = value


# --------------------------------------------------------------------------- run
def run(step: ResolvedStep[MoveVelocityParams], ex: StepContext) -> dict:
    import numpy as np

    from seqrun.arm.velocity import stop_position
    from seqrun.errors import RunAborted
    from seqrun.formatting import format_range

    params = step.params
    arm = ex.arm
    start = ex.read_arm()
    _, acceleration = ex.limits_in_force.maxima()
    plan = plan_velocity_move(arm, start.user_deg, params, speed=ex.speed,
                              max_acceleration_deg_s2=acceleration)
    watched = {arm.index(n): bounds(arm, params, n)
               for n in params.velocity_deg_s if arm.joint(n).locked is None}
    end = np.degrees(plan.target)
    # From the measured start (the arm may stand elsewhere than validation assumed).
    for i, (lo, hi) in watched.items():
        name = arm.joints[i].name
        if not lo <= start.user_deg[i] <= hi or not lo <= end[i] <= hi:
            where = (f"starts at {start.user_deg[i]:.2f}°" if not lo <= start.user_deg[i] <= hi
                     else f"would come to rest at {end[i]:.2f}°")
            raise RunAborted("envelope", f"{name} {where}, outside its envelope "
                             f"{format_range(lo, hi)}; nothing was moved")
    braking = np.degrees(np.abs([p.acceleration for p in plan.profiles]))
    last: list[Any] = [start]

    def inside_envelope(m: Any) -> None:
        """Every cycle: the measured position plus the stopping distance at the measured
        velocity inside the envelope and the limits."""
        before = last[0]
        last[0] = m
        dt = m.t - before.t
        for i, (lo, hi) in watched.items():
            velocity = (m.user_deg[i] - before.user_deg[i]) / dt if dt > 0 else 0.0
            stop = stop_position(float(m.user_deg[i]), float(velocity), float(braking[i]))
            if not lo <= stop <= hi:
                name = arm.joints[i].name
                raise RunAborted("envelope",
                                 f"{name} at {m.user_deg[i]:.2f}° moving {velocity:+.2f} deg/s "
                                 f"would stop at {stop:.2f}°, outside its envelope "
                                 f"{format_range(lo, hi)}", module=arm.joints[i].module)

    ex.emit("velocity_move_planned", duration_s=round(plan.duration, 4),
            velocity_deg_s={arm.joints[i].name: round(float(np.degrees(plan.profiles[i].velocity)), 4)
                            for i in plan.active},
            envelope_deg={arm.joints[i].name: list(b) for i, b in watched.items()})
    tolerance = params.tolerance_deg or arm.control.position_tolerance_deg
    detail = ex.follow(plan, tolerance_deg=tolerance, timeout_s=None,
                       path_check=inside_envelope, command_mode="velocity", start=start)
    return {**detail, "command_mode": "velocity",
            "stop_deg": [round(float(x), 4) for x in end]}


KIND = StepKind(
    name="move_velocity", params=MoveVelocityParams, describe=describe, check=check, run=run,
    value=one_key_value("move_velocity", MoveVelocityParams),
    example="move_velocity: {velocity_deg_s: {j1: 5}, duration_s: 2, envelope_deg: "
            "{j1: [-10, 20]}}", motion=True)
