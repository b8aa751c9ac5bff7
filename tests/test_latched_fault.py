"""Issue 16.7: a fault the modules latched before the run is never cleared silently.

On the simulator the sequence's Reset clears it (the run may pass) but the terminal, the
event log and report.json say so; where the operator must be asked (real hardware), a no
ends the run before anything is reset or moved.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT
from runfolder import RunFolder
from seqrun.cli.app import app
from simrun import run_on_sim
from zerostate import ZERO_CONFIRMED, serve_arm


def cli_run(tmp_path: Path, *faults: str):
    args = ["run", str(ROOT / "sequences" / "opsafe.yaml"), "--virtual-time", "--yes",
            "--plain", "--no-report", "--log-dir", str(tmp_path / "run")]
    for fault in faults:
        args += ["--sim-fault", fault]
    result = CliRunner().invoke(app, args)
    report = RunFolder(tmp_path / "run").report()
    return result, report, " ".join(result.output.split())


def test_a_tow_error_latched_before_the_run_is_told_and_reported(tmp_path):
    result, report, output = cli_run(tmp_path, "4:tow_error@0")
    assert result.exit_code == 0, output
    assert "fault latched before this run" in output
    assert "module 4 (j4): ERROR|HALTED|TOW_ERROR" in output.replace("| ", "|")
    assert "cleared by the sequence's Reset" in output
    (latched,) = report["latched_at_start"]
    assert latched["module"] == 4 and "TOW_ERROR" in latched["flags"]
    kinds = [e["type"] for e in RunFolder(tmp_path / "run").events()]
    assert kinds.index("latched_fault") < kinds.index("latched_fault_cleared")


def test_all_modules_halted_before_the_run_are_all_named(tmp_path):
    result, report, output = cli_run(tmp_path, "all:halt@0")
    assert result.exit_code == 0, output
    assert [e["module"] for e in report["latched_at_start"]] == list(range(1, 8))
    assert all("HALTED" in e["flags"] for e in report["latched_at_start"])


def test_a_clean_start_reports_nothing_latched(tmp_path):
    result, report, output = cli_run(tmp_path)
    assert result.exit_code == 0
    assert report["latched_at_start"] == []
    assert "latched" not in output


def test_where_the_operator_is_asked_a_no_resets_and_moves_nothing(tmp_path):
    asked: list[str] = []

    def decline(question: str) -> bool:
        asked.append(question)
        return False

    outcome, sim, _ = run_on_sim("opsafe", tmp_path, faults=["4:tow_error@0"],
                          confirm_clear_latched=decline)
    assert outcome.result.exit_code == 130
    assert "did not clear the fault latched before the run" in outcome.result.message
    (question,) = asked
    assert "module 4 (j4)" in question and "TOW_ERROR" in question
    sent = [m for m in RunFolder(outcome.log_dir).trace() if not m.is_rx]
    resets = [m for m in sent if m.data[:1] == b"\x00" and 0x0E0 <= m.arbitration_id <= 0x100]
    motion = [m for m in sent if m.data[:1] in (b"\x0b", b"\x08")]
    assert resets == [] and motion == []
    assert "TOW_ERROR" in sim.module(4).state().describe()  # still latched
    assert outcome.report["latched_at_start"][0]["module"] == 4


def test_where_the_operator_is_asked_a_yes_clears_and_runs(tmp_path):
    asked: list[str] = []
    outcome, sim, _ = run_on_sim("opsafe", tmp_path, faults=["all:halt@0"],
                          confirm_clear_latched=lambda q: asked.append(q) or True)
    assert outcome.result.exit_code == 0, outcome.result.message
    assert len(asked) == 1  # once, not per Reset step or module


def test_the_operator_is_not_asked_without_a_latched_fault(tmp_path):
    asked: list[str] = []
    outcome, _, _ = run_on_sim("opsafe", tmp_path, confirm_clear_latched=asked.append)
    assert outcome.result.exit_code == 0 and asked == []


@pytest.mark.slow
def test_on_a_real_interface_even_yes_does_not_clear_a_latched_fault_unasked(tmp_path):
    """Through socketcand the CLI cannot tell the simulator from an arm: it must ask, also
    with --yes; without an operator (stdin at end of input) nothing is reset."""
    import subprocess
    import sys

    server, port, env = serve_arm(tmp_path, "--fault", "all:halt@0", cwd=ROOT)
    try:
        folder = tmp_path / "run"
        proc = subprocess.run(
            [sys.executable, "-m", "seqrun", "run", "sequences/opsafe.yaml", "-i", "socketcand",
             "--bus-kwargs", f"port={port}", "--yes", *ZERO_CONFIRMED, "--plain",
             "--log-dir", str(folder)],
            cwd=ROOT, env=env, stdin=subprocess.DEVNULL, capture_output=True, text=True,
            timeout=120)
    finally:
        server.kill()
        server.wait()
    output = " ".join(proc.stdout.split())
    assert proc.returncode == 130, proc.stdout + proc.stderr
    assert "This Reset clears it" in output and "[y/N]" in output
    report = RunFolder(folder).report()
    assert report["status"] == "aborted"
    assert len(report["latched_at_start"]) == 7
    sent = [m for m in RunFolder(folder).trace() if not m.is_rx]
    assert not any(m.data[:1] == b"\x00" for m in sent if 0x0E0 <= m.arbitration_id <= 0x100)
