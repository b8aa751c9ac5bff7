"""Static validation against the arm; the broken files of tests/data/bad; random documents."""

from __future__ import annotations

import math
import tempfile
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from projecttree import ROOT, shipped_arm, write_sequence
from seqrun.sequence.checks import static_check
from seqrun.errors import SequenceInvalid, SourceError, UserInputError
from seqrun.arm.kinematics import Chain, matrix_from_rpy, point_positions, pose_from_user_deg
from seqrun.schema import CheckpointParams, MoveParams
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence
from seqrun.arm.poses import park_deg
from seqrun.steps.checkpoint import resolve_checkpoint
from seqrun.steps.move import resolve_move_target
from seqrun.yamlsource import display_path
from tiers import examples

BAD = ROOT / "tests" / "data" / "bad"
POSES = ROOT / "poses"
ARM = shipped_arm()
NO_GEOMETRY = ARM.model_copy(update={"geometry": ARM.geometry.model_copy(
    update={"capsules": [], "obstacles": []})})
PARK = park_deg(POSES)
TOTEM = {name: 0.0 for name in ARM.joint_names}
SHIPPED = ["startup", "totem", "opsafe", "park", "shutdown", "linear_approach"]
STARTUP = "- reset\n- home\n- set_limits\n"


def validate(project: Path, steps: str, start=None, started=False, arm=None):
    loaded = load_sequence(write_sequence(project, steps))
    return validate_sequence(loaded, arm or ARM, PARK if start is None else start,
                             started=started)


def where(items: list[SourceError]) -> list[tuple[int, int]]:
    return [(e.line, e.column) for e in items]


# --------------------------------------------------------------------------- bad files
#: file -> [(file it is reported in, line, column, words of the message)]
EXPECTED = {
    "out_of_limit.yaml": [("out_of_limit.yaml", 7, 33,
                           ["j2 target 130°", "outside its limits -120…120"])],
    "wrong_types.yaml": [
        ("wrong_types.yaml", 8, 20, ["expected a number, got 'ten'"]),
        ("wrong_types.yaml", 9, 17, ["expected true or false, got 'yes'", "YAML 1.2"]),
        ("wrong_types.yaml", 10, 23, ["expected a number, got 'fast'"]),
        ("wrong_types.yaml", 11, 21, ["expected a number, got a list"]),
        ("wrong_types.yaml", 12, 14, ["expected text, got 42"]),
    ],
    "unknown_step.yaml": [("unknown_step.yaml", 5, 5,
                           ["unknown step type 'mvoe'", "did you mean 'move'",
                            ("expected one of: reset, home, halt, set_limits, move, move_linear, "
                             "move_trajectory, move_velocity, wait, wait_until, checkpoint, "
                             "check, grip, release, check_gripper, confirm, power_off, signal, "
                             "wait_for, include")])],
    "unknown_key.yaml": [("unknown_key.yaml", 9, 7, ["unknown key 'velocty' in move",
                                                     "velocity_deg_s"])],
    "nan.yaml": [("nan.yaml", 7, 25, ["expected a finite number, got .nan"])],
    "inf.yaml": [("inf.yaml", 9, 18, ["expected a finite number, got .inf"])],
    "duplicate_keys.yaml": [("duplicate_keys.yaml", 10, 9,
                             ["duplicate key 'j1'", "first given at line 9"])],
    "unknown_pose.yaml": [("unknown_pose.yaml", 7, 18,
                           ["unknown pose 'tottem'", "opsafe", "park", "totem"])],
    "include_escape.yaml": [("include_escape.yaml", 4, 14,
                             ["include '../../../sequences/startup.yaml'",
                              "outside the sequences folder"])],
    "include_loop_a.yaml": [("include_loop_b.yaml", 5, 14, [
        "include loop: include_loop_a.yaml -> include_loop_b.yaml -> include_loop_a.yaml"])],
    # B homes before A's reset: a finding of its own, not hidden by the loop (issue 42)
    "include_loop_b.yaml": [("include_loop_a.yaml", 5, 14, [
        "include loop: include_loop_b.yaml -> include_loop_a.yaml -> include_loop_b.yaml"]),
        ("include_loop_b.yaml", 4, 5, ["home before reset"])],
    "syntax_error.yaml": [("syntax_error.yaml", 7, 1, ["a closing '}' is missing",
                                                       "line 5"])],
    "python_tag.yaml": [("python_tag.yaml", 5, 14, ["'!!python/object/apply:os.system'",
                                                    "not allowed"])],
    "billion_laughs.yaml": [("billion_laughs.yaml", 7, 36, ["alias bomb", "100000"])],
    "empty.yaml": [("empty.yaml", 1, 1, ["the file is empty"])],
    "not_utf8.yaml": [("not_utf8.yaml", 2, 32, ["not UTF-8", "0xe9"])],
    "locked_joint.yaml": [("locked_joint.yaml", 7, 29, ["j3 is locked at 0°",
                                                        "never commands it"])],
    "move_before_home.yaml": [("move_before_home.yaml", 6, 5, [
        "move before home: the modules refuse motion until Home"])],
    "velocity_above_max.yaml": [("velocity_above_max.yaml", 9, 28, [
        "velocity_deg_s of j1 45 deg/s", "above its maximum 30 deg/s"])],
}


