"""What static validation must find (issue 9 items 14-15, issue 16 items 13 and 15): every
problem in one pass, pose files checked on their own at their own lines, bounded waits,
steps that can never pass, move timeouts shorter than their plan."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from projecttree import shipped_arm
from seqrun.sequence.checks import static_check
from seqrun.clock import VirtualClock
from seqrun.service.connection import open_connection
from seqrun.service.dryrun import dry_run
from seqrun.errors import RunAborted
from seqrun.arm.planner import Limits
from seqrun.service.runner import build_executor
from seqrun.sequence.loader import load_sequence
from seqrun.formatting import format_number

ARM = shipped_arm()
HEAD = "name: T\ndescription: test\nsteps:\n  - include: startup.yaml\n"


def write(project: Path, steps: str, name: str = "s.yaml") -> Path:
    path = project / "sequences" / name
    path.write_text(HEAD + textwrap.indent(textwrap.dedent(steps), "  "))
    return path


def found(check) -> list[tuple[str, int, int, str]]:
    return [(Path(e.file).name, e.line, e.column, e.message) for e in check.errors]


# --------------------------------------------------------------------------- one pass
def test_every_problem_is_reported_in_one_pass(project):
    path = write(project, """\
        - movve: totem
        - move: totme
        - move: {joints: {j9: 10}}
        - move: {joints: {j3: 10}}
        - move: {joints: {j1: 500}}
        """)
    got = found(static_check(path))
    lines = {line: message for _, line, _, message in got}
    assert "unknown step type 'movve'" in lines[5]
    assert "unknown pose 'totme'" in lines[6]
    assert "unknown joint 'j9'" in lines[7]
    assert "j3 is locked" in lines[8]
    assert "j1 target 500° is outside its limits -180…180" in lines[9]
    assert len(got) == 5, got  # nothing that follows from a step being left out


# --------------------------------------------------------------------------- pose files
def _edit_pose(project: Path, name: str, old: str, new: str) -> None:
    path = project / "poses" / f"{name}.yaml"
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


def test_a_pose_file_is_checked_against_the_arm_at_its_own_line(project):
    _edit_pose(project, "opsafe", "  j2: 30.0", "  j2: 130.0")
    path = write(project, "- move: totem\n- move: opsafe\n")
    got = found(static_check(path))
    # at the value in the pose file; its stored end-effector no longer agrees either
    assert [(f, line, col) for f, line, col, _ in got] == [
        ("opsafe.yaml", 10, 7), ("opsafe.yaml", 18, 16), ("opsafe.yaml", 19, 12)], got
    assert got[0][3].startswith("j2 130° is outside its limits -120…120: pose 'opsafe' "
                                "cannot be a move target (used at ")


def test_a_pose_whose_end_effector_disagrees_with_its_joints_is_an_error(project):
    _edit_pose(project, "opsafe", "[-136.305, 510.761, 389.804]", "[-136.305, 510.761, 400.0]")
    path = write(project, "- move: totem\n- move: opsafe\n")
    got = found(static_check(path))
    assert [(f, line, col) for f, line, col, _ in got] == [("opsafe.yaml", 18, 16)], got
    assert "from forward kinematics" in got[0][3]


def test_a_pose_missing_a_joint_is_an_error(project):
    _edit_pose(project, "opsafe", "  j7: 0.0\n", "")
    path = write(project, "- move: totem\n- checkpoint: opsafe\n")
    got = found(static_check(path))
    assert [(f, line, col) for f, line, col, _ in got] == [("opsafe.yaml", 8, 1)], got
    assert got[0][3] == "missing joint(s) j7"


# --------------------------------------------------------------------------- bounds
def test_a_wait_longer_than_the_arm_file_allows_is_an_error(project):
    path = write(project, "- wait: 1e9\n- wait: {until: in_position, timeout_s: 1e6}\n")
    got = found(static_check(path))
    assert [(f, line, col) for f, line, col, _ in got] == [("s.yaml", 5, 11), ("s.yaml", 6, 43)]
    assert got[0][3] == ("seconds 1e+09 s is longer than the arm file allows "
                         "(control.max_wait_s = 600 s)")
    assert got[1][3].startswith("timeout_s 1e+06 s is longer")


def test_the_dry_run_stops_at_its_simulated_time_limit(project):
    path = write(project, "- wait: 20\n- wait: 20\n")
    check = static_check(path)
    assert check.valid, check.errors
    run = dry_run(check.loaded, check.arm, check.start_deg, time_limit_s=30)
    assert not run.passed
    assert run.result.fault["cause"] == "time_limit"
    assert "stopped after 30 s of simulated time (control.max_dry_run_s" in run.result.message
    assert run.simulated_s < 31


# --------------------------------------------------------------------------- can never pass
def test_a_checkpoint_or_wait_after_a_halt_can_never_pass(project):
    path = write(project, "- halt\n- checkpoint: park\n- wait: 1\n- reset\n- wait: 1\n")
    got = found(static_check(path))
    assert [(line, message.split(":")[0]) for _, line, _, message in got] == [
        (6, "checkpoint after halt"), (7, "wait after halt")]


def test_a_move_timeout_shorter_than_its_plan_is_an_error(project):
    path = write(project, "- move: {pose: totem, timeout_s: 2}\n")
    got = found(static_check(path))
    assert [(line, col) for _, line, col, _ in got] == [(5, 36)]
    assert got[0][3].startswith("timeout_s 2 s is shorter than the move, planned to take ")


def test_the_executor_refuses_a_move_longer_than_its_timeout(project):
    """The runtime side (a sequence that got past validation, e.g. with --from or a
    different start): nothing moves, the step faults."""
    connection = open_connection(force_sim=True, clock=VirtualClock())
    loaded = load_sequence(write(project, "- wait: 1\n"))
    executor, client = build_executor(loaded, ARM, connection)
    try:
        client.reset(None)
        client.home(None)
        before = dict(connection.bus.arm.positions())
        target = np.array([0.0] * 7)
        limits = Limits.from_arm(ARM)
        with pytest.raises(RunAborted, match="longer than its timeout_s 1 s; nothing was moved"):
            executor.move(target, executor.movable, limits, tolerance_deg=0.2, timeout_s=1.0)
        assert connection.bus.arm.positions() == before
    finally:
        client.close()
        connection.close()


# --------------------------------------------------------------------------- messages
def test_numbers_in_messages_keep_their_significant_digits():
    assert format_number(1e-06) == "1e-06"
    assert format_number(0.000123456) == "0.000123"
    assert format_number(0.0) == "0" and format_number(-0.0) == "0"
    assert format_number(389.8041) == "389.804"


def test_a_tight_checkpoint_says_how_far_off_it_is(project):
    path = write(project, """\
        - move: totem
        - checkpoint: {pose: totem, position_tolerance_mm: 0.000001, angle_tolerance_deg: 1}
        """)
    check = static_check(path)
    assert check.valid, check.errors
    run = dry_run(check.loaded, check.arm, check.start_deg)
    assert not run.passed
    message = run.result.message
    assert "(tolerance 1e-06 mm)" in message
    shown = message.split("end-effector ")[1].split(" mm")[0]
    assert float(shown) > 1e-06, message  # never "0.00 mm"


@pytest.mark.parametrize("unreachable", [
    "- move: {position_mm: [2000, 0, 500], rpy_deg: [0, 0, 0]}",
    "- move_linear: {position_mm: [2000, 0, 500], rpy_deg: [0, 0, 0], speed_mm_s: 50}",
])
def test_after_an_unreachable_target_later_checkpoints_add_no_second_error(project,
                                                                         unreachable):
    """Issue 23 (item 6): the checkpoint after an unreachable target said "cannot pass:
    after the moves before it the end-effector is at [Totem]", a second, misleading
    error: the run never gets past the unreachable step. A move to a whole pose after it
    makes the position known again."""
    path = write(project, f"""\
        - move: totem
        {unreachable}
        - checkpoint: {{position_mm: [2000, 0, 500], rpy_deg: [0, 0, 0]}}
        - checkpoint: {{moved_mm: [0, 0, 10]}}
        - move: {{joints: {{j2: 10}}, relative: true}}
        - move: opsafe
        - checkpoint: totem
        """)
    check = static_check(path)
    errors = found(check)
    assert len(errors) == 2, errors
    assert errors[0][1] == 6
    # After the move to Op-safe the position is known again: checked, and it is wrong.
    assert errors[1][1] == 11 and "this checkpoint cannot pass" in errors[1][3]
    notes = {e.line: e.message for e in check.notes}
    assert "not checked before the run: the run cannot get past step" in notes[7]
    assert "not checked before the run" in notes[8]
