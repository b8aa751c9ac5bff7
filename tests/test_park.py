"""Park works (issue 42): its j4 (-120.32, the module zero of a power-off in Park) is j4's
lower limit in the arm file, so `move: park` validates and runs and sequences/park.yaml
ends in Park (the console's Park: tests/test_console_api.py)."""

from __future__ import annotations

import json

from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands on the app)
from projecttree import ROOT, shipped_arm
from seqrun.arm.poses import load_pose, find_pose
from seqrun.cli.app import app


def test_parks_j4_is_the_arm_files_lower_limit_and_the_reason_is_there():
    arm = shipped_arm()
    park = load_pose(find_pose("park", ROOT / "poses"))
    assert arm.joint("j4").limits_deg[0] == park.joints_deg["j4"] == -120.32
    assert arm.power_off_poses["park"].offsets_deg["j4"] == 120.32
    text = (ROOT / "arms" / "lwa3.yaml").read_text(encoding="utf-8")
    assert "j4's lower limit is Park's j4" in text  # the reason, in the arm file


def test_the_park_sequence_runs_into_park(tmp_path):
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "park.yaml"),
                                      "--virtual-time", "--yes", "--plain", "--no-report",
                                      "--log-dir", str(tmp_path / "run")])
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    moves = [s for s in report["steps"] if s["kind"] == "move"]
    assert [s["status"] for s in moves] == ["passed", "passed"]
    [checkpoint] = [s for s in report["steps"] if s["kind"] == "checkpoint"]
    assert checkpoint["status"] == "passed", checkpoint
