"""The example campaign examples/capture-campaign/ (issue 39, item 7): parameters, monitors
on the following error and the tool's height, a wait on the gripper, a condition and
retries, each through `seqrun validate` and `seqrun run --virtual-time`."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers every command)
from projecttree import ROOT
from seqrun.cli.app import app

CAMPAIGN = ROOT / "examples" / "capture-campaign"
CAPTURE = CAMPAIGN / "sequences" / "capture.yaml"

pytestmark = pytest.mark.slow   # whole runs of a 16-step sequence, and its dry runs


def run(*words: str):
    return CliRunner().invoke(app, list(words))


def capture_run(log_dir: Path, *options: str, sequence: Path = CAPTURE) -> tuple[int, dict]:
    result = run("run", str(sequence), "--virtual-time", "--yes", "--plain", "--no-report",
                 "--log-dir", str(log_dir), *options)
    return result.exit_code, json.loads((log_dir / "report.json").read_text())


def test_the_example_validates_over_its_declared_params():
    result = run("validate", str(CAPTURE))
    assert result.exit_code == 0, result.output
    assert "valid (18 steps)" in result.output
    assert "invalid over its declared params" not in result.output
    # what the dry run did not take is said, not hidden
    assert "if 'params.check_open' was never false" in result.output
    assert "the rescue of block 1 never ran" in result.output


def test_the_example_passes_and_traces_every_requirement(tmp_path):
    code, report = capture_run(tmp_path / "run")
    assert (code, report["status"]) == (0, "passed")
    assert report["requirements"] == {f"REQ-CAP-00{i}": "passed" for i in range(1, 5)}
    assert report["params"] == {"speed": 0.5, "part_mm": 40.0, "force_n": 100.0,
                                "hold_s": 2.0, "check_open": True}


def test_a_parameter_skips_the_last_check_and_the_report_says_so(tmp_path):
    code, report = capture_run(tmp_path / "run", "--param", "check_open=false",
                               "--param", "speed=0.8")
    assert code == 0
    last = report["steps"][-1]
    assert last["status"] == "skipped" and last["verifies"] == ["REQ-CAP-003"]
    assert report["requirements"]["REQ-CAP-003"] == "not run"
    assert report["params"]["speed"] == 0.8


def test_a_parameter_outside_its_range_is_refused_before_anything_moves(tmp_path):
    result = run("run", str(CAPTURE), "--virtual-time", "--yes", "--plain",
                 "--log-dir", str(tmp_path / "run"), "--param", "speed=0.9")
    assert result.exit_code == 2
    assert "--param speed=0.9: 0.9 is above the maximum 0.8" in result.output
    assert not (tmp_path / "run" / "trace.asc").exists()


def test_the_monitor_halts_a_stuck_joint_before_the_runs_own_check(tmp_path):
    """j2 stuck at 3 s: the 1° monitor halts the arm; the same sequence without monitors
    halts later, on the run's own following-error bound (the arm file's)."""
    code, report = capture_run(tmp_path / "monitored", "--sim-fault", "2:stuck@3")
    assert (code, report["fault"]["cause"]) == (3, "monitor"), report["fault"]
    assert "j2 lags its plan" in report["message"]
    assert report["requirements"]["REQ-CAP-004"] == "failed"
    # the same campaign, its monitors taken out
    bare = tmp_path / "bare"
    shutil.copytree(CAMPAIGN, bare, ignore=shutil.ignore_patterns("runs"))
    text = (bare / "sequences" / "capture.yaml").read_text()
    start = text.index("      monitors:\n        - {while")
    end = text.index("  - move:\n      pose: opsafe")
    (bare / "sequences" / "capture.yaml").write_text(text[:start] + text[end:])
    code, unmonitored = capture_run(tmp_path / "bare-run", "--sim-fault", "2:stuck@3",
                                    sequence=bare / "sequences" / "capture.yaml")
    assert code == 3 and unmonitored["fault"]["cause"] != "monitor", unmonitored["fault"]
    assert report["duration_s"] < unmonitored["duration_s"]
