"""Issue 39 (item 4): typed parameters, ``${name}`` and ``--param``.

A sequence declares ``params:``; the loader puts their values (defaults, or ``--param``)
into the steps before they are validated, every problem at file:line:col; ``validate``
checks the ends of every numeric range; a run keeps the values it used."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers every command)
from projecttree import shipped_arm
from seqrun.cli.app import app
from seqrun.errors import SequenceInvalid, UserInputError
from seqrun.sequence.loader import load_sequence

ARM = shipped_arm()
runner = CliRunner()

PARAMS = """\
name: P
params:
  speed: {type: float, min: 0.1, max: 0.8, default: 0.25, description: velocity scale}
  target: {type: pose, default: totem}
  word: {type: str, default: Up}
  floor: {type: float, unit: mm, min: 20, max: 100, default: 40}
steps:
  - reset
  - home
  - set_limits
"""  # the steps below start on line 11


def write(project: Path, steps: str, head: str = PARAMS, name: str = "p.yaml") -> Path:
    path = project / "sequences" / name
    path.write_text(head + steps, encoding="utf-8")
    return path


def invoke(*args, cwd: Path):
    with contextlib.chdir(cwd):
        return runner.invoke(app, [str(a) for a in args])


def one_error_line(result) -> str:
    assert "Traceback" not in result.output
    assert result.exit_code == 2, result.output
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    return lines[0]


MOVE = """\
  - move:
      pose: ${target}
      velocity_scale: ${speed}
      label: ${word} at ${speed} to ${target}
