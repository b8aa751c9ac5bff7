"""Messages of the validation commands (issue 9, item 17): one clear line, nothing twice,
JSON when asked for, include labels shown, cut labels marked, the right reference."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers every command)
from projecttree import ROOT
from runfolder import RunFolder
from seqrun.cli.app import app

runner = CliRunner()


def run(*args, cwd: Path | None = None):
    return runner.invoke(app, [str(a) for a in args])


def test_a_bad_pose_name_is_one_clear_line(tmp_path):
    result = run("pose", "save", "bad name!", "--sim", "-o", tmp_path / "p.yaml",
                 "--arm", ROOT / "arms" / "lwa3.yaml")
    assert result.exit_code == 2, result.output
    assert result.stderr.splitlines() == [
        "error: 'bad name!' is not a pose name: letters, digits, _ and -, starting with a "
        "letter or digit (it names the file poses/<name>.yaml)"]
    assert "pydantic" not in result.output
    assert not (tmp_path / "p.yaml").exists()


def test_an_invalid_from_prints_each_error_once(tmp_path):
    result = run("run", ROOT / "sequences" / "opsafe.yaml", "--from", "6", "--virtual-time",
                 "--yes", "--plain", "--log-dir", tmp_path / "run")
    assert result.exit_code == 1, result.output
    text = " ".join(result.output.split())  # the terminal may wrap lines
    assert text.count("--from 6: the arm is not where this step expects it: j2") == 1, text
    assert text.count("move before home") == 1, text


def test_validate_json_of_a_missing_file_is_json(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)  # a file outside the current directory is named in full
    result = run("validate", "--json", tmp_path / "missing.yaml")
    assert result.exit_code == 2
    body = json.loads(result.stdout)
    assert body["valid"] is False and body["dry_run"] is None
    assert body["errors"] == [{"message": f"{tmp_path / 'missing.yaml'}: no such file"}]


def test_the_validate_table_shows_include_labels_and_marks_cut_labels(project):
    long_label = "Go up to Totem with a label far longer than the table has room for at all"
    path = project / "sequences" / "s.yaml"
    path.write_text("name: T\ndescription: test\nsteps:\n"
                    "  - include: {file: startup.yaml, label: Power-on start-up}\n"
                    f"  - move: {{pose: totem, label: {long_label}}}\n")
    result = run("validate", path)
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    header = next(i for i, line in enumerate(lines) if line.strip() == "Power-on start-up")
    assert "Reset all modules" in lines[header + 1]  # the included steps follow, indented
    move = next(line for line in lines if " Go up to Totem" in line)
    assert "…" in move and long_label not in move


def test_step_started_events_name_their_include(project, tmp_path):
    path = project / "sequences" / "s.yaml"
    path.write_text("name: T\ndescription: test\nsteps:\n"
                    "  - include: {file: startup.yaml, label: Power-on start-up}\n"
                    "  - wait: 0.1\n")
    result = run("run", path, "--virtual-time", "--yes", "--plain", "--no-report",
                 "--log-dir", tmp_path / "r")
    assert result.exit_code == 0, result.output
    events = RunFolder(tmp_path / "r").events()
    started = [e for e in events if e["type"] == "step_started"]
    assert [e.get("include") for e in started] == [["Power-on start-up"]] * 3 + [None]


def test_schema_pose_markdown_is_the_pose_reference():
    result = run("schema", "pose", "--markdown")
    assert result.exit_code == 0
    assert result.stdout.startswith("# Pose files\n")
    assert "| `joints_deg` |" in result.stdout and "| `end_effector.position_mm` |" in result.stdout
    assert "### `move`" not in result.stdout
    arm = run("schema", "arm", "--markdown").stdout
    assert arm.startswith("# Arm files\n") and "| `control.max_wait_s` |" in arm


@pytest.mark.parametrize("flag", ["--version", "-V"])
def test_version_is_printed(flag):
    """Issue 23 (item 8): `seqrun --version` was 'No such option', exit 2."""
    from seqrun import __version__

    result = CliRunner().invoke(app, [flag])
    assert result.exit_code == 0, result.output
    assert result.output == f"seqrun {__version__}\n"
    out = subprocess.run([sys.executable, "-m", "seqrun", flag], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0 and out.stdout == f"seqrun {__version__}\n", out
