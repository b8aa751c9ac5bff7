"""Forward kinematics against the reference (shared/reference/lwa3-arm.md) and its properties."""

from __future__ import annotations

from typing import get_args

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from projecttree import shipped_arm
from tiers import examples
from seqrun.arm.description import GuardPoint
from seqrun.arm.kinematics import (
    Chain,
    fk,
    frame_origins,
    frame_transforms,
    jacobian,
    matrix_from_rpy,
    orientation_error,
    point_heights,
    point_positions,
    pose_from_user_deg,
    rpy_from_matrix,
)

ARM = shipped_arm()
CHAIN = Chain.from_arm(ARM)

TOTEM = [0, 0, 0, 0, 0, 0, 0]
PARK = [0, -90, 0, -120.32, 0, 115.74, 0]
OPSAFE = [70, 30, 0, 70, 20, 50, 0]

angles = st.floats(-np.pi, np.pi, allow_nan=False)
configurations = arrays(np.float64, 7, elements=angles)
batches = st.integers(1, 6).flatmap(
    lambda n: arrays(np.float64, (n, 7), elements=angles))


# --- the reference's own numbers -------------------------------------------------------------

RX_MINUS_90 = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]])
RX_PLUS_90 = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])
REFERENCE_TABLE = [  # F2 .. F7, mm
    (0, -13.1, -166.9), (0, 182.6, 13.1), (0, -13.6, -145.4),
    (0, 159.1, 13.6), (0.565, -10.785, -117.4), (-0.571, 141.6, 10.885),
]


def reference_fk(q_rad: np.ndarray) -> np.ndarray:
    """The reference formula written out literally, one configuration at a time."""
    def frame(rotation, translation):
        t = np.eye(4)
        t[:3, :3] = rotation
        t[:3, 3] = translation
        return t

    def rz(a):
        return frame([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]], [0, 0, 0])

    t = frame(np.diag([1, -1, -1]), [0, 0, 133.1]) @ rz(q_rad[0])
    for i, translation in enumerate(REFERENCE_TABLE, start=2):
        rotation = RX_MINUS_90 if i % 2 == 0 else RX_PLUS_90
        t = t @ frame(rotation, translation) @ rz(q_rad[i - 1])
    return t @ frame(np.eye(3), [0, 0, -36.9])


def test_chain_frames_are_the_reference_matrices():
    assert np.array_equal(CHAIN.base[:3, :3], np.diag([1, -1, -1]))
    assert np.array_equal(CHAIN.base[:3, 3], [0, 0, 133.1])
    for i, (link, translation) in enumerate(zip(CHAIN.links, REFERENCE_TABLE), start=2):
        expected = RX_MINUS_90 if i % 2 == 0 else RX_PLUS_90
        assert np.array_equal(link[:3, :3], expected), f"F{i}"
        assert np.array_equal(link[:3, 3], translation), f"F{i}"
    assert np.array_equal(CHAIN.tool, [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -36.9], [0, 0, 0, 1]])


def test_chain_is_read_only():
    with pytest.raises(ValueError):
        CHAIN.links[0, 0, 3] = 1.0


def test_totem_check_value():
    frame = fk(CHAIN, np.zeros(7))
    assert np.allclose(frame[:3, 3], [-0.006, -0.1, 1083.0], rtol=0, atol=0.01)
    assert np.allclose(frame[:3, :3], np.diag([1, -1, -1]), rtol=0, atol=1e-12)
    pose = pose_from_user_deg(ARM, TOTEM)
    assert np.allclose(pose.rpy_deg, [180, 0, 0], rtol=0, atol=1e-9)


def test_park_end_effector_is_48_mm_above_the_base_plane():
    pose = pose_from_user_deg(ARM, PARK)
    # Computed value: (365.9027, -0.1000, 47.9208) mm, rpy (0, 85.4200, 180) deg.
    assert np.allclose(pose.position_mm, [365.9027, -0.1, 47.9208], rtol=0, atol=1e-3)
    assert np.allclose(pose.rpy_deg, [0.0, 85.42, 180.0], rtol=0, atol=1e-3)


