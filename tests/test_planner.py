"""The planner: synchronized, limit-respecting, locked/inactive joints never move."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from projecttree import shipped_arm
from seqrun.errors import PlanningError
from seqrun.arm.planner import Limits, plan_move, plan_stop
from tiers import examples

ARM = shipped_arm()
LIMITS = Limits.from_arm(ARM)
ACTIVE = [0, 1, 3, 4, 5, 6]  # joint 3 (index 2) is locked

PARK = np.radians([0, -90, 0, -120.32, 0, 115.74, 0])
OPSAFE = np.radians([70, 30, 0, 70, 20, 50, 0])


def _samples(plan, n=400):
    ts = np.linspace(0, plan.duration, n)
    rows = [plan.at(t) for t in ts]
    return ts, np.array([r[0] for r in rows]), np.array([r[1] for r in rows])


def test_all_active_joints_arrive_together_and_inactive_hold():
    plan = plan_move(PARK, OPSAFE, LIMITS, ACTIVE)
    pos, vel, _ = plan.at(plan.duration)
    np.testing.assert_allclose(pos[ACTIVE], OPSAFE[ACTIVE], atol=1e-9)
    _, positions, velocities = _samples(plan)
    assert np.all(positions[:, 2] == PARK[2])
    # Synchronized: every joint that moves is still moving just before the end.
    _, v_late, _ = plan.at(plan.duration * 0.9)
    moving = [i for i in ACTIVE if abs(OPSAFE[i] - PARK[i]) > 1e-6]
    assert all(abs(v_late[i]) > 1e-4 for i in moving)


def test_duration_is_bounded_below_by_the_slowest_joint():
    plan = plan_move(PARK, OPSAFE, LIMITS, ACTIVE)
    longest = max(abs(OPSAFE[i] - PARK[i]) for i in ACTIVE)
    assert plan.duration >= longest / LIMITS.velocity[0]
    assert plan.duration < longest / LIMITS.velocity[0] + 2 * LIMITS.velocity[0] / LIMITS.acceleration[0] + 1.0


def test_at_is_clamped_past_the_end():
    plan = plan_move(PARK, OPSAFE, LIMITS, ACTIVE)
    pos, vel, acc = plan.at(plan.duration + 5.0)
    np.testing.assert_allclose(pos, plan.target)
    assert not vel.any() and not acc.any()
    pos0, _, _ = plan.at(-1.0)
    np.testing.assert_allclose(pos0, PARK, atol=1e-12)


def test_speed_override_scales_duration():
    fast = plan_move(PARK, OPSAFE, LIMITS, ACTIVE)
    slow = plan_move(PARK, OPSAFE, Limits.from_arm(ARM, speed=0.5), ACTIVE)
    assert slow.duration > 1.8 * fast.duration


def test_per_joint_velocity_cap_is_respected():
    limits = Limits.from_arm(ARM, velocity_deg_s={"j1": 5.0})
    plan = plan_move(PARK, OPSAFE, limits, ACTIVE)
    assert plan.peak_velocity()[0] <= math.radians(5.0) * 1.001


def test_bad_scale_is_refused():
    with pytest.raises(PlanningError):
        Limits.from_arm(ARM, speed=0.0)
    with pytest.raises(PlanningError):
        plan_move(PARK, np.full(7, np.nan), LIMITS, ACTIVE)


def test_stop_reaches_zero_velocity_within_limits():
    plan = plan_move(PARK, OPSAFE, LIMITS, ACTIVE)
    pos, vel, acc = plan.at(plan.duration / 2)
    stop = plan_stop(pos, vel, acc, LIMITS, ACTIVE)
    _, v_end, _ = stop.at(stop.duration - 1e-9)
    assert np.max(np.abs(v_end)) < 1e-3
    # Braking distance from v with limit a is at least v^2/(2a) and the stop never reverses.
    for i in ACTIVE:
        if abs(vel[i]) > 1e-6:
            assert np.sign(stop.target[i] - pos[i]) == np.sign(vel[i])


angles = st.lists(st.floats(-2.0, 2.0), min_size=7, max_size=7)


@settings(max_examples=examples(60), deadline=None)
@given(angles, angles)
def test_plans_respect_limits_and_reach_the_target(start, target):
    plan = plan_move(start, target, LIMITS, ACTIVE)
    _, positions, velocities = _samples(plan, 200)
    assert np.all(np.abs(velocities) <= LIMITS.velocity * 1.001 + 1e-9)
    np.testing.assert_allclose(plan.at(plan.duration)[0][ACTIVE], np.asarray(target)[ACTIVE], atol=1e-7)
    assert np.all(positions[:, 2] == start[2])


@settings(max_examples=60, deadline=None)
@given(start=st.lists(st.floats(-2.5, 2.5), min_size=7, max_size=7),
       target=st.lists(st.floats(-2.5, 2.5), min_size=7, max_size=7),
       active=st.sets(st.integers(0, 6)))
def test_sample_gives_the_positions_of_at(start, target, active):
    """sample() skips at()'s velocity and acceleration arrays; its positions are at()'s,
    bit for bit, before the start, past the end and for a plan that moves no joint."""
    plan = plan_move(start, target, Limits.from_arm(ARM), sorted(active))
    times = [-0.5, 0.0, *np.linspace(0, plan.duration, 23), plan.duration, plan.duration + 1]
    expected = np.array([plan.at(t)[0] for t in times])
    sampled = plan.sample(times)
    assert sampled.dtype == expected.dtype and np.array_equal(sampled, expected)
    assert plan.sample([]).shape == np.array([]).shape
