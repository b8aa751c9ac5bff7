"""``seqrun validate`` and ``seqrun schema`` through typer's CliRunner, and as a process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli.validate  # noqa: F401  (registers `validate` and `schema`)
from projecttree import ROOT
from seqrun.cli.app import app
from seqrun.schema import sequence_json_schema
from seqrun.yamlsource import display_path

BAD = ROOT / "tests" / "data" / "bad"
SHIPPED = ["startup", "totem", "opsafe", "park", "shutdown", "linear_approach"]

runner = CliRunner()


def run(*args: str):
    return runner.invoke(app, [str(a) for a in args])


def no_crash(result) -> None:
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        result.exception)
    assert "Traceback" not in result.output


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_files_are_valid(name):
    path = ROOT / "sequences" / f"{name}.yaml"
    result = run("validate", path)
    no_crash(result)
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert any(line.startswith(f"{display_path(path)}: valid (") for line in lines)
    # Statically valid, then the dry run on the simulator passes too.
    assert any(line.startswith("dry run from park") and ": passed" in line for line in lines)


def test_human_output_errors_then_notes_then_summary():
    path = BAD / "velocity_above_max.yaml"
    result = run("validate", path)
    assert result.exit_code == 1
    file = display_path(path)
    assert result.stdout.splitlines() == [
        (f"{file}:9:28: velocity_deg_s of j1 45 deg/s is above its maximum 30 deg/s (from the "
        "arm file)"),
        f"{file}: invalid (1 error)",
    ]


def test_human_output_notes_after_the_errors(tmp_path):
    # an arm file whose j4 stops at -120: Park's j4 (-120.32) starts outside it
    arm = tmp_path / "narrow.yaml"
    arm.write_text((ROOT / "arms" / "lwa3.yaml").read_text().replace(
        "limits_deg: [-120.32, 120]", "limits_deg: [-120, 120]"))
    path = BAD / "velocity_above_max.yaml"
    result = run("validate", path, "--arm", arm)
    assert result.exit_code == 1
    file = display_path(path)
    lines = result.stdout.splitlines()
    assert lines[0] == (f"{file}:9:28: velocity_deg_s of j1 45 deg/s is above its maximum 30 "
                        "deg/s (from the arm file)")
    # (and a note that the arm file lies outside the project's folder)
    assert (f"{file}:8:13: note: j4 starts at -120.32°, 0.32° outside its limit -120…120; "
            "this move brings it back inside") in lines[1:-1]
    assert lines[-1] == f"{file}: invalid (1 error, 2 notes)"


def test_json_output():
    path = BAD / "out_of_limit.yaml"
    result = run("validate", path, "--json")
    assert result.exit_code == 1
    report = json.loads(result.stdout)
    # the smallest guard clearance of each move along its planned trajectory
    assert all(set(c) == {"step", "guard", "point", "z_mm", "margin_mm", "t_s", "duration_s"}
               for c in report.pop("clearances"))
    assert all(set(p) == {"step", "pair", "distance_mm", "t_s", "duration_s"}
               for p in report.pop("proximities"))
    assert report == {
        "valid": False,
        "errors": [{"file": display_path(path), "line": 7, "column": 33,
                    "message": "j2 target 130° is outside its limits -120…120"}],
        "notes": [],  # j4 is still outside, but this move does not command it
        "dry_run": None,  # no dry run of a statically invalid file
    }


def test_json_output_of_a_valid_file_has_the_notes(tmp_path):
    arm = tmp_path / "narrow.yaml"  # j4 stops at -120: Park's j4 starts outside it
    arm.write_text((ROOT / "arms" / "lwa3.yaml").read_text().replace(
        "limits_deg: [-120.32, 120]", "limits_deg: [-120, 120]"))
    result = run("validate", ROOT / "sequences" / "opsafe.yaml", "--json", "--static",
                 "--arm", arm)
    assert result.exit_code == 0
    report = json.loads(result.stdout)
    assert report["valid"] is True and report["errors"] == []
    [note] = [n for n in report["notes"] if n["message"].startswith("j4 ")]
    assert set(note) == {"file", "line", "column", "message"}
    assert note["message"].startswith("j4 starts at -120.32°")


def test_start_option():
    path = ROOT / "sequences" / "opsafe.yaml"
    result = run("validate", path, "--start", "totem")
    assert result.exit_code == 0
    assert "note:" not in result.stdout  # from Totem nothing is outside its limits


def test_arm_option(tmp_path):
    text = (ROOT / "arms" / "lwa3.yaml").read_text()
    slow = tmp_path / "slow.yaml"
    slow.write_text(text.replace("max_velocity_deg_s: 30", "max_velocity_deg_s: 10"))
    path = ROOT / "sequences" / "opsafe.yaml"
    assert run("validate", path, "--arm", slow).exit_code == 0
    result = run("validate", BAD / "velocity_above_max.yaml", "--arm", slow)
    assert "above its maximum 10 deg/s" in result.stdout


def test_invalid_arm_file_is_located(tmp_path):
    broken = tmp_path / "arm.yaml"
    broken.write_text("name: x\njoints: []\nkinematics: nope\n")
    result = run("validate", ROOT / "sequences" / "startup.yaml", "--arm", broken)
    no_crash(result)
    assert result.exit_code == 1
    assert result.stdout.splitlines()[0].startswith(f"{display_path(broken)}:2:9: ")


@pytest.mark.parametrize("args, message", [
    (["nope.yaml"], "error: nope.yaml: no such file"),
    ([str(ROOT / "docs")], "no sequence files"),  # a folder: its sequences (campaigns)
    ([str(ROOT / "sequences" / "opsafe.yaml"), "--start", "nowhere"],
     "error: start pose: unknown pose 'nowhere'"),
    ([str(ROOT / "sequences" / "opsafe.yaml"), "--arm", "nope.yaml"],
     "error: arm file nope.yaml not found"),
])
def test_unusable_input_is_one_line_and_exit_2(args, message):
    result = run("validate", *args)
    no_crash(result)
    assert result.exit_code == 2
    assert result.stdout == ""
    assert len(result.stderr.splitlines()) == 1 and message in result.stderr


@pytest.mark.parametrize("path", sorted(BAD.glob("*.yaml")), ids=lambda p: p.name)
def test_every_bad_file_exits_1_with_located_lines(path):
    result = run("validate", path)
    no_crash(result)
    assert result.exit_code == 1
    lines = result.stdout.splitlines()
    assert lines[-1].endswith(")") and ": invalid (" in lines[-1]
    for line in lines[:-1]:
        file, line_no, column, message = line.split(":", 3)
        assert int(line_no) >= 1 and int(column) >= 1 and message.strip()
        assert Path(file).name.endswith(".yaml")


def test_schema_command_prints_the_sequence_schema():
    result = run("schema")
    assert result.exit_code == 0
    assert json.loads(result.stdout) == sequence_json_schema()
    committed = (ROOT / "docs" / "schema" / "sequence.schema.json").read_text()
    assert result.stdout == committed


@pytest.mark.parametrize("kind, title", [("arm", "ArmDescription"), ("pose", "PoseFile")])
def test_schema_command_other_formats(kind, title):
    result = run("schema", kind)
    assert result.exit_code == 0 and json.loads(result.stdout)["title"] == title


def test_as_a_process_no_traceback_for_hostile_input(tmp_path):
    hostile = tmp_path / "hostile.yaml"
    hostile.write_bytes((BAD / "python_tag.yaml").read_bytes())
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-m", "seqrun", "validate", str(hostile)],
                          capture_output=True, text=True, cwd=tmp_path, env=env, timeout=60,
                          check=False)
    assert proc.returncode == 1
    assert "Traceback" not in proc.stderr + proc.stdout
    assert proc.stdout.splitlines()[0] == (
        "hostile.yaml:5:14: tag '!!python/object/apply:os.system' is not allowed: seqrun files "
        "are plain YAML")


def test_schema_markdown_is_the_committed_reference():
    result = run("schema", "--markdown")
    assert result.exit_code == 0
    assert result.stdout == (ROOT / "docs" / "sequence-format.md").read_text(encoding="utf-8")
