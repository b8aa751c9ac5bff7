"""The sequence format: models, shorthand, JSON Schema, and load_sequence with includes."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest

from projecttree import ROOT, make_project
from seqrun.errors import SequenceInvalid, UserInputError
from seqrun.schema import (PARAMS_MODELS, STEP_KINDS, CheckpointParams, ConfirmParams, HaltParams,
                           MoveParams, ResetParams, Sequence, SetLimitsParams, WaitParams,
                           describe, sequence_json_schema)
from seqrun.sequence.loader import find_project_root, load_sequence
from seqrun.yamlsource import display_path

SHIPPED = [ROOT / "sequences" / f"{name}.yaml"
           for name in ("startup", "totem", "opsafe", "park", "shutdown", "linear_approach")]


@pytest.fixture
def project(tmp_path):
    """A project folder without a campaign (arms/, poses/, an empty sequences/)."""
    return make_project(tmp_path / "project", sequences=(), campaign=False)


def write(folder: Path, name: str, body: str) -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(body), encoding="utf-8")
    return path


def seq(steps: str, name: str = "T") -> str:
    return f"name: {name}\ndescription: test\nsteps:\n" + textwrap.dedent(steps)


def load_errors(path) -> list[tuple[str, int, int, str]]:
    with pytest.raises(SequenceInvalid) as info:
        load_sequence(path)
    return [(Path(e.file).name, e.line, e.column, e.message) for e in info.value.errors]


# --------------------------------------------------------------------------- shorthand
def test_shorthand_and_full_forms_give_the_same_parameters(project):
    path = write(project / "sequences", "s.yaml", seq("""\
        - reset
        - reset: all
        - reset: [j1, j2]
        - reset: {joints: [j1], label: Only j1}
        - home
        - home:
        - halt: [j4]
        - set_limits
        - set_limits: {limits_deg: {j1: [-170, 170]}, max_velocity_deg_s: {j1: 20}}
        - move: totem
        - move: {joints: {j1: 10}, relative: true, velocity_deg_s: {j1: 5}}
        - wait: 2
        - wait: {until: in_position, timeout_s: 5}
        - checkpoint: opsafe
        - checkpoint: {position_mm: [1, 2, 3], rpy_deg: [0, 0, 0], position_tolerance_mm: 1}
        - confirm: Is the desk clear?
        - confirm: {prompt: 'Go on?', label: Ask}
        """))
    steps = load_sequence(path).steps
    assert [s.kind for s in steps] == [
        "reset", "reset", "reset", "reset", "home", "home", "halt", "set_limits", "set_limits",
        "move", "move", "wait", "wait", "checkpoint", "checkpoint", "confirm", "confirm"]
    p = [s.params for s in steps]
    assert p[0] == p[1] == ResetParams(joints="all")
    assert p[2] == ResetParams(joints=["j1", "j2"])
    assert p[3].joints == ["j1"] and steps[3].label == "Only j1"
    assert p[5].joints == "all"
    assert p[6] == HaltParams(joints=["j4"])
    assert p[7] == SetLimitsParams()
    assert p[8].limits_deg == {"j1": [-170.0, 170.0]} and p[8].max_velocity_deg_s == {"j1": 20}
    assert p[9] == MoveParams(pose="totem")
    assert p[10].relative and p[10].joints == {"j1": 10}
    assert p[11] == WaitParams(seconds=2)
    assert p[12].until == "in_position" and p[12].timeout_s == 5
    assert p[13] == CheckpointParams(pose="opsafe")
    assert p[14].position_mm == [1, 2, 3] and p[14].position_tolerance_mm == 1
    assert p[15] == ConfirmParams(prompt="Is the desk clear?")
    assert [s.number for s in steps] == list(range(1, 18))


def test_step_titles_use_the_label_or_describe_the_step(project):
    path = write(project / "sequences", "s.yaml", seq("""\
        - move: {pose: totem, label: Up}
        - move: {joints: {j1: 10, j2: -5.5}}
        - wait: 1.5
        """))
    steps = load_sequence(path).steps
    assert [s.title for s in steps] == ["Up", "move j1 to 10°, j2 to -5.5°", "wait 1.5 s"]
    assert describe("halt", HaltParams()) == "halt all modules"


# --------------------------------------------------------------------------- model errors
@pytest.mark.parametrize("steps, line, col, words", [
    ("- mvoe: totem\n", 4, 3, ["unknown step type 'mvoe'", "did you mean 'move'",
                               "reset, home, halt"]),
    ("- move\n", 4, 3, ["step 'move' needs parameters"]),
    ("- {move: totem, label: x}\n", 4, 3, ["exactly one key", "put label inside"]),
    ("- 5\n", 4, 3, ["a step is a mapping with one key"]),
    ("- move: {pose: totem, velocty: 3}\n", 4, 23, ["unknown key 'velocty' in move",
                                                   "allowed: pose, joints,", "label)"]),
    ("- move: {label: x}\n", 4, 9, ["a move needs either 'pose', 'joints' or 'position_mm'"]),
    ("- move: {pose: totem, joints: {j1: 1}}\n", 4, 9, ["not both"]),
    ("- move: {pose: totem, relative: true}\n", 4, 9, ["'relative: true' needs 'joints'"]),
    ("- move: {joints: {}}\n", 4, 18, ["must not be empty"]),
    ("- move: {joints: {j1: 1}, velocity_scale: 0}\n", 4, 43, ["at least 0.01"]),
    ("- move: {joints: {j1: 1}, acceleration_scale: 2}\n", 4, 47, ["at most 1, got 2"]),
    ("- move: {joints: {j1: 1}, tolerance_deg: -0.1}\n", 4, 42, ["greater than 0"]),
    ("- move: ../etc/passwd\n", 4, 9, ["is not a pose name"]),
    ("- wait: 0\n", 4, 9, ["greater than 0"]),
    ("- wait: {seconds: 1, timeout_s: 3}\n", 4, 9, ["belong to 'until: in_position'"]),
    ("- wait: {until: moving}\n", 4, 17, ["expected 'in_position'"]),
    ("- checkpoint: {position_mm: [1, 2, 3]}\n", 4, 15, ["needs rpy_deg too"]),
    ("- checkpoint: {pose: totem, rpy_deg: [0, 0, 0]}\n", 4, 15, ["not both"]),
    ("- checkpoint: {pose: totem, angle_tolerance_deg: .inf}\n", 4, 50, ["finite"]),
    ("- set_limits: {limits_deg: {j1: [10, -10]}}\n", 4, 15, ["min 10 is not below max -10"]),
    ("- set_limits: {limits_deg: {j1: [10]}}\n", 4, 33, ["at least 2 values, got 1"]),
    ("- halt: none\n", 4, 9, ["expected 'all' or a list of joint names"]),
    ("- halt: []\n", 4, 9, ["must not be empty"]),
    ("- confirm: ''\n", 4, 12, ["must not be empty"]),
    ("- confirm: 42\n", 4, 12, ["expected text, got 42"]),
    ("- include: other.txt\n", 4, 12, [("an include names a sequence file ending in .yaml, "
                                        "got 'other.txt'")]),
    ("- include: {file: x.yml, lable: y}\n", 4, 26, [(
        "unknown key 'lable' in include (did you mean 'label'? allowed: file, with, "
        "monitors, verifies, tags, if, skip_if, repeat, retry, on_fail, breakpoint, label)")]),
    ("- reset: {label: ''}\n", 4, 18, ["must not be empty"]),
])
def test_step_errors_are_located_and_explained(project, steps, line, col, words):
    path = write(project / "sequences", "s.yaml", seq(steps))
    [(_, got_line, got_col, message)] = load_errors(path)
    assert (got_line, got_col) == (line, col), message
    for word in words:
        assert word in message, message


def test_top_level_errors(project):
    path = write(project / "sequences", "s.yaml", "name: ''\nsteps: []\nnmae: x\n")
    assert load_errors(path) == [   # (description is optional)
        ("s.yaml", 1, 7, "must not be empty"),
        ("s.yaml", 2, 8, "must not be empty"),
        ("s.yaml", 3, 1, ("unknown key 'nmae' in the sequence (did you mean 'name'? allowed: "
                         "name, description, arm, params, steps, monitors)")),
    ]


def test_all_errors_at_once_including_poses_and_includes_of_valid_steps(project):
    path = write(project / "sequences", "s.yaml", seq("""\
        - mvoe: totem
        - move: tottem
        - include: nothere.yaml
        - wait: -1
        """))
    errors = load_errors(path)
    assert [(line, col) for _, line, col, _ in errors] == [(4, 3), (5, 9), (6, 12), (7, 9)]
    assert "unknown pose 'tottem'" in errors[1][3] and "opsafe, park, totem" in errors[1][3]
    assert "nothere.yaml" in errors[2][3] and "no such file" in errors[2][3]


# --------------------------------------------------------------------------- includes
def test_includes_are_expanded_with_their_own_locations(project):
    sequences = project / "sequences"
    write(sequences, "startup.yaml", seq("- reset\n- home\n- set_limits\n", "Startup"))
    write(sequences, "sub/inner.yaml", seq("- include: ../startup.yaml\n- wait: 1\n", "Inner"))
    top = write(sequences, "top.yaml", seq("""\
        - confirm: Ready?
        - include: {file: sub/inner.yaml, label: Inner part}
        - move: totem
        """))
    loaded = load_sequence(top)
    steps = loaded.steps
    assert [(s.number, s.kind) for s in steps] == [
        (1, "confirm"), (2, "reset"), (3, "home"), (4, "set_limits"), (5, "wait"), (6, "move")]
    assert [(Path(s.location.file).name, s.location.line, s.location.column)
            for s in steps] == [("top.yaml", 4, 3), ("startup.yaml", 4, 3),
                                ("startup.yaml", 5, 3), ("startup.yaml", 6, 3),
                                ("inner.yaml", 5, 3), ("top.yaml", 6, 3)]
    assert steps[0].include_chain == ()
    assert [(Path(c.file).name, c.line) for c in steps[1].include_chain] == [
        ("top.yaml", 5), ("inner.yaml", 4)]
    assert [(Path(c.file).name, c.line) for c in steps[4].include_chain] == [("top.yaml", 5)]
    assert loaded.project_root == project.resolve()
    assert loaded.poses_dir == project.resolve() / "poses"
    assert loaded.arm_path == project.resolve() / "arms" / "lwa3.yaml"
    assert [p.name for p in loaded.files] == ["top.yaml", "inner.yaml", "startup.yaml"]


def test_include_loop_is_located_at_the_include_that_closes_it(project):
    sequences = project / "sequences"
    write(sequences, "a.yaml", seq("- reset\n- include: b.yaml\n"))
    write(sequences, "b.yaml", seq("- home\n- include: a.yaml\n"))
    assert load_errors(sequences / "a.yaml") == [
        ("b.yaml", 5, 12, "include loop: a.yaml -> b.yaml -> a.yaml")]


def test_self_include(project):
    path = write(project / "sequences", "a.yaml", seq("- include: a.yaml\n"))
    assert load_errors(path) == [("a.yaml", 4, 12, "include loop: a.yaml -> a.yaml")]


def test_include_cannot_leave_the_sequences_tree(project):
    write(project, "outside.yaml", seq("- reset\n"))
    path = write(project / "sequences", "s.yaml", seq("- include: ../outside.yaml\n"))
    [(_, line, col, message)] = load_errors(path)
    assert (line, col) == (4, 12)
    assert "outside the sequences folder" in message


def test_include_through_a_symlink_out_of_the_tree_is_refused(project):
    write(project, "outside.yaml", seq("- reset\n"))
    (project / "sequences" / "link.yaml").symlink_to(project / "outside.yaml")
    path = write(project / "sequences", "s.yaml", seq("- include: link.yaml\n"))
    assert "outside the sequences folder" in load_errors(path)[0][3]


def test_the_tree_is_the_top_files_folder_outside_a_sequences_folder(tmp_path):
    write(tmp_path, "lib/common.yaml", seq("- reset\n"))
    top = write(tmp_path, "lib/top.yaml", seq("- include: common.yaml\n"))
    assert [s.kind for s in load_sequence(top).steps] == ["reset"]
    escape = write(tmp_path, "lib/escape.yaml", seq("- include: ../x.yaml\n"))
    assert "outside the sequences folder" in load_errors(escape)[0][3]


def test_errors_in_an_included_file_are_located_there(project):
    sequences = project / "sequences"
    write(sequences, "inner.yaml", seq("- wait: -1\n"))
    top = write(sequences, "top.yaml", seq("- include: inner.yaml\n- wait: 0\n"))
    assert [(f, line, col) for f, line, col, _ in load_errors(top)] == [
        ("top.yaml", 5, 9), ("inner.yaml", 4, 9)]


def test_included_file_must_not_name_another_arm(project):
    sequences = project / "sequences"
    (project / "arms" / "other.yaml").write_text((project / "arms" / "lwa3.yaml").read_text())
    write(sequences, "inner.yaml", seq("- reset\n").replace("steps:", "arm: arms/other.yaml\n"
                                                                    "steps:"))
    write(sequences, "same.yaml", seq("- home\n").replace("steps:", "arm: arms/lwa3.yaml\n"
                                                                  "steps:"))
    top = write(sequences, "top.yaml", seq("- include: inner.yaml\n- include: same.yaml\n"))
    [(name, line, col, message)] = load_errors(top)
    assert (name, line, col) == ("inner.yaml", 3, 6) and "names arm" in message


def test_missing_arm_file_named_by_the_sequence(project):
    path = write(project / "sequences", "s.yaml",
                 "name: x\ndescription: y\narm: arms/nope.yaml\nsteps: [reset]\n")
    [(_, line, col, message)] = load_errors(path)
    assert (line, col) == (3, 6) and "arm file 'arms/nope.yaml' not found" in message


def test_unreadable_top_file_is_a_user_input_error(project):
    with pytest.raises(UserInputError, match="no such file"):
        load_sequence(project / "sequences" / "missing.yaml")


def test_project_root_is_the_nearest_folder_with_arms_or_poses(project, tmp_path, monkeypatch):
    deep = project / "sequences" / "a" / "b"
    deep.mkdir(parents=True)
    assert find_project_root(deep / "x.yaml") == project.resolve()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    nowhere = Path("/") / "tmp"
    monkeypatch.chdir(elsewhere)
    assert find_project_root(nowhere / "nothing-here-hopefully" / "x.yaml") in (
        elsewhere.resolve(), Path("/tmp").resolve())


def test_step_where_finds_parameter_locations(project):
    path = write(project / "sequences", "s.yaml", seq("""\
        - move:
            joints: {j1: 10, j4: -30}
        - move: totem
        """))
    first, second = load_sequence(path).steps
    assert (first.where("joints", "j4").line, first.where("joints", "j4").column) == (5, 26)
    assert first.where("joints", "j4", key=True).column == 22
    # shorthand: no 'pose' key is written, the value itself is the location
    assert (second.where("pose").line, second.where("pose").column) == (6, 9)


# --------------------------------------------------------------------------- JSON Schema
def _objects(schema):
    yield from schema.get("$defs", {}).items()
    yield "Sequence", schema


def test_json_schema_is_exact_and_documented():
    schema = sequence_json_schema()
    assert schema["$schema"].endswith("2020-12/schema")
    for name, definition in _objects(schema):
        assert definition.get("additionalProperties") is False, name
        assert definition.get("description"), name
        for field, prop in definition["properties"].items():
            assert prop.get("description"), f"{name}.{field} has no description"
    step_refs = {ref["$ref"].split("/")[-1] for ref in schema["properties"]["steps"]["items"]
                 ["oneOf"] if "$ref" in ref}
    assert step_refs == {f"{''.join(p.title() for p in k.split('_'))}Step" for k in STEP_KINDS}
    bare = [b for b in schema["properties"]["steps"]["items"]["oneOf"] if "enum" in b]
    assert bare == [{"description": bare[0]["description"], "enum":
                     ["reset", "home", "halt", "set_limits"], "type": "string"}]
    move = schema["$defs"]["MoveParams"]
    assert move["oneOf"] == [{"required": ["pose"]}, {"required": ["joints"]},
                            {"required": ["position_mm"]}]
    assert move["properties"]["velocity_scale"]["minimum"] == 0.01
    assert move["properties"]["velocity_scale"]["maximum"] == 1


def test_json_schema_validates_the_shipped_sequences_structurally():
    """A tiny structural check: every key used in shipped files is in the schema."""
    schema = sequence_json_schema()
    defs = schema["$defs"]
    import yaml

    for path in SHIPPED:
        data = yaml.safe_load(path.read_text())
        assert set(data) <= set(schema["properties"]), path
        for step in data["steps"]:
            if isinstance(step, str):
                continue
            [(kind, value)] = step.items()
            assert kind in STEP_KINDS
            if isinstance(value, dict):
                model = PARAMS_MODELS[kind].__name__
                assert set(value) <= set(defs[model]["properties"]), (path, kind)


def test_committed_schema_file_matches_the_models():
    committed = json.loads((ROOT / "docs" / "schema" / "sequence.schema.json").read_text())
    assert committed == sequence_json_schema()


def test_shipped_files_point_at_the_schema():
    for path in SHIPPED:
        first = path.read_text(encoding="utf-8").splitlines()[0]
        assert first == "# yaml-language-server: $schema=../docs/schema/sequence.schema.json"


def test_models_are_strict():
    from pydantic import ValidationError

    with pytest.raises(ValidationError):
        Sequence.model_validate({"name": "x", "description": "y", "steps": [{"wait": "2"}]})
    with pytest.raises(ValidationError):
        MoveParams.model_validate({"joints": {"j1": 1}, "relative": "yes"})


def test_display_names_are_relative_to_the_cwd():
    assert display_path(ROOT / "sequences" / "opsafe.yaml") in (
        "sequences/opsafe.yaml", str(ROOT / "sequences" / "opsafe.yaml"))


def test_committed_reference_docs_match_the_models():
    from seqrun.sequence.reference import reference_markdown

    committed = (ROOT / "docs" / "sequence-format.md").read_text(encoding="utf-8")
    assert committed == reference_markdown(), (
        "docs/sequence-format.md is stale; run: seqrun schema --markdown > "
        "docs/sequence-format.md")
    for kind in STEP_KINDS:
        assert f"### `{kind}`" in committed


def test_unresolvable_include_paths_are_located(project):
    sequences = project / "sequences"
    (sequences / "l1.yaml").symlink_to(sequences / "l2.yaml")
    (sequences / "l2.yaml").symlink_to(sequences / "l1.yaml")
    path = write(sequences, "s.yaml", seq('- include: "a\\0.yaml"\n- include: l1.yaml\n'))
    errors = load_errors(path)
    assert [(line, col) for _, line, col, _ in errors] == [(4, 12), (5, 12)]
    assert errors[0][3] == "include 'a\\x00.yaml': cannot resolve the path (embedded null byte)"
    assert "cannot resolve the path" in errors[1][3] and "l1.yaml" in errors[1][3]


def test_unusable_top_files_are_user_input_errors(project):
    loop = project / "sequences" / "loop.yaml"
    loop.symlink_to(loop)
    with pytest.raises(UserInputError, match="cannot resolve the path"):
        load_sequence(loop)
    with pytest.raises(UserInputError, match="not a regular file"):
        load_sequence("/dev/null")


def test_the_docs_and_the_campaign_guide_agree_on_where_includes_may_reach():
    """Issue 23 (item 8): the README (now docs/campaigns.md) said anywhere in the campaign,
    the reference said inside the sequences folder. Both now say both rules, as the loader
    applies them."""
    import re

    def flat(text: str) -> str:
        return re.sub(r"\s+", " ", text.replace("`", ""))

    readme = flat((ROOT / "docs" / "campaigns.md").read_text(encoding="utf-8"))
    reference = flat((ROOT / "docs" / "sequence-format.md").read_text(encoding="utf-8"))
    for text in (readme, reference):
        assert "may be anywhere inside the campaign folder" in text
        assert ("must stay inside the project's sequences/ folder (else the folder of the "
                "file given to seqrun)") in text
