"""Static validation checks the workspace guards along the trajectory the executor streams
(the ruckig plan), not along the straight line in joint space (issue 16, item 6)."""

from __future__ import annotations


import numpy as np
import pytest

from projecttree import ROOT, shipped_arm
from seqrun.arm.description import GeometrySpec
from seqrun.service.dryrun import dry_run
from seqrun.arm.kinematics import Chain, point_positions
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence

# The guard planes alone: the arm file's link volumes would also refuse this move (the
# hand's capsule touches the desk), which would hide what is tested here.
ARM = shipped_arm().model_copy(update={"geometry": GeometrySpec()})
PARK = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
# From Park, low over the desk: on the straight line in joint space the lowest watched point
# stays 13.0 mm above the desk (guard: 10 mm); ruckig's time-synchronized path takes the
# end-effector down to 6.9 mm.
DIPPING = {"j1": -31, "j2": -84, "j4": -100, "j5": -9, "j6": 79, "j7": 3}
STEPS = "- reset\n- home\n- set_limits\n- move: {joints: %s}\n" % (
    "{" + ", ".join(f"{k}: {v}" for k, v in DIPPING.items()) + "}")


@pytest.fixture
def sequence(tmp_path):
    (tmp_path / "poses").mkdir()
    for pose in (ROOT / "poses").glob("*.yaml"):
        (tmp_path / "poses" / pose.name).write_text(pose.read_text())
    (tmp_path / "sequences").mkdir()
    path = tmp_path / "sequences" / "dip.yaml"
    path.write_text("name: dip\ndescription: low over the desk\nsteps:\n" + STEPS)
    return load_sequence(path)


def test_the_straight_line_in_joint_space_stays_above_the_guard():
    """The premise: the old check (64 samples of the straight line) found nothing."""
    chain = Chain.from_arm(ARM)
    start = np.array(list(PARK.values()), float)
    end = start.copy()
    for name, value in DIPPING.items():
        end[ARM.index(name)] = value
    line = start + (end - start) * np.linspace(0, 1, 65)[:, None]
    points = point_positions(chain, np.radians(line))
    lowest = min(points[p][:, 2].min() for p in ("wrist", "end_effector"))
    assert 12.5 < lowest < 13.5


def test_static_validation_refuses_a_move_whose_plan_dips_below_a_guard(sequence):
    result = validate_sequence(sequence, ARM, PARK)
    [error] = result.errors
    assert (error.line, error.column) == (7, 3)  # the move step
    assert "end-effector down to z = 6.88 mm" in error.message
    assert "planned trajectory" in error.message and "'desk' guard at 10 mm" in error.message
    clearance = result.clearances[4]
    assert clearance.point == "end_effector" and clearance.margin_mm == pytest.approx(-3.1, abs=0.1)
    assert 0 < clearance.t_s < clearance.duration_s


def test_the_executor_refuses_it_too_before_anything_moves(sequence):
    """The executor re-validates from the measured state (preflight): same finding."""
    run = dry_run(sequence, ARM, PARK)
    assert run.result.status == "invalid" and run.result.exit_code == 1
    assert "end-effector down to z = 6.88 mm" in run.result.message
    assert run.result.min_heights_mm == {}  # nothing was streamed


def test_without_the_check_the_run_halts_at_the_guard_where_the_plan_said(sequence, monkeypatch):
    """What the static check predicts is what the run does: with the guard check along the
    plan switched off, the executor streams the move and its runtime guard halts it."""
    from seqrun.sequence import validation

    monkeypatch.setattr(validation.Checker, "guards_along_plan", lambda *a: None)
    run = dry_run(sequence, ARM, PARK)
    assert run.result.exit_code == 3
    assert run.result.fault["cause"] == "workspace_guard"
    assert "end_effector at z = 9." in run.result.message  # halted on crossing 10 mm


def test_a_move_clear_of_the_guards_reports_its_smallest_clearance(tmp_path, sequence):
    path = sequence.path.parent / "ok.yaml"
    path.write_text("name: ok\ndescription: up\nsteps:\n- reset\n- home\n- set_limits\n"
                    "- move: totem\n")
    result = validate_sequence(load_sequence(path), ARM, PARK)
    assert result.errors == []
    clearance = result.clearances[4]
    assert clearance.margin_mm > 0 and clearance.guard == "desk"
    assert clearance.t_s == pytest.approx(0.0, abs=0.5)  # lowest at the start, in Park