def test_opsafe_value():
    pose = pose_from_user_deg(ARM, OPSAFE)
    assert np.allclose(pose.position_mm, [-136.3048, 510.7606, 389.8036], rtol=0, atol=1e-3)
    assert np.allclose(pose.rpy_deg, [-22.3180, -27.5049, 124.3510], rtol=0, atol=1e-3)


@settings(deadline=None)  # (a loaded host: the first example compiles numpy's paths)
@given(configurations)
def test_fk_is_the_reference_formula(q):
    assert np.allclose(fk(CHAIN, q), reference_fk(q), rtol=0, atol=1e-9)


def test_guard_points_at_totem():
    points = point_positions(CHAIN, np.zeros(7))
    expected = {
        "shoulder": [0, 13.1, 300.0],
        "elbow": [0, 13.6, 628.0],
        "wrist": [0.565, 10.785, 904.5],
        "flange": [-0.006, -0.1, 1046.1],
        "end_effector": [-0.006, -0.1, 1083.0],
    }
    assert set(points) == set(expected) == set(get_args(GuardPoint))
    for name, position in expected.items():
        assert np.allclose(points[name], position, rtol=0, atol=1e-9), name


def test_guard_points_are_vectorised():
    q = np.zeros((2, 3, 7))
    assert all(p.shape == (2, 3, 3) for p in point_positions(CHAIN, q).values())


# --- properties ------------------------------------------------------------------------------

@given(batches)
def test_rotation_is_orthonormal(q):
    rotation = fk(CHAIN, q)[..., :3, :3]
    identity = np.broadcast_to(np.eye(3), rotation.shape)
    assert np.allclose(rotation.swapaxes(-1, -2) @ rotation, identity, atol=1e-12)
    assert np.allclose(np.linalg.det(rotation), 1.0, atol=1e-12)


@given(batches)
def test_batch_equals_loop_of_singles(q):
    batch_frames = frame_transforms(CHAIN, q)
    batch_jacobians = jacobian(CHAIN, q)
    for k, single in enumerate(q):
        assert np.allclose(fk(CHAIN, single), batch_frames[k, -1], rtol=0, atol=1e-9)
        assert np.allclose(frame_transforms(CHAIN, single), batch_frames[k], rtol=0, atol=1e-9)
        assert np.allclose(jacobian(CHAIN, single), batch_jacobians[k], rtol=0, atol=1e-9)
    assert fk(CHAIN, q.reshape(1, *q.shape)).shape == (1, len(q), 4, 4)


@given(st.floats(-np.pi, np.pi), st.floats(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3),
       st.floats(-np.pi, np.pi))
def test_rpy_round_trip_away_from_the_singularity(roll, pitch, yaw):
    rpy = rpy_from_matrix(matrix_from_rpy([roll, pitch, yaw]))
    assert np.all((-np.pi < rpy) & (rpy <= np.pi))
    difference = np.angle(np.exp(1j * (rpy - [roll, pitch, yaw])))  # ±π are the same angle
    assert np.allclose(difference, 0.0, rtol=0, atol=1e-8)


def test_matrix_from_rpy_is_z_y_x():
    roll, pitch, yaw = 0.3, -0.4, 1.1

    def axis_rotation(axis, a):
        c, s = np.cos(a), np.sin(a)
        return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
                "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
                "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]

    expected = axis_rotation("z", yaw) @ axis_rotation("y", pitch) @ axis_rotation("x", roll)
    assert np.allclose(matrix_from_rpy([roll, pitch, yaw]), expected, rtol=0, atol=1e-15)


def test_rpy_half_turns_are_positive():
    # -0.0 entries used to give roll = -180
    rotation = np.array([[1.0, 0, 0], [0, -1, 0], [0, -0.0, -1]])
    assert rpy_from_matrix(rotation).tolist() == [np.pi, 0.0, 0.0]


