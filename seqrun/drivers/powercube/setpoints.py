"""Setpoint laws: how a ruckig plan becomes PowerCube motion requests, cycle by cycle.

Pure: a law turns (plan, plan time, measured joints) into request objects in module units
(:mod:`.units`); the driver sends them. One class per command mode of the arm file
(``control.command_mode``):

- :class:`RampSetpoints` ("ramp", the facility's way): TargetVel + FRAMP_ACK. The position
  sent lies far enough ahead on the plan that the module's own braking curve never binds
  before the plan decelerates, and TargetVel follows the plan's velocity plus a catch-up
  term for the measured lag. The module's trapezoid interpolates between cycles, so the
  arm keeps moving smoothly through a late cycle.
- :class:`StepSetpoints` ("step"): FSTEP_ACK to the plan's position one cycle ahead, reached
  by linear interpolation in exactly one cycle.
- :class:`VelocitySetpoints` ("velocity", never a run's mode: a velocity move or a jog in
  velocity mode asks for it per motion): FVEL_ACK with the plan's velocity.

Both ask for extended acknowledges, which report every commanded module's position and
short state: monitoring costs no extra frames.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from seqrun.arm.description import ArmDescription
from seqrun.arm.planner import Limits, MovePlan
from seqrun.drivers.powercube.units import ModuleUnits
from seqrun.powercube.codec import Request, SetMotion, SetParam
from seqrun.powercube.protocol import MotionMode, ParamId


#: Enum members as module constants (looked up for every joint of every cycle).
_TARGET_VEL, _FRAMP_ACK = ParamId.TARGET_VEL, MotionMode.FRAMP_ACK


class SetpointLaw(Protocol):
    def start(self, moving: list[int], limits: Limits) -> list[Request]:
        """Requests sent once when a move (or a stop) starts."""

    def cycle(self, plan: MovePlan, t: float, moving: list[int],
              measured_deg: np.ndarray) -> list[Request]:
        """Motion requests for plan time ``t`` given the measured joints (user deg)."""

    #: After :meth:`cycle`: where each joint comes to rest if no request follows (user
    #: rad, joint order; NaN: not commanded), None: nowhere in particular (velocity).
    holds_at_rad: np.ndarray | None


class _Law:
    def __init__(self, arm: ArmDescription, cycle_s: float, run_limits: Limits) -> None:
        self.arm = arm
        self.cycle_s = cycle_s
        self.run_limits = run_limits          # arm x speed override: sets the lookahead
        self.modules = arm.module_ids
        self.module_rad = ModuleUnits(arm).module_rad_of_user_rad
        self.holds_at_rad: np.ndarray | None = None

    def _holding(self, moving: list[int], user_rad: np.ndarray) -> None:
        """The moving joints stop at ``user_rad`` (a position command's target)."""
        holds = np.full(len(self.modules), np.nan)
        holds[moving] = user_rad[moving]
        self.holds_at_rad = holds


class StepSetpoints(_Law):
    """FSTEP_ACK to where the plan will be one cycle from now."""

    def start(self, moving: list[int], limits: Limits) -> list[Request]:
        return []

    def cycle(self, plan: MovePlan, t: float, moving: list[int],
              measured_deg: np.ndarray) -> list[Request]:
        user = plan.at(t + self.cycle_s)[0]
        self._holding(moving, user)
        target = self.module_rad(user)
        ms = max(1, int(round(self.cycle_s * 1000)))
        return [SetMotion(self.modules[i], MotionMode.FSTEP_ACK, float(target[i]), ms)
                for i in moving]


class RampSetpoints(_Law):
    """TargetVel + FRAMP_ACK with lookahead and a bounded catch-up (module docstring)."""

    #: Proportional gain (1/s) of the velocity cap that pulls a lagging joint onto its plan.
    CATCH_UP_GAIN = 10.0
    #: Smallest TargetVel sent (deg/s): a zero cap would leave a joint short of its target.
    MIN_COMMAND_VELOCITY_DEG_S = 1.0
    #: TargetVel resolution (deg/s); a write that would not change it is not sent.
    TARGET_VEL_QUANTUM_DEG_S = 0.1

    def __init__(self, arm: ArmDescription, cycle_s: float, run_limits: Limits) -> None:
        super().__init__(arm, cycle_s, run_limits)
        self._sent_target_vel: dict[int, float] = {}
        self._move_limits = run_limits

    def start(self, moving: list[int], limits: Limits) -> list[Request]:
        # A module may have been reset or written meanwhile: TargetVel is sent afresh.
        self._sent_target_vel.clear()
        self._move_limits = limits
        # TargetAcc once per move: the module's own ramp must be able to follow the plan.
        factor = self.arm.control.module_acceleration_factor
        return [SetParam(self.modules[i], ParamId.TARGET_ACC,
                         float(limits.acceleration[i] * factor)) for i in moving]

    def cycle(self, plan: MovePlan, t: float, moving: list[int],
              measured_deg: np.ndarray) -> list[Request]:
        pos_now = plan.at(t)[0].tolist()
        vel_next = plan.at(t + self.cycle_s)[1].tolist()
        # Catch-up may use the reserve the plan left, never more than the move allows.
        ceiling = (np.degrees(self._move_limits.velocity)
                   / (1 - self.arm.control.tracking_reserve)).tolist()
        # A slow loop must correct gently or it overshoots its own correction.
        gain = min(self.CATCH_UP_GAIN, 0.5 / self.cycle_s)
        quantum = self.TARGET_VEL_QUANTUM_DEG_S
        requests: list[Request] = []
        # Joints with the same limits look equally far ahead: one plan sample serves them.
        aheads: dict[float, tuple[np.ndarray, np.ndarray]] = {}  # lead -> (user, module)
        holds = np.full(len(self.modules), np.nan)
        # Per joint on Python floats (.tolist()): the same IEEE double arithmetic as on
        # numpy's scalars, without a numpy call per operation.
        velocity, acceleration = (self.run_limits.velocity.tolist(),
                                  self.run_limits.acceleration.tolist())
        target, start = plan.target.tolist(), plan.start.tolist()
        measured = np.asarray(measured_deg).tolist()
        for i in moving:
            lead = velocity[i] / (2 * acceleration[i]) + 2 * self.cycle_s
            ahead = aheads.get(lead)
            if ahead is None:
                user = plan.at(t + lead)[0]
                ahead = aheads[lead] = (user, self.module_rad(user))
            direction = math.copysign(1.0, target[i] - start[i])
            lag = (math.degrees(pos_now[i]) - measured[i]) * direction
            cap = abs(math.degrees(vel_next[i])) + gain * lag
            # TargetVel only when it changes by more than the quantum: at cruise the
            # velocity is steady and the write would only load the bus.
            cap = round(cap / quantum) * quantum
            cap = min(max(cap, self.MIN_COMMAND_VELOCITY_DEG_S), ceiling[i],
                      self.arm.joints[i].max_velocity_deg_s)
            module = self.modules[i]
            if self._sent_target_vel.get(module) != cap:
                requests.append(SetParam(module, _TARGET_VEL, math.radians(cap)))
                self._sent_target_vel[module] = cap
            # FRAMP ends at its target: without another cycle the joint stops there
            holds[i] = ahead[0][i]
            requests.append(SetMotion(module, _FRAMP_ACK, float(ahead[1][i])))
        self.holds_at_rad = holds
        return requests


class VelocitySetpoints(_Law):
    """FVEL_ACK: the plan's velocity one cycle ahead plus a bounded pull towards its
    position (a velocity move, a jog in velocity mode).

    FVEL is open-ended on the module: it keeps the velocity until told otherwise. The
    driver arms the modules' watchdog before the first FVEL of a motion (see
    :meth:`PowerCubeDriver.start_motion`), so a host that goes silent stops the joints
    within the watchdog's timeout; and every cycle sends the velocity afresh, so the plan's
    end (velocity 0) is the stop.
    """

    #: Gain (1/s) of the position pull: a joint that lags its plan is sped up, one ahead
    #: is slowed, so the following error stays small.
    CATCH_UP_GAIN = 10.0

    def __init__(self, arm: ArmDescription, cycle_s: float, run_limits: Limits) -> None:
        super().__init__(arm, cycle_s, run_limits)
        self._commanded: list[int] = []

    def start(self, moving: list[int], limits: Limits) -> list[Request]:
        self._commanded = list(moving)
        # FVEL changes velocity at min(TargetAcc, MaxAcc): the module must be able to
        # follow the plan's ramps (as for FRAMP).
        factor = self.arm.control.module_acceleration_factor
        return [SetParam(self.modules[i], ParamId.TARGET_ACC,
                         float(limits.acceleration[i] * factor)) for i in moving]

    def cycle(self, plan: MovePlan, t: float, moving: list[int],
              measured_deg: np.ndarray) -> list[Request]:
        pos_now = plan.at(t)[0]
        vel_next = plan.at(t + self.cycle_s)[1]
        gain = min(self.CATCH_UP_GAIN, 0.5 / self.cycle_s)
        measured_rad = np.radians(np.asarray(measured_deg))
        requests: list[Request] = []
        for i in moving:
            ceiling = math.radians(self.arm.joints[i].max_velocity_deg_s)
            # Rates have no offset: user rad/s are module rad/s (units.py).
            velocity = float(vel_next[i]) + gain * float(pos_now[i] - measured_rad[i])
            velocity = min(max(velocity, -ceiling), ceiling)
            requests.append(SetMotion(self.modules[i], MotionMode.FVEL_ACK, velocity))
        return requests

    def finish(self) -> list[Request]:
        """When the motion ends (in position, stopped or failed): FVEL 0 to every joint it
        commanded. The last cycle's velocity held the position pull of a small residual
        error; left standing, FVEL would keep the joint creeping."""
        commanded, self._commanded = self._commanded, []
        return [SetMotion(self.modules[i], MotionMode.FVEL_ACK, 0.0) for i in commanded]


LAWS: dict[str, type[RampSetpoints] | type[StepSetpoints] | type[VelocitySetpoints]] = {
    "ramp": RampSetpoints, "step": StepSetpoints, "velocity": VelocitySetpoints}


def setpoint_law(mode: str, arm: ArmDescription, cycle_s: float,
                 run_limits: Limits) -> SetpointLaw:
    try:
        return LAWS[mode](arm, cycle_s, run_limits)
    except KeyError:
        raise ValueError(f"unknown command mode '{mode}' (ramp, step or velocity)") from None