def test_every_bad_file_has_an_expectation():
    assert {p.name for p in BAD.glob("*.yaml")} == set(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_bad_file_gives_the_expected_located_errors(name):
    check = static_check(BAD / name)
    assert not check.valid
    got = [(Path(e.file).name, e.line, e.column, e.message) for e in check.errors]
    assert len(got) == len(EXPECTED[name]), got
    for (file, line, col, message), (efile, eline, ecol, words) in zip(got, EXPECTED[name]):
        assert (file, line, col) == (efile, eline, ecol), message
        for word in words:
            assert word in message, message
    for error in check.errors:
        assert error.file == display_path(BAD / Path(error.file).name)


# --------------------------------------------------------------------------- shipped
@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_sequence_validates_from_park(name):
    check = static_check(ROOT / "sequences" / f"{name}.yaml")
    assert check.errors == []
    assert check.start_deg == PARK


@pytest.mark.parametrize("name", ["totem", "opsafe", "park", "shutdown"])
def test_shipped_motion_sequences_start_with_startup_from_park_within_the_limits(name):
    # Park's j4 (-120.32) is j4's lower limit in the arm file (issue 42): no note
    loaded = load_sequence(ROOT / "sequences" / f"{name}.yaml")
    assert [s.kind for s in loaded.steps[:3]] == ["reset", "home", "set_limits"]
    result = validate_sequence(loaded, ARM, PARK)
    assert result.errors == [] and result.notes == []


def test_opsafe_goes_via_totem_and_its_checkpoint_is_the_fk_of_opsafe():
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    moves = [s.params.pose for s in loaded.steps if s.kind == "move"]
    assert moves == ["totem", "opsafe"]
    [check] = [s.params for s in loaded.steps if s.kind == "checkpoint"]
    fk = pose_from_user_deg(ARM, [70, 30, 0, 70, 20, 50, 0])
    assert np.allclose(check.position_mm, fk.position_mm, atol=1e-3)
    assert np.allclose(check.rpy_deg, fk.rpy_deg, atol=1e-3)
    result = validate_sequence(loaded, ARM, PARK)
    assert result.final_deg == {"j1": 70, "j2": 30, "j3": 0, "j4": 70, "j5": 20, "j6": 50,
                                "j7": 0}


def test_the_numbers_in_the_opsafe_route_comment():
    """opsafe.yaml says: the direct move would pass the desk guard, with the wrist at
    >= 61 mm and the end-effector >= 48 mm, the wrist first sinking; from Totem on, 390 mm."""
    chain = Chain.from_arm(ARM)
    park = np.array(list(PARK.values()))
    opsafe = np.array([70, 30, 0, 70, 20, 50, 0.0])
    f = np.linspace(0, 1, 65)[:, None]
    direct = point_positions(chain, np.radians(park + (opsafe - park) * f))
    assert 61 <= direct["wrist"][:, 2].min() < direct["wrist"][0, 2]  # sinks, then rises
    assert 47.5 <= direct["end_effector"][:, 2].min() <= 48.5
    high = point_positions(chain, np.radians(opsafe * f))
    assert high["end_effector"][:, 2].min() >= 389
    assert all(high[p][:, 2].min() >= 389 for p in ("wrist", "end_effector", "flange"))


def test_direct_route_would_pass_static_validation(project):
    result = validate(project, STARTUP + "- move: opsafe\n")
    assert result.errors == []


# --------------------------------------------------------------------------- start state
#: An arm powered off 0.5° beyond j4's lower limit (Park's -120.32).
BEYOND = dict(PARK, j4=-120.82)


def test_start_outside_limits_is_a_note_at_the_move(project):
    # (the link volumes are left out: this move takes the forearm's capsule into the desk)
    result = validate(project, STARTUP + "- move: {joints: {j4: -100}}\n", start=BEYOND,
                      arm=NO_GEOMETRY)
    assert result.errors == []
    [note] = result.notes
    assert (note.line, note.column) == (7, 23)
    assert note.message == ("j4 starts at -120.82°, 0.5° outside its limit -120.32…120; this "
                            "move brings it back inside")


def test_moving_further_out_is_an_error(project):
    result = validate(project, STARTUP + "- move: {joints: {j4: -125}}\n")
    assert [e.message for e in result.errors] == [
        "j4 target -125° is outside its limits -120.32…120"]


def test_other_joints_may_move_while_one_is_still_outside(project):
    result = validate(project, STARTUP + "- move: {joints: {j1: 30}}\n", start=BEYOND)
    assert result.errors == [] and result.notes == []
    assert result.final_deg["j4"] == -120.82


def test_park_is_a_move_target(project):
    # Park's j4 is j4's lower limit (arms/lwa3.yaml says why): `move: park` gets there
    result = validate(project, STARTUP + "- move: totem\n- move: park\n- checkpoint: park\n")
    assert result.errors == [] and result.notes == []
    assert result.final_deg == PARK


def test_moving_a_pose_outside_the_limits_is_refused(project):
    # The pose file's value is what is out of range: the error is at its line, naming the
    # step that uses the pose as a target.
    pose = project / "poses" / "park.yaml"
    pose.write_text(pose.read_text(encoding="utf-8").replace("j4: -120.32", "j4: -120.82"),
                    encoding="utf-8")
    result = validate(project, STARTUP + "- move: totem\n- move: park\n")
    errors = [e for e in result.errors if e.message.startswith("j4 -120.82°")]
    [error] = errors
    assert Path(error.file).name == "park.yaml" and (error.line, error.column) == (14, 7)
    assert error.message.startswith("j4 -120.82° is outside its limits -120.32…120: pose "
                                    "'park' cannot be a move target (used at ")
    assert error.message.endswith("s.yaml:8:9)")


def test_start_state_problems(project):
    bad = dict(PARK, j1=math.nan)
    del bad["j2"]
    bad["j9"] = 0.0
    result = validate(project, STARTUP, start=bad)
    assert [e.message for e in result.errors] == [
        "start state: j1 is nan (a finite angle is needed for every unlocked joint)",
        "start state: j2 is missing (a finite angle is needed for every unlocked joint)",
        "start state: unknown joint(s) j9 (the arm has j1, j2, j3, j4, j5, j6, j7)"]
    assert where(result.errors) == [(1, 1)] * 3


def test_started_arm_needs_no_startup(project):
    assert validate(project, "- move: totem\n", start=TOTEM, started=True).errors == []
    assert validate(project, "- move: totem\n", start=TOTEM).errors != []


# --------------------------------------------------------------------------- start-up order
@pytest.mark.parametrize("steps, line, message", [
    ("- reset\n- home\n- move: totem\n", 6,
     ("move before set_limits: write the joint limits first (the modules' stored limits are "
     "narrower than the arm file's)")),
    ("- home\n- reset\n- set_limits\n", 4,
     ("home before reset: reset the modules first (Reset clears the error state they power "
     "up with)")),
    ("- set_limits\n- reset\n- home\n", 4,
     "set_limits before reset: the modules accept parameters only after Reset"),
    ("- move: totem\n", 4,
     "move before home: the modules refuse motion until Home; reset them first, then home"),
    (STARTUP + "- halt\n- move: totem\n", 8,
     "move after halt: the modules refuse motion until Reset"),
    ("- reset\n- home: [j1]\n- set_limits\n- move: {joints: {j1: 5, j2: -80}}\n", 7,
     "move before home (j2): the modules refuse motion until Home"),
])
def test_start_up_order(project, steps, line, message):
    result = validate(project, steps)
    assert [(e.line, e.message) for e in result.errors] == [(line, message)]


def test_reset_after_halt_allows_motion_again(project):
    result = validate(project, STARTUP + "- halt: [j1]\n- reset: [j1]\n- move: {joints: {j1: 5}}\n")
    assert result.errors == []
    result = validate(project, STARTUP + "- halt: [j2]\n- move: {joints: {j1: 5}}\n")
    assert result.errors == []  # j2 is halted, but j1 is not


def test_per_joint_commands_check_names_and_the_locked_joint(project):
    result = validate(project, "- reset: [j1, j3, j9]\n")
    assert [(e.line, e.column, e.message) for e in result.errors] == [
        (4, 15, ("j3 is locked at 0°: a reset of a locked joint is not allowed (seqrun never "
                "commands it)")),
        (4, 19, "unknown joint 'j9' (the arm has j1, j2, j3, j4, j5, j6, j7)")]


# --------------------------------------------------------------------------- moves
def test_relative_moves_are_resolved_against_the_tracked_state(project):
    steps = STARTUP + textwrap.dedent("""\
        - move: {joints: {j1: 170}}
        - move: {joints: {j1: 5}, relative: true}
        - move: {joints: {j1: 10}, relative: true}
        - move: {joints: {j1: -20}, relative: true}
        """)
    result = validate(project, steps)
    assert [(e.line, e.column, e.message) for e in result.errors] == [
        (9, 23, "j1 target 185° (175° + 10°) is outside its limits -180…180")]
    assert result.final_deg["j1"] == 155  # 175 - 20: the refused move is not tracked as done


def test_unknown_and_locked_joints_in_a_move(project):
    result = validate(project, STARTUP + "- move: {joints: {j9: 1, j3: 0}, "
                                         "velocity_deg_s: {j3: 1}}\n")
    assert where(result.errors) == [(7, 19), (7, 26), (7, 51)]
    assert "unknown joint 'j9'" in result.errors[0].message
    assert "j3 is locked at 0°: moving a locked joint" in result.errors[1].message
    assert "a velocity for a locked joint" in result.errors[2].message


def test_set_limits_overrides(project):
    steps = """\
        - reset
        - home
        - set_limits:
            limits_deg: {j1: [-190, 90], j2: [-100, 100], j3: [-1, 1]}
            max_velocity_deg_s: {j1: 10, j2: 40}
            max_acceleration_deg_s2: {j2: 100}
        - move: {joints: {j2: 110}, velocity_deg_s: {j1: 20}}
        """
    result = validate(project, textwrap.dedent(steps))
    assert [(e.line, e.column, e.message) for e in result.errors] == [
        (7, 22, ("limits_deg of j1 -190…90 go beyond the arm's limits -180…180; an override "
                "may only narrow them")),
        (7, 51, ("j3 is locked at 0°: writing limits to a locked joint is not allowed (seqrun "
                "never commands it)")),
        (8, 38, "max_velocity_deg_s of j2 40 deg/s is above the arm's maximum 30 deg/s"),
        (9, 35, ("max_acceleration_deg_s2 of j2 100 deg/s^2 is above the arm's maximum 60 "
                "deg/s^2")),
        (10, 23, "j2 target 110° is outside the limits written by set_limits -100…100"),
        (10, 50, ("velocity_deg_s of j1 20 deg/s is above its maximum 10 deg/s (from "
                 f"set_limits at {display_path(project / 'sequences' / 's.yaml')}:6:3)")),
    ]


def test_workspace_guard_along_a_move(project):
    result = validate(project, STARTUP + "- move: totem\n- move: {joints: {j2: 90, j4: 90}}\n")
    # the link volumes find it too: the hand, the wrist and the forearm go into the desk
    # (every collision of the move, in time order, at the move's line)
    *collisions, error = result.errors
    assert [c.message.split(" (at")[0] for c in collisions] == [
        f"this move takes the {link} into the desk" for link in ("hand", "wrist", "forearm")]
    assert {(e.line, e.column) for e in result.errors} == {(8, 3)}
    assert error.message.startswith("this move takes the end-effector down to z = -155")
    assert "below the 'desk' guard at 10 mm" in error.message


# --------------------------------------------------------------------------- checkpoints
def test_checkpoint_that_cannot_pass(project):
    result = validate(project, STARTUP + "- move: totem\n- checkpoint: opsafe\n"
                                         "- checkpoint: totem\n")
    [error] = result.errors
    assert (error.line, error.column) == (8, 3)
    assert error.message.startswith("this checkpoint cannot pass: after the moves before it "
                                    "the end-effector is at [-0.006, -0.1, 1083]")


def test_checkpoint_tolerance_is_honoured(project):
    at_totem = pose_from_user_deg(ARM, TOTEM)
    x, y, z = at_totem.position_mm
    ok = f"- checkpoint: {{position_mm: [{x}, {y}, {z + 4}], rpy_deg: [180, 0, 0], " \
         "position_tolerance_mm: 5}\n"
    off = ok.replace("5}", "3}")
    assert validate(project, STARTUP + "- move: totem\n" + ok).errors == []
    assert len(validate(project, STARTUP + "- move: totem\n" + off).errors) == 1


# --------------------------------------------------------------------------- helpers
def test_resolve_move_target():
    current = dict(PARK)
    target = resolve_move_target(MoveParams(pose="opsafe"), current, ARM, POSES)
    assert target == {"j1": 70, "j2": 30, "j3": 0, "j4": 70, "j5": 20, "j6": 50, "j7": 0}
    rel = resolve_move_target(MoveParams(joints={"j1": 5, "j3": 9}, relative=True), target,
                              ARM, POSES)
    assert rel["j1"] == 75 and rel["j3"] == 0 and rel["j2"] == 30
    assert list(rel) == ARM.joint_names
    with pytest.raises(UserInputError, match="unknown joint 'j9'"):
        resolve_move_target(MoveParams(joints={"j9": 1}), target, ARM, POSES)
    with pytest.raises(UserInputError, match="unknown pose"):
        resolve_move_target(MoveParams(pose="nowhere"), target, ARM, POSES)


def test_resolve_checkpoint():
    position, rotation, pos_tol, ang_tol = resolve_checkpoint(
        CheckpointParams(pose="opsafe"), ARM, POSES)
    fk = pose_from_user_deg(ARM, [70, 30, 0, 70, 20, 50, 0])
    assert np.allclose(position, fk.position_mm) and np.allclose(rotation, fk.rotation)
    assert (pos_tol, ang_tol) == (7.0, 1.5)
    position, rotation, pos_tol, ang_tol = resolve_checkpoint(
        CheckpointParams(position_mm=[1, 2, 3], rpy_deg=[10, 20, 30], position_tolerance_mm=1,
                         angle_tolerance_deg=0.5), ARM, POSES)
    assert position.tolist() == [1, 2, 3] and (pos_tol, ang_tol) == (1, 0.5)
    assert np.allclose(rotation, matrix_from_rpy(np.radians([10, 20, 30])))


def test_validation_never_raises_for_a_broken_pose_file(project):
    (project / "poses" / "broken.yaml").write_text("name: broken\njoints_deg: {j1: x}\n")
    path = project / "sequences" / "s.yaml"
    path.write_text("name: T\ndescription: d\nsteps:\n- reset\n- move: broken\n")
    with pytest.raises(SequenceInvalid) as info:
        load_sequence(path)
    files = {Path(e.file).name for e in info.value.errors}
    assert files == {"broken.yaml", "s.yaml"}


# --------------------------------------------------------------------------- random documents
_scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6), st.integers(),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
    st.sampled_from(["all", "totem", "opsafe", "park", "nowhere", "j1", "j3", "j9",
                     "in_position", "startup.yaml", "../x.yaml", "s.yaml", "yes", "1:30"]))
