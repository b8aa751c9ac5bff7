"""Issue 39 (items 1-2): expressions over the telemetry, ``wait_until`` and ``check``.

The expression language is checked when the file is loaded (names, joint numbers, types,
units; every problem at file:line:col) and evaluated against the run's own readings, in
the dry run and in a run at virtual time alike."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from projecttree import shipped_arm, write_sequence
from seqrun.errors import SequenceInvalid
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence
from seqrun.service.dryrun import dry_run
from seqrun.steps.expressions import ExpressionError, parse
from simrun import run_on_sim
from tiers import examples

ARM = shipped_arm()
PARK = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
UP = "- reset\n- home\n- set_limits\n"  # lines 4-6


# --------------------------------------------------------------------------- the language
@pytest.mark.parametrize("text, values, expected", [
    ("tool.z_mm > 40", {"tool.z_mm": 41.0}, True),
    ("tool.z_mm > 40", {"tool.z_mm": 40.0}, False),
    ("-5 < pos_deg[1] < 5", {"pos_deg": [4.9, 0, 0]}, True),
    ("-5 < pos_deg[1] < 5", {"pos_deg": [5.0, 0, 0]}, False),
    ("abs(following_error_deg[2]) < 0.5 and not moving",
     {"following_error_deg": [9, -0.4], "moving": False}, True),
    ("max(pos_deg[1], pos_deg[2]) - min(pos_deg[1], pos_deg[2]) >= 3",
     {"pos_deg": [1.0, 4.0]}, True),
    ("gripper.holding == true or step_time_s > 2 * 1.5",
     {"gripper.holding": False, "step_time_s": 3.1}, True),
    ("pos_deg[2] / 2 + 1 == 2", {"pos_deg": [0, 2.0]}, True),
])
def test_expressions_evaluate_as_written(text, values, expected):
    assert parse(text, joints=7).evaluate(values) is expected


@pytest.mark.parametrize("text, message, column", [
    ("pos_deg[2] < tool.z_mm", "cannot compare deg and mm", 14),
    ("tool.z_mm + pos_deg[1] > 3", "cannot add or subtract mm and deg", 1),
    ("pos_deg[8] > 0", "joint number 8 is not one of the arm's (1 to 7)", 9),
    ("pos_deg[0] > 0", "joint number 0", 9),
    ("pos_deg[1.5] > 0", "a joint's number is a whole number", 9),
    ("pos_deg > 0", "pos_deg is per joint", 1),
    ("tool.q_mm > 0", "unknown name 'tool.q_mm'", 1),
    ("__import__('os').system('true')", "the only functions are abs, min and max", 1),
    ("open('x')", "the only functions are abs, min and max", 1),
    ("tool.__class__", "unknown name", 1),
    ("[1, 2]", "not part of the expression language", 1),
    ("'12' > 3", "is not a number", 1),
    ("True", "write true or false (lower case)", 1),
    ("moving > 1", "compares a bool with a number", 10),
    ("not tool.z_mm", "not needs a truth value", 5),
    ("tool.z_mm ** 2 > 1", "only + - * / are arithmetic here", 1),
    ("tool.z_mm > 1 if moving else 2", "no 'if' inside an expression", 1),
    ("abs(1, 2) > 0", "abs takes one number", 1),
    ("tool.z_mm >", "not an expression", None),
    ("", "an expression is needed", 1),
])
def test_what_the_language_refuses_it_says_where(text, message, column):
    with pytest.raises(ExpressionError) as caught:
        parse(text, joints=7)
    assert message in caught.value.message
    assert caught.value.column == column if column is not None else caught.value.column >= 1


@settings(max_examples=examples(200), deadline=None)
@given(st.text(max_size=40))
def test_no_text_escapes_the_language(text):
    """Whatever the text, parsing either refuses it in one ExpressionError or gives an
    expression that reads only telemetry names (nothing else can be evaluated)."""
    try:
        expression = parse(text, joints=7)
    except ExpressionError as exc:
        assert exc.message and exc.column >= 1
        return
    from seqrun.steps.expressions import JOINT_SERIES, NAMES

    assert expression.names <= set(NAMES) | set(JOINT_SERIES)


# --------------------------------------------------------------------------- validation
def test_an_expression_that_mixes_units_is_refused_when_the_file_is_read(project):
    path = write_sequence(project, UP + """\
        - wait_until: {until: "pos_deg[2] < tool.z_mm", timeout_s: 5}
    """.replace("        ", ""))
    with pytest.raises(SequenceInvalid, match=r"s.yaml:7:23: cannot compare deg and mm "
                                              r"\(at column 14 of 'pos_deg\[2\] < tool.z_mm'\)"):
        load_sequence(path)


def test_every_expression_is_checked_against_the_arm_at_its_line(project):
    path = write_sequence(project, UP + """\
        - check: "pos_deg[9] > 1"
        - check: "tool.z_mm + 3"
        - wait_until: {until: "tool.z_mm > 40", timeout_s: 1, persist_s: 2}
        - wait_until: {until: "tool.z_mm > 40", timeout_s: 1, poll_hz: 1000}
    """.replace("        ", ""))
    errors = [str(e) for e in validate_sequence(load_sequence(path), ARM).errors]
    assert any(e.endswith("s.yaml:7:10: joint number 9 is not one of the arm's (1 to 7) "
                          "(at column 9 of 'pos_deg[9] > 1')") for e in errors), errors
    assert any("s.yaml:8:10: 'tool.z_mm + 3' is a number, not a condition" in e
               for e in errors), errors
    assert any("s.yaml:9:" in e and "persist_s 2 s is not shorter than timeout_s 1 s" in e
               for e in errors), errors
    assert any("s.yaml:10:" in e and "poll_hz 1000 is faster than the control loop" in e
               for e in errors), errors


def test_a_gripper_expression_on_an_arm_without_one_is_refused(tmp_path):
    from projecttree import make_project
    from seqrun.arm.description import load_arm

    text = (make_project(tmp_path / "with") / "arms" / "lwa3.yaml").read_text(encoding="utf-8")
    section = text[text.index("\ngripper:"):]
    root = make_project(tmp_path / "p", arm_changes={section: "\n"})
    arm = load_arm(root / "arms" / "lwa3.yaml")
    assert arm.gripper is None
    path = write_sequence(root, UP + "- check: gripper.holding\n")
    errors = [str(e) for e in validate_sequence(load_sequence(path), arm).errors]
    assert any(e.endswith("s.yaml:7:10: 'gripper.holding' reads the gripper, and the arm "
                          "file has none") for e in errors), errors


# --------------------------------------------------------------------------- the dry run
def test_the_dry_run_waits_until_the_arm_stands_still_and_checks_the_tool(project):
    path = write_sequence(project, UP + """\
        - move: totem
        - wait_until: {until: "abs(vel_deg_s[4]) < 0.01 and not moving", timeout_s: 5, persist_s: 0.2}
        - check: {that: "tool.z_mm > 40", verifies: [REQ-CAP-1]}
    """.replace("        ", ""))
    run = dry_run(load_sequence(path), ARM, PARK)
    assert run.result.exit_code == 0, run.result.message
    waited = run.result.steps[4].detail
    assert waited["held_s"] >= 0.2 and waited["waited_s"] < 1.0
    checked = run.result.steps[5].detail
    assert checked["passed"] is True and checked["verifies"] == ["REQ-CAP-1"]
    # Totem: the end-effector straight up, far above 40 mm
    assert checked["values"]["tool.z_mm"] > 900


def test_a_wait_until_that_times_out_halts_the_arm_with_exit_3(tmp_path, project):
    write_sequence(project, UP + '- wait_until: {until: "tool.z_mm > 5000", timeout_s: 0.3}\n',
                   "w.yaml")
    sim = run_on_sim("w", tmp_path, root=project)
    result = sim.outcome.result
    assert result.exit_code == 3 and result.steps[3].status == "failed"
    assert result.message == "wait_until: 'tool.z_mm > 5000' did not hold within 0.3 s"
    assert result.fault["halt_confirmed"] is True
    assert result.steps[3].detail["timed_out"] is True


def test_on_timeout_continue_goes_on_and_says_it_timed_out(tmp_path, project):
    write_sequence(project, UP + """\
        - wait_until: {until: "tool.z_mm > 5000", timeout_s: 0.2, on_timeout: continue}
        - check: "tool.z_mm < 5000"
    """.replace("        ", ""), "c.yaml")
    sim = run_on_sim("c", tmp_path, root=project)
    result = sim.outcome.result
    assert result.exit_code == 0, result.message
    assert result.steps[3].detail["timed_out"] is True
    assert result.steps[3].detail["waited_s"] == pytest.approx(0.2, abs=0.02)
    assert result.steps[4].status == "passed"


def test_a_failed_check_is_a_failed_checkpoint_with_the_values_it_read(tmp_path, project):
    write_sequence(project, UP + """\
        - check: {that: "pos_deg[2] > 0", message: the shoulder must be up, verifies: [REQ-7]}
    """.replace("        ", ""), "f.yaml")
    sim = run_on_sim("f", tmp_path, root=project)
    result = sim.outcome.result
    assert result.exit_code == 3
    assert result.message == "check failed: pos_deg[2] > 0 (the shoulder must be up)"
    detail = result.steps[3].detail
    assert detail["passed"] is False and detail["verifies"] == ["REQ-7"]
    assert detail["values"]["pos_deg[2]"] == pytest.approx(-90, abs=0.01)  # Park's j2


def test_a_following_error_before_any_move_has_no_value_and_says_so(tmp_path, project):
    """Nothing has been commanded yet: no target, so no following error to compare."""
    write_sequence(project, UP + """\
        - check: "abs(following_error_deg[1]) < 1"
    """.replace("        ", ""), "h.yaml")
    sim = run_on_sim("h", tmp_path, root=project)
    result = sim.outcome.result
    assert result.exit_code == 3
    assert "following_error_deg[1] has no value now" in result.message


# --------------------------------------------------------------------------- monitors
MOVE_UP = "- move: {pose: totem, monitors: [%s]}\n"


def test_a_monitor_that_holds_lets_the_step_run(tmp_path, project):
    write_sequence(project, UP + MOVE_UP % '{while: "abs(following_error_deg[4]) < 5"}',
                   "m.yaml")
    sim = run_on_sim("m", tmp_path, root=project)
    assert sim.outcome.result.exit_code == 0, sim.outcome.result.message


def test_a_halt_monitor_trips_before_the_runs_own_tracking_check(tmp_path, project):
    """A stuck j4 (no fault bit: the module just stops following) is caught by the run's
    own following-error check; a monitor with a tighter bound halts the arm earlier."""
    write_sequence(project, UP + "- move: totem\n", "plain.yaml")
    write_sequence(project, UP + MOVE_UP % (
        '{while: "abs(following_error_deg[4]) < 1.0", persist_cycles: 2, '
        'message: j4 lags its plan}'), "watched.yaml")
    plain = run_on_sim("plain", tmp_path / "a", root=project, faults=["4:stuck@0.5"])
    watched = run_on_sim("watched", tmp_path / "b", root=project, faults=["4:stuck@0.5"])
    assert plain.outcome.result.exit_code == 3
    result = watched.outcome.result
    assert result.exit_code == 3 and result.fault["halt_confirmed"] is True
    assert result.message.startswith("monitor 'abs(following_error_deg[4]) < 1.0' "
                                     "(j4 lags its plan) did not hold: following_error_deg[4] = ")
    assert result.fault["cause"] == "monitor"
    assert plain.outcome.result.fault["cause"] == "following_error"
    # the move's step ended (in the Halt) earlier with the monitor than without it
    assert result.steps[3].finished < plain.outcome.result.steps[3].finished - 0.1


def test_a_warn_monitor_warns_once_per_episode_and_the_run_goes_on(tmp_path, project):
    write_sequence(project, UP + MOVE_UP % '{while: "tool.z_mm < 500", action: warn}',
                   "w.yaml")
    sim = run_on_sim("w", tmp_path, root=project)
    assert sim.outcome.result.exit_code == 0, sim.outcome.result.message
    from runfolder import RunFolder

    tripped = [e for e in RunFolder(sim.outcome.log_dir).events()
               if e["type"] == "monitor_tripped"]
    assert len(tripped) == 1 and tripped[0]["action"] == "warn"
    assert tripped[0]["values"]["tool.z_mm"] >= 500


def test_a_monitor_on_the_gripper_is_refused_at_its_line(project):
    path = write_sequence(project, UP + '- wait: {seconds: 1, monitors: [{while: "gripper.holding"}]}\n')
    errors = [str(e) for e in validate_sequence(load_sequence(path), ARM).errors]
    assert any("s.yaml:7:" in e and "the gripper is not read every cycle" in e
               for e in errors), errors


def test_a_monitor_with_a_wrong_key_names_the_keys_as_written(project):
    path = write_sequence(project, UP + '- wait: {seconds: 1, monitors: [{whille: "moving"}]}\n')
    with pytest.raises(SequenceInvalid, match=r"unknown key 'whille' in monitor \(did you mean "
                                              r"'while'\? allowed: while, persist_cycles"):
        load_sequence(path)
