"""End-effector targets in sequences: ``move`` to a tool pose and ``move_linear``.

Validation solves them (file:line:col errors for what cannot be done), the executor solves
them again from the measured joints; the dry runs here are the real executor on the
simulator at virtual time.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from projecttree import shipped_arm, write_sequence
from seqrun.arm.cartesian import LinearPath, resolve_target, solver_for, tool_pose
from seqrun.service.dryrun import dry_run
from seqrun.errors import SequenceInvalid
from seqrun.arm.kinematics import Chain, fk
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence

ARM = shipped_arm()
CHAIN = Chain.from_arm(ARM)
PARK = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
OPSAFE = np.array([70, 30, 0, 70, 20, 50, 0], float)
UP = "- reset\n- home\n- set_limits\n- move: totem\n- move: opsafe\n"  # lines 4-8


def load(project: Path, steps: str, name: str = "s.yaml"):
    return load_sequence(write_sequence(project, steps, name))


def messages(items) -> list[str]:
    return [f"{e.line}:{e.column}: {e.message}" for e in items]


# --------------------------------------------------------------------------- validation
def test_absolute_tool_pose_is_solved_nearest_the_tracked_joints(project):
    frame = fk(CHAIN, np.radians(OPSAFE + [5, -5, 0, 5, 0, 5, 0]))
    from seqrun.arm.kinematics import rpy_from_matrix

    xyz, rpy = frame[:3, 3].tolist(), np.degrees(rpy_from_matrix(frame)).tolist()
    result = validate_sequence(load(project, UP + f"- move: {{position_mm: {xyz}, "
                                                  f"rpy_deg: {rpy}}}\n"), ARM, PARK)
    assert result.errors == []
    solution = result.targets_deg[6]
    assert solution == pytest.approx(OPSAFE + [5, -5, 0, 5, 0, 5, 0], abs=1e-3)
    assert [result.final_deg[n] for n in ARM.joint_names] == pytest.approx(solution)
    [note] = [n for n in result.notes if "solved" in n.message]
    assert (note.line, note.column) == (9, 23)  # at position_mm
    assert "j1 75°" in note.message and "j2 25°" in note.message


def test_relative_tool_frame_move_goes_along_the_tool_axis(project):
    result = validate_sequence(load(project, UP + "- move: {position_mm: [0, 0, -50], "
                                                  "relative: true, frame: tool}\n"), ARM, PARK)
    assert result.errors == []
    before, after = fk(CHAIN, np.radians(OPSAFE)), fk(CHAIN, np.radians(result.targets_deg[6]))
    moved = after[:3, 3] - before[:3, 3]
    assert moved == pytest.approx(-50 * before[:3, 2], abs=1e-3)
    assert np.allclose(after[:3, :3], before[:3, :3], atol=1e-8)


def test_unreachable_target_is_an_error_at_its_position(project):
    result = validate_sequence(load(project, UP + "- move: {position_mm: [0, 0, 2000], "
                                                  "rpy_deg: [0, 0, 0]}\n"), ARM, PARK)
    [error] = result.errors
    assert (error.line, error.column) == (9, 23)
    assert error.message.startswith("end-effector target unreachable: no configuration inside "
                                    "the joint limits reaches the target (closest found:")


def test_unknown_tool_is_an_error_at_the_tool(project):
    result = validate_sequence(load(project, UP + "- move: {position_mm: [0, 0, 10], "
                                                  "relative: true, tool: gripper}\n"), ARM, PARK)
    assert messages(result.errors) == [
        "9:57: unknown tool 'gripper' (the arm file's tools: none defined)"]


def test_a_target_outside_narrowed_limits_is_refused(project):
    steps = ("- reset\n- home\n- set_limits: {limits_deg: {j1: [-60, 60]}}\n- move: totem\n"
             "- move: {joints: {j1: 50, j2: 30, j4: 70, j5: 20, j6: 50}}\n"
             "- move: {position_mm: [-136.305, 510.761, 389.804], "
             "rpy_deg: [-22.318, -27.505, 124.351]}\n")
    result = validate_sequence(load(project, steps), ARM, PARK)
    assert messages(result.errors) == [
        "9:23: the end-effector target puts j1 at 70°, outside the limits in force -60…60"]


@pytest.mark.parametrize("params, message", [
    ("{rpy_deg: [0, 0, 0], joints: {j1: 1}}", "rpy_deg belong to an end-effector target: give "
                                              "position_mm too"),
    ("{position_mm: [1, 2, 3]}", "an absolute end-effector target needs rpy_deg with "
                                 "position_mm"),
    ("{position_mm: [1, 2, 3], pose: totem}", "a move takes either position_mm or pose, not "
                                              "both"),
    ("{position_mm: [1, 2, 3], rpy_deg: [0, 0, 0], frame: tool}", "frame: tool is for relative "
                                                                  "targets (relative: true)"),
])
def test_malformed_tool_targets_are_located_errors(project, params, message):
    with pytest.raises(SequenceInvalid) as info:
        load(project, f"- move: {params}\n")
    [error] = info.value.errors
    assert (error.line, error.column) == (4, 9)
    assert error.message == message


def test_linear_move_is_checked_sample_by_sample(project):
    result = validate_sequence(load(project, UP + "- move_linear: {position_mm: [0, 0, -300], "
                                                  "relative: true, frame: tool, "
                                                  "speed_mm_s: 20}\n"), ARM, PARK)
    assert result.errors == []
    [note] = [n for n in result.notes if "solved" in n.message]
    assert "300.0 mm in 15.50 s" in note.message and "manipulability" in note.message
    clearance = result.clearances[6]
    assert clearance.duration_s == pytest.approx(15.5) and clearance.margin_mm > 100


@pytest.mark.parametrize("start, line, message", [
    # arm stretched out towards its reach: no solution beyond
    ({"j1": 0, "j2": 20, "j4": 40, "j6": -60}, "position_mm: [0, 0, -600], frame: tool",
     "straight line: the line leaves the workspace at 7% of the way"),
    # through the stretched-elbow singularity
    ({"j1": 0, "j2": 30, "j4": 60, "j6": 30}, "position_mm: [0, 0, -300], frame: base",
     "straight line: the line passes near a singular configuration at 54% of the way "
     "(manipulability 0.000, below the arm's 0.05)"),
    # into j4's limit
    ({"j1": 70, "j2": 30, "j4": 70, "j5": 20, "j6": 50}, "position_mm: [0, -300, 0], frame: base",
     "straight line: j4 reaches its limit 120° at 95% of the way"),
    # too fast for the joints
    ({"j1": 70, "j2": 30, "j4": 70, "j5": 20, "j6": 50},
     "position_mm: [0, 0, -300], frame: tool, speed_mm_s: 400, acceleration_mm_s2: 2000, "
     "jerk_mm_s3: 20000", "straight line: j2 would have to turn at 30.9 deg/s at 6% of the way (limit 28.5 deg/s)"),
])
def test_impossible_lines_are_errors_at_the_step(project, start, line, message):
    joints = ", ".join(f"{k}: {v}" for k, v in start.items())
    speed = "" if "speed_mm_s" in line else ", speed_mm_s: 20"
    steps = (f"- reset\n- home\n- set_limits\n- move: totem\n- move: {{joints: {{{joints}}}}}\n"
             f"- move_linear: {{relative: true, {line}{speed}}}\n")
    result = validate_sequence(load(project, steps), ARM, PARK)
    [error] = result.errors
    assert (error.line, error.column) == (9, 46)  # position_mm
    assert error.message.startswith(message), error.message


# --------------------------------------------------------------------------- dry runs
def test_linear_approach_stays_on_the_line_in_a_virtual_time_run(project):
    steps = UP + ("- move_linear: {position_mm: [0, 0, -300], relative: true, frame: tool, "
                  "speed_mm_s: 20, max_deviation_mm: 0.5}\n"
                  "- move: {position_mm: [0, 0, 50], relative: true, frame: tool}\n"
                  "- move: {position_mm: [-136.305, 510.761, 389.804], "
                  "rpy_deg: [-22.318, -27.505, 124.351]}\n"
                  "- checkpoint: {pose: opsafe, position_tolerance_mm: 0.5}\n")
    run = dry_run(load(project, steps), ARM, PARK)
    assert run.result.exit_code == 0, run.result.message
    linear = run.result.steps[5]
    assert linear.detail["length_mm"] == pytest.approx(300.0)
    assert 0 < linear.detail["max_deviation_mm"] <= 0.5
    assert linear.detail["executed_duration_s"] == pytest.approx(15.5, abs=0.5)
    # the joint solution is in the report, and it is the validated one
    assert len(run.result.steps[6].detail["ik_solution_deg"]) == 7
    assert run.result.steps[7].detail["ik_solution_deg"] == pytest.approx(OPSAFE, abs=1e-3)
    # where the line really ended: 300 mm along the tool axis from Op-safe
    end = [e for e in run.events if e["type"] == "step_finished" and e["step"] == 6][0]
    assert end["status"] == "passed"


def test_leaving_the_line_is_a_fault_with_a_halt(project):
    """Streamed with the ramp law the slow joints run ahead: 2.8 mm off, beyond 1 mm."""
    arm = ARM.model_copy(update={"cartesian": ARM.cartesian.model_copy(
        update={"linear_command_mode": "ramp"})})
    steps = UP + ("- move_linear: {position_mm: [0, 0, -300], relative: true, frame: tool, "
                  "speed_mm_s: 20, max_deviation_mm: 1}\n")
    run = dry_run(load(project, steps), arm, PARK)
    assert run.result.exit_code == 3
    assert run.result.fault["cause"] == "path_deviation"
    assert run.result.fault["halt_sent"] is True
    assert "off the straight line (allowed 1 mm)" in run.result.message


def test_a_run_time_solution_away_from_the_validated_one_is_a_fault(project, monkeypatch):
    from seqrun.sequence import validation

    arrive = validation.Checker.arrive

    def validated_elsewhere(self, step, joints_deg):
        arrive(self, step, joints_deg)
        self.targets_deg[step.number] = np.asarray(joints_deg) + 5.0

    monkeypatch.setattr(validation.Checker, "arrive", validated_elsewhere)
    steps = UP + "- move: {position_mm: [0, 0, -50], relative: true, frame: tool}\n"
    run = dry_run(load(project, steps), ARM, PARK)
    assert run.result.exit_code == 3
    assert run.result.fault["cause"] == "ik_mismatch"
    assert "from the validated" in run.result.message


# --------------------------------------------------------------------------- pure pieces
def test_relative_targets_in_base_and_tool_frames():
    current = fk(CHAIN, np.radians(OPSAFE))
    base = resolve_target(current, [10, 0, 0], [0, 0, 90], relative=True, frame="base")
    assert base[:3, 3] == pytest.approx(current[:3, 3] + [10, 0, 0])
    rz = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    assert base[:3, :3] == pytest.approx(rz @ current[:3, :3])
    tool = resolve_target(current, [0, 0, 10], None, relative=True, frame="tool")
    assert tool[:3, 3] == pytest.approx(current[:3, 3] + 10 * current[:3, 2])


def test_path_deviation_is_the_distance_from_the_segment():
    a, b = np.eye(4), np.eye(4)
    b[:3, 3] = [100, 0, 0]
    path = LinearPath(a, b)
    points = np.array([[50, 3, 4], [-3, 4, 0], [110, 0, 0]], float)
    assert path.deviation_mm(points) == pytest.approx([5, 5, 10])


def test_tool_pose_matches_forward_kinematics():
    solver = solver_for(ARM, None)
    assert tool_pose(solver, OPSAFE) == pytest.approx(fk(CHAIN, np.radians(OPSAFE)))


# --------------------------------------------------------------------------- relative checkpoints
APPROACH = UP + ("- move_linear: {position_mm: [0, 0, -100], relative: true, frame: tool, "
                 "speed_mm_s: 20}\n")


def test_relative_checkpoint_passes_validation_and_the_run(project):
    steps = APPROACH + "- checkpoint: {moved_mm: [0, 0, -100], frame: tool, position_tolerance_mm: 0.5}\n"
    loaded = load(project, steps)
    assert validate_sequence(loaded, ARM, PARK).errors == []
    run = dry_run(loaded, ARM, PARK)
    assert run.result.exit_code == 0, run.result.message
    detail = run.result.steps[-1].detail
    assert detail["moved_mm"] == pytest.approx([0, 0, -100], abs=0.5)
    assert detail["displacement_error_mm"] <= 0.5


def test_relative_checkpoint_that_cannot_pass_is_located(project):
    steps = APPROACH + "- checkpoint: {moved_mm: [0, 0, 100], frame: tool}\n"
    result = validate_sequence(load(project, steps), ARM, PARK)
    [error] = result.errors
    assert (error.line, error.column) == (10, 26)  # moved_mm
    # IK meets the line's end within 1e-3 mm: -99.999 or -100 as rounded to 3 decimals
    assert re.match(r"this checkpoint cannot pass: the last move takes the tool by "
                    r"\[0, 0, -(99\.999|100)\] mm \(tool frame\), (199\.999|200) mm from the "
                    r"expected \[0, 0, 100\] \(tolerance 7 mm\)$", error.message), error.message


def test_relative_checkpoint_in_the_base_frame(project):
    steps = APPROACH + "- checkpoint: {moved_mm: [0, 0, -100]}\n"
    result = validate_sequence(load(project, steps), ARM, PARK)
    # the tool's z at Op-safe points mostly up-and-sideways, so in base coordinates the
    # displacement is not [0, 0, -100]
    [error] = result.errors
    assert "(base frame)" in error.message