_keys = st.sampled_from(["pose", "joints", "relative", "velocity_deg_s", "velocity_scale",
                         "acceleration_scale", "tolerance_deg", "timeout_s", "seconds",
                         "until", "position_mm", "rpy_deg", "position_tolerance_mm",
                         "angle_tolerance_deg", "prompt", "file", "label", "limits_deg",
                         "max_velocity_deg_s", "j1", "j2", "j3", "j4", "j9", "velocty"])
_values = st.recursive(_scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(_keys, inner, max_size=4)), max_leaves=12)
_kinds = st.sampled_from(["reset", "home", "halt", "set_limits", "move", "wait",
                          "checkpoint", "confirm", "include", "mvoe"])
_joint_targets = st.dictionaries(st.sampled_from(["j1", "j2", "j3", "j4", "j5", "j6", "j7"]),
                                 st.floats(-200, 200), min_size=1, max_size=4)
_good_steps = st.one_of(
    st.sampled_from(["reset", "home", "set_limits", "halt"]),
    st.builds(lambda p: {"move": p}, st.sampled_from(["totem", "opsafe", "park"])),
    st.builds(lambda j, r: {"move": {"joints": j, "relative": r}}, _joint_targets,
              st.booleans()),
    st.builds(lambda s: {"wait": s}, st.floats(0.01, 10)),
    st.builds(lambda p: {"checkpoint": p}, st.sampled_from(["totem", "opsafe"])),
    st.just({"confirm": "Ready?"}),
)
_any_steps = st.one_of(_good_steps, _values,
                       st.builds(lambda k, v: {k: v}, _kinds, _values))
