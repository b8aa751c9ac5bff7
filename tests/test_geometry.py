"""Link volumes, obstacles and self-collision (seqrun/arm/geometry.py), and their use in
validation (along the planned trajectory) and at run time (measured joints)."""

from __future__ import annotations


import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from projecttree import shipped_arm, write_sequence
from seqrun.arm.description import ArmDescription
from seqrun.service.dryrun import dry_run
from seqrun.arm.geometry import (Geometry, _segment_distance, point_box, point_cylinder,
                             segment_box, segment_min, segment_segment)
from seqrun.arm.kinematics import matrix_from_rpy
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence
from tiers import examples

ARM = shipped_arm()
GEOMETRY = Geometry(ARM)
PARK = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}

coordinate = st.floats(-300, 300, allow_nan=False)
point = arrays(np.float64, 3, elements=coordinate)


def _dense(a, b, n=4001):
    t = np.linspace(0, 1, n)[:, None]
    return a + t * (b - a)


@settings(max_examples=examples(200), deadline=None)
@given(p1=point, q1=point, p2=point, q2=point)
def test_segment_distance_matches_dense_sampling(p1, q1, p2, q2):
    exact = float(segment_segment(p1, q1, p2, q2))
    a, b = _dense(p1, q1, 801), _dense(p2, q2, 801)
    # Every pair's squared distance, one coordinate at a time (a tenth of the time of the
    # 801 x 801 x 3 difference array and its norm; the same minimum).
    squared = sum((a[:, k, None] - b[None, :, k]) ** 2 for k in range(3))
    brute = float(np.sqrt(squared.min()))
    spacing = (np.linalg.norm(q1 - p1) + np.linalg.norm(q2 - p2)) / 800
    assert exact <= brute + 1e-6
    assert brute - exact <= spacing + 1e-6


def test_a_short_segment_is_a_segment_not_its_first_point():
    # hypothesis' counter-example (issue 29): seg 1 is 1e-5 long and ends where seg 2
    # starts, so they touch; taken for parallel segments, seg 1 was measured from its first
    # point only (8.2e-6). The run-time check (Geometry) uses the scalar twin.
    p1, q1 = np.array([1e-5, 0.0, 0.0]), np.zeros(3)
    p2, q2 = np.zeros(3), np.full(3, 0.0625)
    assert float(segment_segment(p1, q1, p2, q2)) == 0.0
    assert _segment_distance(p1, q1, p2, q2) == 0.0
    # the same pair the other way round, and seg 1 a little away from seg 2's start
    assert float(segment_segment(p2, q2, p1, q1)) == 0.0
    assert _segment_distance(p2, q2, p1, q1) == 0.0
    lifted = np.array([0.0, 0.0, -1e-6])
    assert float(segment_segment(p1 + lifted, q1 + lifted, p2, q2)) == pytest.approx(
        1e-6, rel=1e-6)
    assert _segment_distance(p1 + lifted, q1 + lifted, p2, q2) == pytest.approx(1e-6, rel=1e-6)


def test_parallel_and_degenerate_segments():
    a, b = np.array([0.0, 0.0, 0.0]), np.array([10.0, 0.0, 0.0])
    for p2, q2, expected in (
            (np.array([5.0, 3.0, 0.0]), np.array([25.0, 3.0, 0.0]), 3.0),    # overlapping
            (np.array([14.0, 3.0, 0.0]), np.array([25.0, 3.0, 0.0]), 5.0),   # beyond the end
            (np.array([-7.0, 4.0, 0.0]), np.array([-3.0, 4.0, 0.0]), 5.0),   # before the start
            (np.array([4.0, 0.0, 2.0]), np.array([4.0, 0.0, 2.0]), 2.0),     # a point
    ):
        for args in ((a, b, p2, q2), (p2, q2, a, b), (b, a, q2, p2)):
            assert float(segment_segment(*args)) == pytest.approx(expected)
            assert _segment_distance(*args) == pytest.approx(expected)
    assert float(segment_segment(a, a, b, b)) == pytest.approx(10.0)
    assert _segment_distance(a, a, b, b) == pytest.approx(10.0)


@settings(max_examples=examples(150), deadline=None)
@given(a=point, b=point, center=point, size=arrays(np.float64, 3, elements=st.floats(1, 200)),
       rpy=arrays(np.float64, 3, elements=st.floats(-3, 3)))
def test_segment_to_box_matches_dense_sampling(a, b, center, size, rpy):
    rotation = matrix_from_rpy(rpy)
    distance = lambda p: point_box(p, center, rotation, size / 2)  # noqa: E731
    brute = float(distance(_dense(a, b)).min())
    tolerance = 1e-6 + np.linalg.norm(b - a) / 4000  # the samples' spacing
    closed_form = float(segment_box(a, b, center, rotation, size / 2))
    if brute >= 0:  # outside: exact, never more than the true distance
        assert closed_form <= brute + 1e-6
        assert closed_form == pytest.approx(brute, abs=tolerance)
    else:  # crossing the box: reported as a contact
        assert closed_form <= 0
    searched = float(segment_min(a, b, distance))  # the generic search, a lower bound
    assert brute - 0.2 <= searched <= brute + 1e-6


@settings(max_examples=examples(150), deadline=None)
@given(a=point, b=point, base=point, axis=point.filter(lambda v: np.linalg.norm(v) > 1),
       radius=st.floats(1, 100), height=st.floats(1, 300))
