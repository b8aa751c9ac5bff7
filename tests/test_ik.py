"""Inverse kinematics (seqrun/arm/ik.py) and ``seqrun ik``: round trips, limits, tools, errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import seqrun.cli.ik  # noqa: F401  (registers `ik`)
from projecttree import ROOT, shipped_arm
from seqrun.arm.description import Tool
from seqrun.cli.app import app
from seqrun.arm.ik import IkSolver, Unreachable, target_frame, tool_chain
from seqrun.arm.kinematics import Chain, fk, orientation_error
from tiers import examples

ARM = shipped_arm()
CHAIN = Chain.from_arm(ARM)
LIMITS = np.array([j.limits_deg for j in ARM.joints])
FILES = ["--arm", str(ROOT / "arms" / "lwa3.yaml"), "--poses-dir", str(ROOT / "poses")]
OPSAFE = [70, 30, 0, 70, 20, 50, 0]


def _unlocked(arm):
    joints = [j.model_copy(update={"locked": None}) for j in arm.joints]
    return arm.model_copy(update={"joints": joints})


ARM7 = _unlocked(ARM)
SOLVER6 = IkSolver(ARM)
SOLVER7 = IkSolver(ARM7)


def configuration(locked_j3: bool):
    """Random in-limit configurations (degrees), kept 1° inside so the target is not on a
    limit where only a measure-zero set of solutions exists."""
    def one(j, lo, hi):
        if locked_j3 and j == 2:
            return st.just(0.0)
        return st.floats(lo + 1, hi - 1, allow_nan=False)
    return st.tuples(*(one(j, lo, hi) for j, (lo, hi) in enumerate(LIMITS))).map(np.array)


def _check(solver, chain, q_true, seed):
    target = fk(chain, np.radians(q_true))
    solution = solver.solve(target, seed)
    reached = fk(chain, np.radians(solution.joints_deg))
    assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) <= 1e-3
    assert orientation_error(reached, target) <= 1e-6
    assert np.all(solution.joints_deg >= LIMITS[:, 0]) and np.all(solution.joints_deg <= LIMITS[:, 1])
    return solution


def _well_conditioned(q_deg, columns=(0, 1, 3, 4, 5, 6)) -> bool:
    """Away from singularities (where the solution is not unique, e.g. Totem: j1, j5, j7
    on one line)."""
    from seqrun.arm.kinematics import jacobian

    jac = jacobian(CHAIN, np.radians(q_deg))[:, list(columns)]
    jac[:3] /= 200.0  # mm -> comparable with radians
    return float(np.linalg.svd(jac, compute_uv=False).min()) > 0.1


@settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(q=configuration(locked_j3=True), near=st.booleans())
def test_round_trip_six_active_joints_keeps_j3_locked(q, near):
    seed = np.clip(q + 3.0, LIMITS[:, 0], LIMITS[:, 1]) if near else np.zeros(7)
    seed[2] = 0.0
    solution = _check(SOLVER6, CHAIN, q, seed)
    assert solution.joints_deg[2] == 0.0  # the locked joint never moves
    if near and _well_conditioned(q):  # seeded 3° away: the same solution, not another branch
        assert np.max(np.abs(solution.joints_deg - q)) < 1e-3


@settings(max_examples=examples(40), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(q=configuration(locked_j3=False))
def test_round_trip_full_seven_joint_arm_from_a_nearby_seed(q):
    seed = np.clip(q + 2.0, LIMITS[:, 0], LIMITS[:, 1])
    solution = _check(SOLVER7, CHAIN, q, seed)
    if _well_conditioned(q, range(7)):
        # redundancy resolved towards the seed: the swivel stays near where the arm is
        assert np.max(np.abs(solution.joints_deg - seed)) < 10.0


def test_redundant_arm_prefers_the_configuration_nearest_the_seed():
    target = fk(CHAIN, np.radians(OPSAFE))
    far = SOLVER7.solve(target, [0, 0, 0, 0, 0, 0, 0]).joints_deg
    near = SOLVER7.solve(target, [70, 30, 3, 70, 20, 50, 0]).joints_deg
    assert abs(near[2] - 3.0) < abs(near[2] - far[2]) or abs(near[2] - 3.0) < 3.0
    assert np.linalg.norm(near - OPSAFE) < 5.0


def test_opsafe_from_totem_is_found_inside_the_limits():
    solution = _check(SOLVER6, CHAIN, np.array(OPSAFE, float), np.zeros(7))
    assert solution.seeds_tried >= 1


def test_unreachable_target_says_so_with_the_residual():
    with pytest.raises(Unreachable) as info:
        SOLVER6.solve(target_frame([0, 0, 2000], [0, 0, 0]), np.zeros(7))
    assert info.value.position_error_mm > 900  # the arm is ~1083 mm long, 2000 mm is far
    assert "unreachable" in str(info.value) and "mm" in str(info.value)
    best = info.value.best_deg
    assert np.all(best >= LIMITS[:, 0]) and np.all(best <= LIMITS[:, 1])


def test_reachable_only_beyond_a_joint_limit_is_unreachable():
    # j2 at 150° is a real pose of the chain, outside j2's ±120°; the other joints at 0
    # leave no other way to that orientation and position.
    chain_target = fk(CHAIN, np.radians([0, 150, 0, 0, 0, 0, 0]))
    with pytest.raises(Unreachable):
        IkSolver(ARM, restarts=10).solve(chain_target, np.zeros(7))


def test_tool_frame_moves_the_target_to_the_tool_centre_point():
    arm = ARM.model_copy(update={"tools": [Tool(name="probe", xyz_mm=(0, 0, -100))],
                                 "default_tool": "probe"})
    chain = tool_chain(arm, "probe")
    q = np.radians(OPSAFE)
    tip, flange = fk(chain, q), fk(CHAIN, q)
    assert np.linalg.norm(tip[:3, 3] - flange[:3, 3]) == pytest.approx(100.0)
    solution = IkSolver(arm).solve(tip, np.array(OPSAFE) + 2.0 * (np.arange(7) != 2))
    assert np.max(np.abs(solution.joints_deg - OPSAFE)) < 1e-3


def test_unknown_tool_is_a_key_error():
    with pytest.raises(KeyError):
        IkSolver(ARM, "gripper")


def test_arm_file_rejects_an_unknown_default_tool():
    with pytest.raises(ValueError, match="default_tool"):
        ARM.model_validate({**ARM.model_dump(), "default_tool": "nothing"})


# --- seqrun ik --------------------------------------------------------------------------

runner = CliRunner()


def run(*args: str):
    return runner.invoke(app, list(args))


def test_cli_finds_opsafe_near_opsafe():
    result = run("ik", "--position-mm", "-136.305", "510.761", "389.804",
                 "--rpy-deg", "-22.318", "-27.505", "124.351", "--near", "opsafe", "--json",
                 *FILES)
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert [data["joints_deg"][n] for n in ARM.joint_names] == pytest.approx(OPSAFE, abs=1e-3)


def test_cli_near_deg_takes_negative_angles():
    park = ["0", "-90", "0", "-120", "0", "115.74", "0"]
    pose = fk(CHAIN, np.radians([0, -85, 0, -110, 0, 100, 0]))
    from seqrun.arm.kinematics import rpy_from_matrix

    rpy = np.degrees(rpy_from_matrix(pose))
    result = run("ik", "--position-mm", *map(str, pose[:3, 3]), "--rpy-deg", *map(str, rpy),
                 "--near-deg", *park, "--json", *FILES)
    assert result.exit_code == 0, result.output
    joints = json.loads(result.stdout)["joints_deg"]
    assert joints["j2"] == pytest.approx(-85, abs=1e-3)


def test_cli_unreachable_is_one_line_and_exit_1():
    result = run("ik", "--position-mm", "0", "0", "2000", "--rpy-deg", "0", "0", "0", *FILES)
    assert result.exit_code == 1
    assert result.stdout == ""
    assert result.stderr.startswith("error: unreachable:") and result.stderr.count("\n") == 1


@pytest.mark.parametrize("args, message", [
    (["--position-mm", "0", "0", "--rpy-deg", "0", "0", "0"], "--position-mm needs 3 numbers, got 2"),
    (["--position-mm", "0", "0", "x", "--rpy-deg", "0", "0", "0"], "--position-mm: 'x' is not a number"),
    (["--position-mm", "0", "0", "500", "--rpy-deg", "0", "0", "0", "--tool", "gripper"],
     "unknown tool 'gripper' (the arm file's tools: none defined)"),
    (["--position-mm", "0", "0", "500", "--rpy-deg", "0", "0", "0", "--near-deg", "1", "2"],
     "--deg needs 7 angles (j1 j2 j3 j4 j5 j6 j7), got 2"),
])
def test_cli_bad_input_is_one_line_and_exit_2(args, message):
    result = run("ik", *args, *FILES)
    assert result.exit_code == 2, result.output
    assert result.stderr == f"error: {message}\n"


def test_rotation_vector_near_a_half_turn():
    from seqrun.arm.ik import rotation_vector
    from seqrun.arm.kinematics import matrix_from_rpy

    for angle in (math.pi, math.pi - 1e-7, 1e-8, 0.0, 2.0):
        axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        rotation = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k
        vector = rotation_vector(rotation)
        assert np.linalg.norm(vector) == pytest.approx(angle, abs=1e-9)
        if angle > 1e-3:
            assert abs(abs(vector @ axis) - angle) < 1e-6
    assert matrix_from_rpy([0, 0, 0]).shape == (3, 3)
