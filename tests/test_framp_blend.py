"""Issue 9.4: firmware whose FRAMP does not blend (every FRAMP restarts from standstill).

The fault campaign's clean case (opsafe.yaml through the CLI) under the simulator switch
``framp_from_standstill`` must end in a completed run or a clean Halt whose message names
the likely cause, never in a silent wrong pose.
"""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT
from runfolder import RunFolder
from seqrun.cli.app import app


def cli_run(tmp_path: Path, monkeypatch, *extra: str):
    monkeypatch.setenv("SEQRUN_SIM_OPTIONS", "framp_from_standstill")
    folder = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "opsafe.yaml"),
                                      "--virtual-time", "--yes", "--plain", "--no-report",
                                      "--log-dir", str(folder), *extra])
    report = RunFolder(folder).report()
    return result, report, folder


def test_non_blending_framp_halts_cleanly_and_names_the_likely_cause(tmp_path, monkeypatch):
    result, report, folder = cli_run(tmp_path, monkeypatch)
    output = " ".join(result.output.split())
    assert result.exit_code == 3, output
    assert "Traceback" not in output
    fault = report["fault"]
    assert fault["cause"] == "following_error"
    assert "the module does not seem to blend FRAMP commands" in fault["message"]
    assert "does not seem to blend FRAMP" in output
    assert fault["halt_sent"] and fault["halt_confirmed"]
    # Halted in the first move, long before the plan would have ended: no silent wrong pose.
    sent = [m for m in RunFolder(folder).trace_frames() if not m.is_rx]
    t_halt = next(m.timestamp for m in sent
                  if m.arbitration_id == 0x100 and m.data[:1] == b"\x02")
    after = [m for m in sent if m.timestamp >= t_halt and m.data[:1] in (b"\x0b", b"\x08")]
    assert after == []
    assert report["steps"][fault["step"] - 1]["kind"] == "move"


def test_step_mode_does_not_depend_on_framp_blending(tmp_path, monkeypatch):
    result, report, _ = cli_run(tmp_path, monkeypatch, "--command-mode", "step")
    assert result.exit_code == 0, result.output
    assert report["status"] == "passed"


def test_a_stuck_joint_is_not_taken_for_non_blending_firmware(tmp_path):
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "opsafe.yaml"),
                                      "--virtual-time", "--yes", "--plain", "--no-report",
                                      "--log-dir", str(tmp_path / "run"),
                                      "--sim-fault", "4:stuck@3"])
    assert result.exit_code == 3
    report = RunFolder(tmp_path / "run").report()
    assert report["fault"]["cause"] == "following_error"
    assert "blend" not in report["fault"]["message"]
