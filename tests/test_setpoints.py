"""Setpoint laws (pure): what a plan becomes on the wire, cycle by cycle."""

import math

import numpy as np
import pytest

from projecttree import shipped_arm
from seqrun.arm.planner import Limits, plan_move
from seqrun.powercube.codec import SetMotion, SetParam
from seqrun.powercube.protocol import MotionMode, ParamId
from seqrun.drivers.powercube.setpoints import RampSetpoints, StepSetpoints, setpoint_law

ARM = shipped_arm()
RUN = Limits.from_arm(ARM)
PARK = np.radians([0, -90, 0, -120.32, 0, 115.74, 0])
TOTEM = np.zeros(7)
MOVING = [1, 3, 5]
OFFSETS = np.radians([j.offset_deg for j in ARM.joints])


def test_step_law_sends_the_plan_one_cycle_ahead_in_module_radians():
    law = StepSetpoints(ARM, 0.01, RUN)
    plan = plan_move(PARK, TOTEM, RUN, MOVING)
    requests = law.cycle(plan, 1.0, MOVING, np.degrees(plan.at(1.0)[0]))
    expected = plan.at(1.01)[0] + OFFSETS
    assert [r.module for r in requests] == [2, 4, 6]
    for r in requests:
        assert r.mode is MotionMode.FSTEP_ACK and r.time_ms == 10
        assert r.value == pytest.approx(expected[r.module - 1])


def test_ramp_law_targets_ahead_of_the_plan_and_caps_at_the_plan_velocity():
    law = RampSetpoints(ARM, 0.01, RUN)
    start = law.start(MOVING, RUN)
    assert all(isinstance(r, SetParam) and r.param is ParamId.TARGET_ACC for r in start)
    plan = plan_move(PARK, TOTEM, RUN, MOVING)
    t = plan.duration / 2
    on_plan = np.degrees(plan.at(t)[0])
    requests = law.cycle(plan, t, MOVING, on_plan)
    vel = {r.module: math.degrees(r.value) for r in requests if isinstance(r, SetParam)}
    pos = {r.module: r.value for r in requests if isinstance(r, SetMotion)}
    planned_vel = np.degrees(np.abs(plan.at(t + 0.01)[1]))
    for i in MOVING:
        module = i + 1
        assert vel[module] == pytest.approx(planned_vel[i], abs=0.06)   # quantum 0.1 deg/s
        # Ahead of where the plan is now, in the direction of motion.
        direction = np.sign(TOTEM[i] - PARK[i])
        assert (pos[module] - (plan.at(t)[0][i] + OFFSETS[i])) * direction > 0.01


def test_each_law_says_where_its_position_commands_leave_the_joints():
    """Where the commanded joints stop if no command follows (what bounds an arm whose
    host stalls): a FRAMP's or an FSTEP's target in user radians, NaN for joints the
    motion does not command, None for a velocity command."""
    plan = plan_move(PARK, TOTEM, RUN, MOVING)
    t = plan.duration / 2
    for law in (RampSetpoints(ARM, 0.01, RUN), StepSetpoints(ARM, 0.01, RUN)):
        law.start(MOVING, RUN)
        requests = law.cycle(plan, t, MOVING, np.degrees(plan.at(t)[0]))
        holds = law.holds_at_rad
        assert holds is not None
        sent = {r.module: r.value for r in requests if isinstance(r, SetMotion)}
        for i in range(7):
            if i in MOVING:
                assert holds[i] + OFFSETS[i] == pytest.approx(sent[i + 1])
            else:
                assert math.isnan(holds[i])
    velocity = setpoint_law("velocity", ARM, 0.01, RUN)
    velocity.start(MOVING, RUN)
    velocity.cycle(plan, t, MOVING, np.degrees(plan.at(t)[0]))
    assert velocity.holds_at_rad is None


def test_ramp_law_does_not_resend_an_unchanged_target_velocity():
    law = RampSetpoints(ARM, 0.01, RUN)
    law.start(MOVING, RUN)
    plan = plan_move(PARK, TOTEM, RUN, MOVING)
    t = plan.duration / 2                      # cruise: constant velocity
    first = law.cycle(plan, t, MOVING, np.degrees(plan.at(t)[0]))
    again = law.cycle(plan, t + 0.01, MOVING, np.degrees(plan.at(t + 0.01)[0]))
    assert sum(isinstance(r, SetParam) for r in first) == 3
    assert sum(isinstance(r, SetParam) for r in again) == 0
    assert sum(isinstance(r, SetMotion) for r in again) == 3   # positions every cycle


def test_catch_up_never_exceeds_the_moves_own_limit():
    slow = Limits.from_arm(ARM, velocity_scale=0.5)
    law = RampSetpoints(ARM, 0.1, RUN)
    law.start(MOVING, slow)
    plan = plan_move(PARK, TOTEM, slow, MOVING)
    t = plan.duration / 2
    far_behind = np.degrees(plan.at(t)[0]) - 20.0           # 20 degrees of lag
    caps = [math.degrees(r.value) for r in law.cycle(plan, t, MOVING, far_behind)
            if isinstance(r, SetParam)]
    ceiling = 30 * 0.5 / (1 - ARM.control.tracking_reserve)
    assert caps and max(caps) <= ceiling + 1e-9


def test_unknown_mode_is_refused():
    with pytest.raises(ValueError, match="unknown command mode"):
        setpoint_law("jog", ARM, 0.01, RUN)
