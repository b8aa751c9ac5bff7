"""The checks the commands run before anything moves (seqrun/sequence/checks.py), without the CLI."""

from __future__ import annotations

from pathlib import Path

from seqrun.arm.description import load_arm
from seqrun.sequence.checks import static_check, static_validation
from seqrun.sequence.loader import load_sequence

ROOT = Path(__file__).resolve().parents[1]
OPSAFE = ROOT / "sequences" / "opsafe.yaml"
ARM = load_arm(ROOT / "arms" / "lwa3.yaml")


def test_split_at_gives_the_steps_before_and_from_a_step():
    loaded = load_sequence(OPSAFE)
    before, rest = loaded.split_at(6)
    assert [s.number for s in before.steps] == [1, 2, 3, 4, 5]
    assert [s.number for s in rest.steps] == list(range(6, len(loaded.steps) + 1))
    assert before.poses == rest.poses == loaded.poses and rest.file == loaded.file


def test_from_a_step_starts_where_the_steps_before_leave_the_arm():
    """Step 6 of opsafe.yaml (Totem -> Op-safe) is valid after steps 1-5; from Park with
    nothing before it, the modules are neither reset nor homed."""
    loaded = load_sequence(OPSAFE)
    assert [s.kind for s in loaded.steps[4:6]] == ["move", "move"]
    assert static_validation(loaded, ARM, None, False, 6).errors == []
    assert static_check(OPSAFE).valid
    before, rest = loaded.split_at(6)
    from seqrun.sequence.validation import validate_sequence
    from seqrun.arm.poses import park_deg

    cold = validate_sequence(rest, ARM, park_deg(loaded.pose_path), started=False)
    assert any("move before home" in e.message for e in cold.errors)


def test_static_check_reports_load_and_arm_errors_in_one_pass(tmp_path):
    (tmp_path / "poses").mkdir()
    for pose in (ROOT / "poses").glob("*.yaml"):
        (tmp_path / "poses" / pose.name).write_text(pose.read_text())
    (tmp_path / "sequences").mkdir()
    path = tmp_path / "sequences" / "two.yaml"
    path.write_text("name: two\ndescription: one bad on its own, one bad for the arm\n"
                    "steps:\n  - wait: -1\n  - move: {joints: {j9: 3}}\n")
    check = static_check(path)
    assert [(e.line, e.message.split(" (")[0]) for e in check.errors] == [
        (4, "must be greater than 0, got -1"), (5, "unknown joint 'j9'")]