@given(configurations, configurations)
def test_orientation_error_is_symmetric(qa, qb):
    ra, rb = fk(CHAIN, qa), fk(CHAIN, qb)
    assert np.isclose(orientation_error(ra, rb), orientation_error(rb, ra), rtol=0, atol=1e-12)
    assert orientation_error(ra, ra) == pytest.approx(0.0, abs=1e-7)
    assert 0.0 <= orientation_error(ra, rb) <= np.pi


unit_axes = arrays(np.float64, 3, elements=st.floats(-1, 1)).filter(
    lambda v: np.linalg.norm(v) > 0.1)


@given(configurations, unit_axes, st.floats(0, np.pi))
def test_orientation_error_is_the_rotation_angle(q, axis, angle):
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    turn = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k  # Rodrigues
    start = fk(CHAIN, q)[:3, :3]
    assert orientation_error(start, start @ turn) == pytest.approx(angle, abs=1e-9)


def test_orientation_error_keeps_precision_near_zero_and_half_turn():
    for angle in (1e-9, np.pi - 1e-9):
        turn = matrix_from_rpy([angle, 0, 0])
        assert orientation_error(np.eye(3), turn) == pytest.approx(angle, rel=1e-6)


@settings(deadline=None)
@given(configurations)
def test_jacobian_equals_finite_differences(q):
    step = 1e-6
    analytic = jacobian(CHAIN, q)
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = step
        plus, minus = fk(CHAIN, q + dq), fk(CHAIN, q - dq)
        linear = (plus[:3, 3] - minus[:3, 3]) / (2 * step)
        # dR/dq = [w]x R  ->  [w]x = (R+ - R-) / 2h · R^T
        skew = (plus[:3, :3] - minus[:3, :3]) / (2 * step) @ fk(CHAIN, q)[:3, :3].T
        angular = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
        assert np.allclose(analytic[:3, i], linear, rtol=0, atol=1e-4), f"linear, joint {i + 1}"
        assert np.allclose(analytic[3:, i], angular, rtol=0, atol=1e-7), f"angular, joint {i + 1}"


@given(configurations, angles)
def test_joint_7_does_not_move_the_flange(q, q7):
    moved = q.copy()
    moved[6] = q7
    before, after = point_positions(CHAIN, q), point_positions(CHAIN, moved)
    assert np.allclose(before["flange"], after["flange"], rtol=0, atol=1e-9)
    assert np.allclose(before["wrist"], after["wrist"], rtol=0, atol=1e-9)


# --- user-coordinate entry point -------------------------------------------------------------

def test_pose_from_mapping_fills_the_locked_joint():
    by_name = {"j1": 70, "j2": 30, "j4": 70, "j5": 20, "j6": 50, "j7": 0}
    assert np.allclose(pose_from_user_deg(ARM, by_name).position_mm,
                       pose_from_user_deg(ARM, OPSAFE).position_mm, rtol=0, atol=0)