"""


# --------------------------------------------------------------------------- substitution
def test_a_whole_reference_takes_the_typed_value_and_a_longer_text_the_text(project):
    loaded = load_sequence(write(project, MOVE))
    move = loaded.steps[3].params
    assert move.velocity_scale == 0.25 and isinstance(move.velocity_scale, float)
    assert move.pose == "totem"
    assert move.label == "Up at 0.25 to totem"
    assert loaded.param_values == {"speed": 0.25, "target": "totem", "word": "Up",
                                   "floor": 40.0}
    # the step keeps its own place in the file
    assert str(loaded.steps[3].location).endswith("p.yaml:11:5")


def test_an_unknown_reference_is_an_error_at_its_line_and_column(project):
    path = write(project, '  - move: {pose: totem, label: "go ${spede} now"}\n')
    with pytest.raises(SequenceInvalid) as caught:
        load_sequence(path)
    errors = [str(e) for e in caught.value.errors]
    # line 11; the '$' is the 36th character of the line (inside the quotes)
    assert any(e.endswith("p.yaml:11:36: unknown parameter '${spede}' (declared: floor, "
                          "speed, target, word)") for e in errors), errors


def test_a_pose_parameter_names_a_pose_that_must_exist(project):
    path = write(project, MOVE)
    with pytest.raises(SequenceInvalid, match=r"p.yaml:12:13: .*nowhere"):
        load_sequence(path, params={"target": "nowhere"})


@pytest.mark.parametrize("declaration, message", [
    ("{type: int, default: true}", "default: expected a whole number, got true"),
    ("{type: float, default: '12'}", "default: expected a finite number, got '12'"),
    ("{type: int, min: 1, max: 5, default: 7}", "default: 7 is above the maximum 5"),
    ("{type: choice, choices: [slow, fast], default: medium}",
     "default: expected one of slow, fast, got 'medium'"),
    ("{type: str, min: 1, default: a}", "min and max are for int and float parameters"),
    ("{type: number, default: 1}", "expected 'int', 'float', 'bool', 'str', 'choice' or "
                                   "'pose'"),
])
def test_a_declaration_is_strictly_typed(project, declaration, message):
    path = write(project, "", head=f"name: P\nparams:\n  n: {declaration}\nsteps:\n  - reset\n")
    with pytest.raises(SequenceInvalid) as caught:
        load_sequence(path)
    errors = [str(e) for e in caught.value.errors]
    assert any(":3:" in e and message in e for e in errors), errors


def test_a_bad_default_is_located_at_the_default(project):
    path = write(project, "", head="name: P\nparams:\n  n: {type: int, default: true}\n"
                                   "steps:\n  - reset\n")
    with pytest.raises(SequenceInvalid) as caught:
        load_sequence(path)
    assert [str(e).rsplit("/", 1)[-1] for e in caught.value.errors] == [
        "p.yaml:3:27: default: expected a whole number, got true"]


# --------------------------------------------------------------------------- --param
def test_param_overrides_the_default_parsed_by_its_type(project):
    path = write(project, MOVE)
    loaded = load_sequence(path, params={"speed": "0.5", "target": "opsafe"})
    assert loaded.steps[3].params.velocity_scale == 0.5
    assert loaded.steps[3].params.pose == "opsafe"
    assert loaded.param_values["speed"] == 0.5
    result = invoke("validate", "--static", path, "--param", "speed=0.5", cwd=project)
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize("option, message", [
    ("speed=fast", "--param speed=fast: expected a number, got 'fast'"),
    ("speed=true", "--param speed=true: expected a number, got 'true'"),
    ("speed=0.9", "--param speed=0.9: 0.9 is above the maximum 0.8"),
    ("sped=0.5", "--param sped: sequences/p.yaml declares no parameter 'sped' "
                 "(declared: speed, target, word, floor)"),
    ("speed", "--param 'speed': expected NAME=VALUE, e.g. --param speed=0.5"),
    ("word=a\x1b[31m", "--param word='a\\x1b[31m': a value is printable text (no control "
                        "characters)"),
])
@pytest.mark.parametrize("command", ["validate", "run"])
def test_a_bad_param_is_one_line_and_exit_2(project, option, message, command):
    path = write(project, MOVE)
    extra = ["--virtual-time", "--yes", "--plain", "--no-report"] if command == "run" else []
    result = invoke(command, path.relative_to(project), "--param", option, *extra,
                    cwd=project)
    assert one_error_line(result) == f"error: {message}"


def test_a_parameter_without_default_needs_a_value(project):
    path = write(project, "  - move: ${target}\n",
                 head="name: P\nparams:\n  target: {type: pose}\nsteps:\n  - reset\n"
                      "  - home\n  - set_limits\n")
    with pytest.raises(UserInputError, match="parameter 'target' has no default: give its "
                                             r"value with --param target=VALUE"):
        load_sequence(path)
    result = invoke("validate", "--static", path, cwd=project)
    assert "parameter 'target' has no default" in one_error_line(result)
    assert load_sequence(path, params={"target": "totem"}).steps[3].params.pose == "totem"


# --------------------------------------------------------------------------- validate
def test_validate_checks_each_end_of_a_range_and_names_the_value(project):
    # 'scale' may be set up to 1.5: its max exceeds what a move accepts
    head = PARAMS.replace("  word:", "  scale: {type: float, min: 0.5, max: 1.5, "
                                     "default: 0.5}\n  word:")
    path = write(project, "  - move: {pose: totem, velocity_scale: \"${scale}\"}\n",
                 head=head)
    result = invoke("validate", "--static", path, cwd=project)
    assert result.exit_code == 1, result.output
    lines = result.stdout.splitlines()
    assert any(line.startswith("params: scale = 1.5 (its max): ")
               and "p.yaml:12:" in line and "at most 1" in line for line in lines), lines
    assert not any("its min" in line for line in lines), lines
    # with the value given, only that value is checked
    assert invoke("validate", "--static", path, "--param", "scale=0.7",
                  cwd=project).exit_code == 0


@pytest.mark.slow
def test_validate_dry_runs_the_ends_of_a_range_a_monitor_depends_on(project):
    # Totem holds the tool far above 100 mm, but the start (Park) is at about 48 mm: with
    # floor at its max, the monitor trips at the first move's start.
    path = write(project, "  - move:\n      pose: totem\n      monitors:\n"
                          "        - while: tool.z_mm > params.floor\n")
    result = invoke("validate", path, cwd=project)
    assert result.exit_code == 1, result.output
    failed = [line for line in result.stdout.splitlines() if line.startswith("params:")]
    assert len(failed) == 1, result.stdout
    assert failed[0].startswith("params: floor = 100.0 (its max): the dry run failed: "
                                "monitor 'tool.z_mm > params.floor' did not hold")


# --------------------------------------------------------------------------- expressions
def test_an_expression_reads_a_parameter_with_its_type_and_unit(project):
    head = PARAMS.replace("  word:", "  fast: {type: bool, default: false}\n  word:")
    path = write(project, '  - check: "tool.z_mm > params.floor"\n'
                          '  - check: "pos_deg[2] > params.floor"\n'
                          '  - check: "tool.z_mm > params.fast"\n', head=head)
    with pytest.raises(SequenceInvalid) as caught:
        load_sequence(path)
    errors = [str(e) for e in caught.value.errors]
    assert not any("p.yaml:12:" in e for e in errors), errors
    assert any("p.yaml:13:" in e and "cannot compare deg and mm" in e for e in errors), errors
    assert any("p.yaml:14:" in e and "compares a number with a bool" in e for e in errors), errors


def test_a_check_reads_the_parameter_value_in_the_dry_run(project):
    from seqrun.service.dryrun import dry_run

    park = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
    path = write(project, '  - check: "tool.z_mm > params.floor"\n')
    passed = dry_run(load_sequence(path), ARM, park)
    assert passed.result.exit_code == 0, passed.result.message
    assert passed.result.steps[3].detail["values"]["params.floor"] == 40.0
    failed = dry_run(load_sequence(path, params={"floor": "90"}), ARM, park)
    assert failed.result.exit_code != 0
    assert failed.result.steps[3].detail["values"]["params.floor"] == 90.0


# --------------------------------------------------------------------------- the record
@pytest.mark.slow
def test_a_run_keeps_the_values_it_used(project, tmp_path):
    path = write(project, MOVE)
    folder = tmp_path / "run"
    result = invoke("run", path, "--virtual-time", "--yes", "--plain", "--log-dir", folder,
                    "--param", "speed=0.5", cwd=project)
    assert result.exit_code == 0, result.output
    expected = {"speed": 0.5, "target": "totem", "word": "Up", "floor": 40.0}
    assert json.loads((folder / "record.json").read_text())["params"] == expected
    assert json.loads((folder / "report.json").read_text())["params"] == expected
    html = (folder / "report.html").read_text(encoding="utf-8")
    assert "speed = 0.5; target = &quot;totem&quot;; word = &quot;Up&quot;; floor = 40.0" \
        in html