def test_segment_to_cylinder_matches_dense_sampling(a, b, base, axis, radius, height):
    unit = axis / np.linalg.norm(axis)
    distance = lambda p: point_cylinder(p, base, unit, radius, height)  # noqa: E731
    exact = float(segment_min(a, b, distance))
    brute = float(distance(_dense(a, b)).min())
    assert exact <= brute + 1e-6  # a lower bound: never overstates the clearance
    assert exact == pytest.approx(brute, abs=0.2)


def test_point_distances_inside_are_negative():
    assert float(point_box(np.zeros(3), np.zeros(3), np.eye(3), np.array([10, 20, 30.]))) == -10
    assert float(point_cylinder(np.array([0, 0, 5.]), np.zeros(3), np.array([0, 0, 1.]),
                                 4.0, 100.0)) == -4


def test_named_poses_are_clear_and_park_is_closest_to_the_desk():
    for joints in ([0] * 7, list(PARK.values()), [70, 30, 0, 70, 20, 50, 0]):
        assert GEOMETRY.smallest(np.radians(joints)).distance_mm > GEOMETRY.margin_mm
    park = GEOMETRY.smallest(np.radians(list(PARK.values())))
    # Park: the wrist axis point j6 at 61.6 mm, j7 at 50.9 mm; wrist radius 35 mm
    assert park.pair == "wrist~desk"
    assert park.distance_mm == pytest.approx(50.9 - 35, abs=0.1)


def test_hand_into_the_desk_and_self_collision_are_negative():
    down = GEOMETRY.smallest(np.radians([3, 108, 0, 108, -45, -18, 79]))
    assert down.pair.endswith("~desk") and down.distance_mm < -100
    folded = GEOMETRY.smallest(np.radians([-1, 116, 0, 118, 26, 100, 18]))
    values, names = GEOMETRY.clearances(np.radians([-1, 116, 0, 118, 26, 100, 18]))
    assert dict(zip(names, values))["column~hand"] < 0
    assert folded.distance_mm < 0


def test_batched_equals_single():
    rng = np.random.default_rng(3)
    q = np.radians(rng.uniform(-120, 120, (50, 7)))
    batch, names = GEOMETRY.clearances(q)
    single = np.array([GEOMETRY.clearances(row)[0] for row in q])
    assert batch == pytest.approx(single)
    assert len(names) == batch.shape[1]


def test_arm_file_rejects_an_unknown_frame_in_a_capsule():
    data = ARM.model_dump()
    data["geometry"]["capsules"][0]["end"] = "elbow"
    with pytest.raises(ValueError, match="capsule column: unknown frame 'elbow'"):
        ArmDescription.model_validate(data)


# --------------------------------------------------------------------------- in use

def _load(project, steps):
    return load_sequence(write_sequence(project, steps))


def _with_mock(arm: ArmDescription) -> ArmDescription:
    """The arm with a target mock (a box) on the desk in front of it, and no guard planes,
    so that only the link volumes can find the problem."""
    data = arm.model_dump()
    data["geometry"]["obstacles"].append(
        {"name": "target_mock", "box": {"center_mm": [-150, 450, 100], "size_mm": [200, 200, 200]}})
    data["workspace"] = {"guards": []}
    return ArmDescription.model_validate(data)


STEPS = ("- reset\n- home\n- set_limits\n- move: totem\n- move: opsafe\n"
         "- move: {joints: {j2: 60, j4: 60}}\n")


def test_validation_refuses_a_move_into_an_obstacle_at_its_line(project):
    result = validate_sequence(_load(project, STEPS), _with_mock(ARM), PARK)
    # every link that goes into it, in the order it happens, each at the move's line
    hand, wrist = result.errors
    assert hand.message.startswith("this move takes the hand into the target_mock (at 1.43 s")
    assert wrist.message.startswith("this move takes the wrist into the target_mock (at 1.73 s")
    for error in result.errors:
        assert (error.line, error.column) == (9, 3)
        assert "planned trajectory" in error.message
    assert result.proximities[6].distance_mm < ARM.geometry.margin_mm


def test_without_obstacles_the_same_move_is_fine(project):
    result = validate_sequence(_load(project, STEPS), ARM.model_copy(
        update={"workspace": ARM.workspace.model_copy(update={"guards": []})}), PARK)
    assert result.errors == []
    assert result.proximities[6].distance_mm > ARM.geometry.margin_mm


def test_the_run_halts_before_the_obstacle(project, monkeypatch):
    """Run-time check from the measured joints: with validation's geometry check switched
    off the executor streams the move and halts it at the margin."""
    from seqrun.sequence import validation

    monkeypatch.setattr(validation.Checker, "_path_collisions", lambda *a, **k: [])
    run = dry_run(_load(project, STEPS), _with_mock(ARM), PARK)
    assert run.result.exit_code == 3
    assert run.result.fault["cause"] == "collision"
    assert "target_mock" in run.result.message


@settings(max_examples=examples(100), deadline=None)
@given(q=arrays(np.float64, 7, elements=st.floats(-3.2, 3.2)))
def test_single_configuration_fast_path_equals_the_batched_one(q):
    values, names = GEOMETRY.clearances(q[None])
    fast = GEOMETRY.smallest(q)
    k = int(np.argmin(values[0]))
    assert fast.distance_mm == pytest.approx(values[0, k], abs=1e-9)
    assert fast.pair == names[k] or values[0, names.index(fast.pair)] == pytest.approx(values[0, k])