@pytest.mark.parametrize(("joints", "message"), [
    ({"j1": 0, "j2": 0, "j4": 0, "j5": 0, "j6": 0}, "missing joint(s) j7"),
    ({"j1": 0, "j2": 0, "j4": 0, "j5": 0, "j6": 0, "j7": 0, "j9": 0}, "unknown joint(s) j9"),
    ([0, 0, 5, 0, 0, 0, 0], "j3 is locked at 0 deg, got 5"),
    ([0, 0, 0], "expected 7 joint angles"),
    ([0, float("nan"), 0, 0, 0, 0, 0], "j2: nan is not a finite angle"),
])
def test_pose_from_user_deg_rejects_bad_joints(joints, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        pose_from_user_deg(ARM, joints)


def test_wrong_shape_is_refused():
    with pytest.raises(ValueError, match=r"\(\.\.\., 7\)"):
        fk(CHAIN, np.zeros(6))


# --- the same bits as the 4x4 products -------------------------------------------------------

def blas_chain_frames(chain: Chain, q: np.ndarray) -> np.ndarray:
    """The chain as 4x4 products, one joint after the other (what frame_transforms computed
    before it mixed cos and sin into the quarter-turn frames itself): the bits every
    guard height, clearance and checkpoint of a run was computed with."""
    c, s = np.cos(q), np.sin(q)
    rot = np.zeros(q.shape + (4, 4))
    rot[..., 0, 0], rot[..., 0, 1], rot[..., 1, 0], rot[..., 1, 1] = c, -s, s, c
    rot[..., 2, 2] = rot[..., 3, 3] = 1.0
    frames = np.empty(q.shape[:-1] + (chain.dof + 1, 4, 4))
    current = frames[..., 0, :, :] = chain.base @ rot[..., 0, :, :]
    for k, link in enumerate(chain.links, start=1):
        current = frames[..., k, :, :] = current @ (link @ rot[..., k, :, :])
    frames[..., chain.dof, :, :] = current @ chain.tool
    return frames


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal bit for bit, the signs of zeros included."""
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


SPECIAL_ANGLES = [0.0, -0.0, np.pi / 2, -np.pi / 2, np.pi, -np.pi, 2 * np.pi, 1e-300, 1e-17]
special_configurations = arrays(np.float64, 7, elements=st.sampled_from(SPECIAL_ANGLES))
# A chain whose base and third frame are not quarter turns: those two take the 4x4 product.
SKEWED = Chain.from_arm(ARM.model_copy(update={"kinematics": ARM.kinematics.model_copy(update={
    "base": ARM.kinematics.base.model_copy(update={"rpy_deg": [170.0, 3.0, 0.0]}),
    "links": [link.model_copy(update={"rpy_deg": [-83.0, 7.0, 1.5]}) if i == 2 else link
              for i, link in enumerate(ARM.kinematics.links)]})}))


@settings(max_examples=examples(200))
@given(st.one_of(batches, configurations, special_configurations),
       st.sampled_from([CHAIN, SKEWED]))
def test_frames_have_the_bits_of_the_4x4_products(q, chain):
    expected = blas_chain_frames(chain, q)
    assert same_bits(frame_transforms(chain, q), expected)
    assert same_bits(fk(chain, q), expected[..., -1, :, :])
    assert same_bits(frame_origins(chain, q), np.ascontiguousarray(expected[..., :3, 3]))
    if q.ndim == 2:
        for k, single in enumerate(q):
            assert same_bits(frame_transforms(chain, single), expected[k])


def test_quarter_turn_frames_skip_the_product():
    assert CHAIN._turns.general == ()
    assert SKEWED._turns.general == (0, 3)
    assert not np.allclose(fk(SKEWED, np.zeros(7)), fk(CHAIN, np.zeros(7)))


def test_chain_of_an_arm_is_built_once():
    arm = shipped_arm()
    assert Chain.from_arm(arm) is Chain.from_arm(arm)
    assert Chain.from_arm(arm.model_copy(update={"description": "other"})) is Chain.from_arm(arm)
    moved = arm.model_copy(update={"kinematics": arm.kinematics.model_copy(update={
        "tool": arm.kinematics.tool.model_copy(update={"xyz_mm": [0.0, 0.0, -100.0]})})})
    assert Chain.from_arm(moved) is not Chain.from_arm(arm)
    assert fk(Chain.from_arm(moved), np.zeros(7))[2, 3] == pytest.approx(1046.1 + 100.0)


@given(st.one_of(configurations, special_configurations), st.sampled_from([CHAIN, SKEWED]))
def test_point_heights_are_the_z_of_point_positions(q, chain):
    heights = point_heights(chain, q)
    positions = point_positions(chain, q)
    assert set(heights) == set(positions)
    for name, position in positions.items():
        assert same_bits(np.float64(heights[name]), position[2]), name


def test_point_heights_take_one_configuration():
    with pytest.raises(ValueError, match=r"one configuration of shape \(7,\)"):
        point_heights(CHAIN, np.zeros((2, 7)))