_documents = st.one_of(
    st.builds(lambda steps: {"name": "R", "description": "random", "steps": steps},
              st.lists(_good_steps, min_size=1, max_size=8)),
    st.builds(lambda steps: {"name": "R", "description": "random", "steps": steps},
              st.lists(_any_steps, max_size=8)),
    _values,
)


@pytest.fixture(scope="module")
def fuzz_project():
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        (root / "poses").mkdir()
        for pose in POSES.glob("*.yaml"):
            (root / "poses" / pose.name).write_text(pose.read_text())
        (root / "sequences").mkdir()
        (root / "sequences" / "startup.yaml").write_text(
            "name: S\ndescription: s\nsteps: [reset, home, set_limits]\n")
        yield root


def _check_document(root: Path, text: str) -> None:
    path = root / "sequences" / "s.yaml"
    path.write_text(text, encoding="utf-8", errors="surrogateescape")
    try:
        loaded = load_sequence(path)
    except SequenceInvalid as exc:
        assert exc.errors
        for error in exc.errors:
            assert isinstance(error, SourceError)
            assert error.line >= 1 and error.column >= 1 and error.file and error.message
        event("invalid file")
        return
    result = validate_sequence(loaded, ARM, PARK)
    for item in result.errors + result.notes:
        assert item.line >= 1 and item.column >= 1 and item.message
    event("valid" if result.valid else "loads, fails validation")


@settings(max_examples=examples(150), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(document=_documents)
def test_random_documents_are_valid_or_located_errors(fuzz_project, document):
    _check_document(fuzz_project, yaml.safe_dump(document, allow_unicode=True))


@settings(max_examples=examples(150), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(base=st.sampled_from(SHIPPED), cut=st.integers(0, 2000), junk=st.text(max_size=6))
def test_mutated_shipped_files_are_valid_or_located_errors(fuzz_project, base, cut, junk):
    text = (ROOT / "sequences" / f"{base}.yaml").read_text(encoding="utf-8")
    cut = min(cut, len(text))
    _check_document(fuzz_project, text[:cut] + junk + text[cut:])
