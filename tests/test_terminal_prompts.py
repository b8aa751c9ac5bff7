"""The operator's questions are on the screen, in a real terminal (a tmux pane).

``seqrun run`` without ``--yes`` asks before a ``confirm`` step, and ``--step`` asks before
every step. With the live view on, a question printed under the panel used to be erased by
the next redraw, so the operator answered blind. Here seqrun runs in a detached tmux pane
(its own tmux server, killed afterwards); the test reads the screen with capture-pane, answers
with send-keys and checks the run ends as answered.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from projecttree import ROOT
from runfolder import RunFolder


class Pane:
    """seqrun in a detached tmux session on a private server."""

    def __init__(self, command: list[str], cwd: Path) -> None:
        self.server = f"seqrun-test-{uuid.uuid4().hex[:8]}"
        env = f"PYTHONPATH={shlex.quote(str(ROOT))}"
        line = (f"cd {shlex.quote(str(cwd))} && {env} {shlex.join(command)}; "
                f"echo SEQRUN-EXIT=$?; sleep 300")
        self._tmux("new-session", "-d", "-s", "t", "-x", "120", "-y", "50", line)

    def _tmux(self, *args: str) -> str:
        return subprocess.run(["tmux", "-L", self.server, *args], check=True,
                              capture_output=True, text=True, timeout=20).stdout

    def screen(self) -> str:
        return self._tmux("capture-pane", "-p", "-t", "t")

    def wait_for(self, text: str, timeout: float = 60.0) -> str:
        deadline = time.monotonic() + timeout
        while True:
            screen = self.screen()
            if text in screen:
                return screen
            if time.monotonic() > deadline:
                raise AssertionError(f"{text!r} not on the screen within {timeout} s:\n{screen}")
            time.sleep(0.2)

    def answer(self, keys: str) -> None:
        self._tmux("send-keys", "-t", "t", keys, "Enter")

    def close(self) -> None:
        subprocess.run(["tmux", "-L", self.server, "kill-server"], capture_output=True,
                       timeout=20)


def seqrun(*args: str) -> list[str]:
    return [sys.executable, "-m", "seqrun", "run", *args]


@pytest.mark.slow
def test_a_confirm_question_stays_on_the_screen_and_the_answer_counts(tmp_path):
    """Real time, live view: the confirm step's question is visible until answered."""
    pane = Pane(seqrun("--log-dir", str(tmp_path / "run"), "sequences/opsafe.yaml"), ROOT)
    try:
        screen = pane.wait_for("[y/N]")
        assert "Is the space around the arm clear for the move to Op-safe? [y/N]" in screen
        time.sleep(1.0)  # several refresh intervals: a redraw would have erased it by now
        assert "Op-safe? [y/N]" in pane.screen()
        pane.answer("y")
        screen = pane.wait_for("SEQRUN-EXIT=", timeout=120)
        assert "SEQRUN-EXIT=0" in screen
        assert "PASSED (exit 0)" in screen
        assert "Op-safe? [y/N] y" in screen   # the question and its answer stay above
    finally:
        pane.close()
    report = RunFolder(tmp_path / "run").report()
    assert report["status"] == "passed"


@pytest.mark.slow
def test_step_mode_shows_every_question_in_turn(tmp_path):
    """--step: a question before each of the 9 steps, each visible and about the right step;
    the panel never says preflight while a step is asked about."""
    pane = Pane(seqrun("--step", "--virtual-time", "--log-dir", str(tmp_path / "run"),
                       "sequences/opsafe.yaml"), ROOT)
    try:
        for n in range(1, 10):
            screen = pane.wait_for(f"Run step {n}/9:")
            question = next(line for line in screen.splitlines() if f"Run step {n}/9:" in line)
            assert question.rstrip().endswith("[y/N]"), screen
            assert "preflight" not in screen
            assert "??" not in question
            pane.answer("y")
            if n == 4:  # the confirm step asks its own question as well
                pane.wait_for("Op-safe? [y/N]")
                pane.answer("y")
        screen = pane.wait_for("SEQRUN-EXIT=", timeout=120)
        assert "SEQRUN-EXIT=0" in screen, screen
    finally:
        pane.close()
    report = RunFolder(tmp_path / "run").report()
    assert report["status"] == "passed"
    assert [s["status"] for s in report["steps"]] == ["passed"] * 9


@pytest.mark.slow
def test_a_no_in_step_mode_ends_the_run_before_that_step(tmp_path):
    pane = Pane(seqrun("--step", "--virtual-time", "--log-dir", str(tmp_path / "run"),
                       "sequences/opsafe.yaml"), ROOT)
    try:
        pane.wait_for("Run step 1/9:")
        pane.answer("y")
        pane.wait_for("Run step 2/9:")
        pane.answer("n")
        screen = pane.wait_for("SEQRUN-EXIT=", timeout=60)
        assert "SEQRUN-EXIT=130" in screen, screen
    finally:
        pane.close()
