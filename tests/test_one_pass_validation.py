"""All problems in one pass (issue 42): a step that fails its schema never hides the
findings of the steps that parsed, and every collision along a move (the hand's, the
tool's, each guard's) is reported, in the order it happens, at the move's file:line:col.
"""

from __future__ import annotations

from pathlib import Path

from projecttree import make_project, write_sequence
from seqrun.sequence.checks import static_check

UP = "- reset\n- home\n- set_limits\n"  # lines 4-6
WRONG_SIGN = ("- move_velocity: {velocity_deg_s: {j1: -5}, duration_s: 2, "
              "envelope_deg: {j1: [0, 20]}}\n")
#: The commented example of arms/lwa3.yaml, replaced by a test's own tool.
TOOLS_EXAMPLE = "# tools:\n#   - {name: probe"
PROBE = "tools:\n  - {name: probe, xyz_mm: [0, 0, -400]}\ndefault_tool: probe\n"


def found(path: Path) -> list[str]:
    return [f"{e.line}:{e.column}: {e.message}" for e in static_check(path).errors]


def test_a_schema_error_does_not_hide_a_wrong_sign_in_another_step(project):
    path = write_sequence(project, UP + "- move: totem\n- wait: {seconds: \"3\"}\n"
                          + WRONG_SIGN)
    errors = found(path)
    assert errors[0] == "8:19: expected a number, got '3' (remove the quotes)"
    assert len(errors) == 2, errors
    assert errors[1].startswith("9:40: j1 at -5 deg/s for 2 s comes to rest at -10°")


def test_a_schema_error_does_not_hide_the_start_up_order(project):
    # the broken step is a wait: it changes neither the modules' state nor the joints
    path = write_sequence(project, "- wait: {seconds: -1}\n- move: totem\n")
    errors = found(path)
    assert errors[0] == "4:19: must be greater than 0, got -1"
    assert any(e.startswith("5:3: ") and "reset" in e for e in errors), errors


def test_after_a_broken_move_the_joints_are_known_again_after_an_absolute_move(project):
    # the broken move may have put j1 anywhere: the velocity move right after it is not
    # judged; after the move to Totem it is
    path = write_sequence(project, UP + "- move: {joints: {j1: 10}, velocity_scale: 2}\n"
                          + WRONG_SIGN + "- move: totem\n" + WRONG_SIGN)
    errors = found(path)
    assert [e.split(": ")[0] for e in errors] == ["7:44", "10:40"], errors
    assert "comes to rest at -10°" in errors[1]


def test_a_broken_include_leaves_what_it_may_do_unknown_but_checks_the_rest(project):
    path = write_sequence(project, "- include: nosuch.yaml\n- move: totem\n"
                          "- move: {joints: {j1: 400}}\n")
    errors = found(path)
    assert errors[0].startswith("4:12: include 'nosuch.yaml': no such file")
    # the start-up may be in the missing file: no "before reset" finding; the limit is one
    assert errors[1:] == ["6:23: j1 target 400° is outside its limits -180…180"], errors


def test_every_collision_of_a_move_with_a_tool_in_time_order(tmp_path):
    project = make_project(tmp_path / "p",
                           arm_changes={TOOLS_EXAMPLE: PROBE + "\n" + TOOLS_EXAMPLE})
    path = write_sequence(project, UP + "- move: totem\n- move: {joints: {j2: 90, j4: 90}}\n")
    errors = found(path)
    assert all(e.startswith("8:3: this move takes the ") for e in errors), errors
    shown = [e.split("this move takes the ")[1].split(" (at ")[0] for e in errors]
    # the hand hits the desk too, not only the tool hanging below it
    assert "hand into the desk" in shown, shown
    assert "tool probe into the desk" in shown, shown
    assert any(s.startswith("end-effector down to z = ") for s in shown), shown
    assert any(s.startswith("tool probe down to z = ") for s in shown), shown
    times = [float(e.split(" (at ")[1].split(" s of")[0]) for e in errors]
    assert times == sorted(times), errors
