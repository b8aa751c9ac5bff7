"""Checkpoints and moves mean the same frame (issue 23.3): the step's tool, else the arm's
default_tool, else the end-effector. With default_tool set, a move to P put the tool tip at
P but a checkpoint at P checked the end-effector and failed by the tool's length; an
absolute checkpoint refused ``tool:``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from projecttree import make_project, write_sequence
from seqrun.arm.cartesian import solver_for, tool_pose
from seqrun.arm.description import ArmDescription, load_arm
from seqrun.arm.kinematics import rpy_from_matrix
from seqrun.errors import SequenceInvalid
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence
from seqrun.service.dryrun import dry_run

PARK = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
UP = "- reset\n- home\n- set_limits\n- move: totem\n- move: opsafe\n"  # lines 4-8
NEAR_OPSAFE = np.array([75, 25, 0, 75, 20, 55, 0], float)
TOOLS_EXAMPLE = "# tools:\n#   - {name: probe"


def project_with(root: Path, default_tool: bool) -> tuple[Path, ArmDescription]:
    tools = "tools:\n  - {name: probe, xyz_mm: [0, 0, -120]}\n"
    if default_tool:
        tools += "default_tool: probe\n"
    project = make_project(root, arm_changes={TOOLS_EXAMPLE: tools + TOOLS_EXAMPLE})
    return project, load_arm(project / "arms" / "lwa3.yaml")


def target(arm: ArmDescription) -> str:
    """position_mm and rpy_deg of the probe's tip near Op-safe, as YAML."""
    frame = tool_pose(solver_for(arm, "probe"), NEAR_OPSAFE)
    xyz = [round(float(v), 4) for v in frame[:3, 3]]
    rpy = [round(float(v), 4) for v in np.degrees(rpy_from_matrix(frame[:3, :3]))]
    return f"position_mm: {xyz}, rpy_deg: {rpy}"


def validate(project: Path, arm: ArmDescription, steps: str):
    return validate_sequence(load_sequence(write_sequence(project, steps)), arm, PARK)


def test_a_checkpoint_at_the_point_a_move_went_to_checks_the_same_point(tmp_path):
    project, arm = project_with(tmp_path / "p", default_tool=True)
    steps = UP + f"- move: {{{target(arm)}}}\n- checkpoint: {{{target(arm)}}}\n"
    assert validate(project, arm, steps).errors == []
    run = dry_run(load_sequence(write_sequence(project, steps)), arm, PARK)
    assert run.result.exit_code == 0, run.result.message
    detail = run.result.steps[-1].detail
    assert detail["tool"] == "probe"
    assert detail["position_error_mm"] < 1.0  # the probe's tip, not 120 mm off


def test_an_absolute_checkpoint_takes_a_tool(tmp_path):
    project, arm = project_with(tmp_path / "p", default_tool=False)
    steps = (UP + f"- move: {{{target(arm)}, tool: probe}}\n"
             f"- checkpoint: {{{target(arm)}, tool: probe}}\n")
    assert validate(project, arm, steps).errors == []
    run = dry_run(load_sequence(write_sequence(project, steps)), arm, PARK)
    assert run.result.exit_code == 0, run.result.message


def test_without_the_tool_the_checkpoint_checks_the_end_effector_and_says_so(tmp_path):
    project, arm = project_with(tmp_path / "p", default_tool=False)
    steps = UP + f"- move: {{{target(arm)}, tool: probe}}\n- checkpoint: {{{target(arm)}}}\n"
    [error] = validate(project, arm, steps).errors
    assert (error.line, error.column) == (10, 3)
    assert "after the moves before it the end-effector is at" in error.message
    assert ", 120 mm and " in error.message  # the probe's length


def test_a_pose_checkpoint_checks_the_tool_too(tmp_path):
    project, arm = project_with(tmp_path / "p", default_tool=True)
    steps = UP + "- checkpoint: opsafe\n- checkpoint: {pose: opsafe, tool: probe}\n"
    assert validate(project, arm, steps).errors == []
    run = dry_run(load_sequence(write_sequence(project, steps)), arm, PARK)
    assert run.result.exit_code == 0, run.result.message
    first, second = run.result.steps[-2].detail, run.result.steps[-1].detail
    expected = tool_pose(solver_for(arm, "probe"), [70, 30, 0, 70, 20, 50, 0])[:3, 3]
    for detail in (first, second):
        assert detail["expected_position_mm"] == pytest.approx(expected.tolist(), abs=1e-3)


def test_an_unknown_tool_on_a_checkpoint_is_an_error_at_the_tool(tmp_path):
    project, arm = project_with(tmp_path / "p", default_tool=False)
    result = validate(project, arm, UP + "- checkpoint: {pose: opsafe, tool: gripper}\n")
    [error] = result.errors
    assert (error.line, error.column) == (9, 36)  # at the value
    assert error.message == "unknown tool 'gripper' (the arm file's tools: probe)"


def test_frame_still_belongs_to_a_relative_checkpoint(tmp_path):
    project, _ = project_with(tmp_path / "p", default_tool=False)
    with pytest.raises(SequenceInvalid) as info:
        load_sequence(write_sequence(project, "- checkpoint: {pose: opsafe, frame: tool}\n"))
    [error] = info.value.errors
    assert error.message == "frame belongs to a relative checkpoint (moved_mm)"
