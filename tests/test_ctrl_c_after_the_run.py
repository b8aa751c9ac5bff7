"""Ctrl-C just after a run has ended (issue 43, item 5): the exit code and the last words
are the run's. A faulted run (report.json: failed, exit 3) whose operator pressed Ctrl-C
as its last line appeared ended killed by SIGINT (the shell's 130), or with "nothing was
sent"."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from projecttree import ROOT

pytestmark = pytest.mark.slow


def run_interrupted_after_its_verdict(log_dir, *, presses: int) -> tuple[int, str]:
    """A run that faults (exit 3); Ctrl-C ``presses`` times, 5 ms apart, from the moment
    its last line is printed."""
    run = subprocess.Popen(
        [sys.executable, "-m", "seqrun", "run", "sequences/opsafe.yaml", "--yes", "--plain",
         "--no-report", "--virtual-time", "--sim-fault", "4:tow_error@3", "--log-dir",
         str(log_dir)], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT),
                                       "PYTHONUNBUFFERED": "1"},
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = ""
    try:
        for line in run.stdout:
            out += line
            if line.startswith("duration "):   # the last line of the verdict
                for _ in range(presses):
                    if run.poll() is not None:
                        break
                    run.send_signal(signal.SIGINT)
                    time.sleep(0.005)
                break
        out += run.stdout.read()
        run.wait(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    return run.returncode, out


@pytest.mark.parametrize("presses", [1, 3])
def test_ctrl_c_after_a_faulted_run_keeps_its_exit_code_and_story(tmp_path, presses):
    code, out = run_interrupted_after_its_verdict(tmp_path / "run", presses=presses)
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert (report["status"], report["exit_code"]) == ("failed", 3)
    assert "FAILED (exit 3)" in out
    assert code == 3, out
    assert "nothing was sent" not in out and "Traceback" not in out, out
