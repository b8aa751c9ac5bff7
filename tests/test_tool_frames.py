"""The tool axis convention as docs/sequence-format.md ("Tools and frames") states it, the
hint for a target that points the tool up, and the shipped move_linear example."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from projecttree import ROOT, shipped_arm, write_sequence
from seqrun.arm.cartesian import pointing_up_hint, solver_for, tool_axis, tool_pose
from seqrun.arm.description import ArmDescription
from seqrun.arm.ik import target_frame
from seqrun.arm.kinematics import matrix_from_rpy
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence
from seqrun.service.dryrun import dry_run
from tiers import examples

ARM = shipped_arm()
PARK = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
DIRECTIONS = {"down": (0, 0, -1), "up": (0, 0, 1), "forward": (1, 0, 0), "back": (-1, 0, 0),
              "left": (0, 1, 0), "right": (0, -1, 0)}


def arm_with(*tools: dict) -> ArmDescription:
    return ArmDescription.model_validate({**ARM.model_dump(), "tools": list(tools)})


def documented_table() -> list[tuple[str, list[float], list[float]]]:
    """The rows of the direction table in docs/sequence-format.md."""
    text = (ROOT / "docs" / "sequence-format.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| (\w+) \([^)]*\) \| `(\[[^]]*\])` \| `(\[[^]]*\])` \|$", text, re.M)
    return [(word, json.loads(plain), json.loads(flipped)) for word, plain, flipped in rows]


def test_the_documented_directions_are_true():
    rows = documented_table()
    assert [word for word, _, _ in rows] == list(DIRECTIONS)
    plain = arm_with({"name": "probe", "xyz_mm": [0, 0, -120]})
    flipped = arm_with({"name": "probe", "xyz_mm": [0, 0, -120], "rpy_deg": [180, 0, 0]})
    for word, rpy_plain, rpy_flipped in rows:
        for arm, rpy in ((plain, rpy_plain), (flipped, rpy_flipped)):
            along = matrix_from_rpy(np.radians(rpy)) @ tool_axis(arm, "probe")
            assert along == pytest.approx(DIRECTIONS[word], abs=1e-12), (word, rpy)
        # the end-effector itself points as a tool without rotation does
        along = matrix_from_rpy(np.radians(rpy_plain)) @ tool_axis(ARM, None)
        assert along == pytest.approx(DIRECTIONS[word], abs=1e-12)


def test_totem_points_the_end_effector_up_along_its_minus_z():
    """The premise of the table: Totem's orientation is rpy [180, 0, 0], the arm points up,
    and a tool tip on the flange's axis ([0, 0, -120]) lies 120 mm higher."""
    frame = tool_pose(solver_for(arm_with({"name": "p", "xyz_mm": [0, 0, -120]}), "p"),
                      np.zeros(7))
    bare = tool_pose(solver_for(ARM, None), np.zeros(7))
    assert bare[:3, :3] == pytest.approx(np.diag([1, -1, -1]), abs=1e-12)
    assert frame[:3, 3] - bare[:3, 3] == pytest.approx([0, 0, 120], abs=1e-9)


@settings(max_examples=examples(40), deadline=None)
@given(yaw=st.floats(-180, 180))
def test_pointing_down_with_any_yaw_is_reachable_above_the_desk(yaw):
    solution = solver_for(ARM, None).solve(target_frame([0, 500, 300], [0, 0, yaw]),
                                           np.array([70, 30, 0, 70, 20, 50, 0], float))
    assert solution.position_error_mm < 1e-2


def test_an_unreachable_target_pointing_the_tool_up_says_how_to_point_it_down(project):
    steps = ("- reset\n- home\n- set_limits\n- move: totem\n- move: opsafe\n"
             "- move: {position_mm: [0, 400, 100], rpy_deg: [180, 0, 0]}\n")
    result = validate_sequence(load_sequence(write_sequence(project, steps)), ARM, PARK)
    [error] = result.errors
    assert (error.line, error.column) == (9, 23)
    assert error.message.startswith("end-effector target unreachable: ")
    assert error.message.endswith(
        "; this orientation points the tool up (the end-effector's z axis points back into "
        "the arm: [180, 0, 0] is Totem's); pointing down is rpy_deg [0, 0, 0] with any yaw "
        "(docs/sequence-format.md, 'Tools and frames')")


def test_the_hint_names_the_rpy_that_points_each_tool_down():
    up = target_frame([0, 400, 100], [180, 0, 0])
    flipped = arm_with({"name": "p", "xyz_mm": [0, 0, -120], "rpy_deg": [180, 0, 0]})
    assert "rpy_deg [180, 0, 0]" in pointing_up_hint(flipped, "p", target_frame([0, 0, 0],
                                                                                 [0, 0, 0]))
    assert pointing_up_hint(flipped, "p", up) == ""  # that one points down
    assert "rpy_deg [0, 0, 0]" in pointing_up_hint(ARM, None, up)
    sideways = arm_with({"name": "s", "xyz_mm": [0, 0, -120], "rpy_deg": [0, 90, 0]})
    hint = pointing_up_hint(sideways, "s", target_frame([0, 0, 0], [0, -90, 0]))
    rpy = [float(v) for v in re.search(r"rpy_deg \[([^]]*)\]", hint).group(1).split(", ")]
    assert matrix_from_rpy(np.radians(rpy)) @ tool_axis(sideways, "s") == pytest.approx(
        [0, 0, -1], abs=1e-9)


def test_the_linear_example_approaches_along_the_tool_and_passes():
    loaded = load_sequence(ROOT / "sequences" / "linear_approach.yaml")
    assert "move_linear" in [s.kind for s in loaded.steps]
    run = dry_run(loaded, ARM, PARK)
    assert run.result.exit_code == 0, run.result.message
    approach = next(s for s in run.result.steps if s.kind == "move_linear")
    assert approach.detail["length_mm"] == pytest.approx(100.0, abs=1e-3)
    assert approach.detail["max_deviation_mm"] < 0.05
    moved = next(s for s in run.result.steps if s.detail.get("moved_mm") is not None)
    assert moved.detail["moved_mm"] == pytest.approx([0, 0, -100], abs=0.05)


def test_a_straight_line_to_a_tool_pointing_up_says_how_to_point_it_down(project):
    steps = ("- reset\n- home\n- set_limits\n- move: totem\n- move: opsafe\n"
             "- move_linear: {position_mm: [0, 400, 100], rpy_deg: [180, 0, 0], "
             "speed_mm_s: 20}\n")
    result = validate_sequence(load_sequence(write_sequence(project, steps)), ARM, PARK)
    [error] = result.errors
    assert (error.line, error.column) == (9, 30)
    assert error.message.startswith("straight line: ")  # (a joint limit on the way)
    assert "; this orientation points the tool up" in error.message
    assert error.message.endswith("pointing down is rpy_deg [0, 0, 0] with any yaw "
                                  "(docs/sequence-format.md, 'Tools and frames')")
