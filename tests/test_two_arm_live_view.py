"""The live terminal view of a two-arm run (issue 28): one status line per arm, drawn
from the arms' loops; plain lines into a pipe or with --plain. As tests/test_display.py,
the screen is a recording rich Console (here one that says it is a terminal), runs are at
virtual time on the simulators."""

from __future__ import annotations

import io
import re

import pytest
from rich.console import Console
from typer.testing import CliRunner

from seqrun.cli import app
from twoarmskit import two_arm_campaign


@pytest.fixture
def terminal(tmp_path, monkeypatch):
    """A two-arm campaign, and the run's screen: a recording console that is a terminal."""
    two_arm_campaign(tmp_path, monkeypatch)
    screen = Console(record=True, file=io.StringIO(), force_terminal=True, width=200,
                     color_system=None)
    monkeypatch.setattr("seqrun.cli.output.make_console", lambda **kwargs: screen)
    return screen


def run(tmp_path, *extra: str):
    return CliRunner().invoke(app, ["run", "sequences/short.yaml", "--sim", "--virtual-time",
                                    "--yes", "--no-report", "--log-dir",
                                    str(tmp_path / "run"), *extra])


def last_frame(screen: Console) -> list[str]:
    """The lines of the view as the run left it on the screen (its last panel)."""
    text = screen.export_text()
    return text[text.rindex("╭"):].splitlines()


def arm_lines(frame: list[str]) -> dict[str, str]:
    return {m.group(1): line for line in frame
            if (m := re.match(r"│ ([AB])  ", line))}


def test_one_status_line_per_arm_stays_on_the_screen(terminal, tmp_path):
    result = run(tmp_path)
    assert result.exit_code == 0, result.output
    frame = last_frame(terminal)
    assert "seqrun: Short" in frame[0]
    lines = arm_lines(frame)
    assert set(lines) == {"A", "B"} and len(frame) == 4      # top, A, B, bottom
    for arm in "AB":
        assert "step 9/9: done (item 2)" in lines[arm]
        assert re.search(r"ee \[ +[-\d.]+, +[-\d.]+, +[-\d.]+\] mm", lines[arm])
        assert lines[arm].rstrip(" │").endswith("passed: sequence completed")
    # no plain step lines on a terminal: the view says it
    assert "[A] " not in result.output and "[B] " not in result.output
    assert "arm A: PASSED" in result.output and "arm B: PASSED" in result.output


def test_the_view_was_drawn_while_the_arms_moved(terminal, tmp_path):
    result = run(tmp_path)
    assert result.exit_code == 0, result.output
    text = terminal.export_text()
    moving = [line for line in text.splitlines()
              if re.match(r"│ A  step 4/9: move j1 to 10° +━+ +\d\.\d/ +1\.\d s  ee \[", line)]
    assert moving, "no frame drawn during A's move"


def test_a_fault_shows_on_its_arms_line(terminal, tmp_path):
    result = run(tmp_path, "--sim-fault", "A/3:tow_error@0.2")
    assert result.exit_code == 3, result.output
    frame = last_frame(terminal)
    lines = arm_lines(frame)
    assert "failed: module 3 (j3): ERROR|HALTED|TOW_ERROR" in lines["A"]
    # each halted arm: its Halt on a line of its own, under the arm's line
    below = {arm: frame[frame.index(lines[arm]) + 1] for arm in "AB"}
    assert "HALT sent at" in below["A"] and "(confirmed by every module)" in below["A"]
    assert "HALT sent at" in below["B"] and "arm A" in below["B"]   # (B waited for A)
    assert len(frame) == 6                     # top, A, its halt, B, its halt, bottom


def test_plain_lines_with_plain_or_into_a_pipe(terminal, tmp_path):
    result = run(tmp_path, "--plain")
    assert result.exit_code == 0, result.output
    assert "╭" not in terminal.export_text()
    assert re.search(r"^\[A\] +\d+\.\d\d s  step 4: move j1 to 10°$", result.output, re.M)
    assert re.search(r"^\[B\] +\d+\.\d\d s  step 4: wait for A_turned$", result.output, re.M)
