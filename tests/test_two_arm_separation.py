"""Arm against arm (issue 43, item 3): validation proves the clearance for every timing a
run can take, every control cycle checks the arms from their measured joints and stopping
distances, a faulted arm's neighbour goes on only when its rest of the motion is clear of
where the faulted arm stopped, and the console of several arms refuses a motion into
another arm."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from projecttree import ROOT
from seqrun.service.arms_check import campaign_has_arms, check_arms_sequence

EXAMPLE = ROOT / "examples" / "two-arms"

#: A asks the operator inside its branch, then visits the spot B reaches for; B waits a
#: fixed time: on the planned time line (the answer at once) A is gone before B comes,
#: for a late answer they meet.
CONFIRM_INSIDE = """\
name: Confirm inside
description: A asks the operator inside its branch; B reaches over after a fixed wait.
steps:
  - parallel:
      - arm: A
        steps: [include: startup.yaml]
      - arm: B
        steps: [include: startup.yaml]
  - parallel:
      - arm: A
        steps:
          - confirm: Is the target in place?
          - move: {position_mm: [-150, 400, 300], rpy_deg: [0, 0, 90], label: A to the hold pose}
          - move: {pose: totem, label: A back up}
      - arm: B
        steps:
          - move: {pose: totem, label: B up to Totem}
          - wait: 20
          - move: {position_mm: [150, 450, 300], rpy_deg: [0, 0, 90], label: B reaches over}
          - move: {pose: totem, label: B back up}
"""

#: The same, ordered: B reaches over only once A signals it is back up.
ORDERED = CONFIRM_INSIDE.replace(
    "          - move: {pose: totem, label: A back up}\n",
    "          - move: {pose: totem, label: A back up}\n          - signal: A_up\n").replace(
    "          - wait: 20\n", "          - wait_for: {event: A_up, timeout_s: 120}\n")


@pytest.fixture
def campaign(tmp_path, monkeypatch):
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    folder = tmp_path / "two-arms"
    shutil.copytree(EXAMPLE, folder)
    monkeypatch.chdir(folder)
    return folder


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / "sequences" / name
    path.write_text(text)
    return path


def check(path: Path, **options):
    return check_arms_sequence(path, campaign_has_arms(path), **options)


# ------------------------------------------------------------------ (a) every timing
def test_a_confirm_that_lets_the_arms_meet_for_a_late_answer_is_refused_there(campaign):
    found = check(write(campaign, "confirm_inside.yaml", CONFIRM_INSIDE), dry_run=False)
    (error,) = found.errors
    lines = CONFIRM_INSIDE.splitlines()
    assert lines[error.line - 1].strip().startswith("- confirm:")
    assert error.column == lines[error.line - 1].index("confirm") + 1
    assert "waits for the operator's answer" in error.message
    assert "order the arms with signal/wait_for" in error.message.lower()
    assert "A.forearm" in error.message and "B." in error.message
    # the planned time line alone (the answer at once) sees them well apart
    (between,) = found.between
    assert between.distance_mm > 100


def test_the_same_moves_ordered_with_signal_and_wait_for_validate(campaign):
    found = check(write(campaign, "ordered.yaml", ORDERED), dry_run=False)
    assert found.errors == []


def test_the_shipped_examples_stay_valid_and_refused_as_they_were(campaign):
    good = check(campaign / "sequences" / "hold_and_approach.yaml", dry_run=False)
    assert good.errors == []
    bad = check(campaign / "sequences" / "paths_cross.yaml", dry_run=False)
    assert [e.message.startswith("the arms' paths cross") for e in bad.errors] == [True]


def test_offsets_are_proved_for_every_value_of_the_delays():
    from seqrun.sequence.arm_timing import Stamp, offset_range, rigid

    start = Stamp.zero()
    asked = start.plus(1.0).delayed(0)            # A after a confirm
    waited = start.plus(5.0).later(asked.plus(2.0))  # B waits for A's signal 2 s later
    assert offset_range(asked, start) == (1.0, float("inf"))
    # B ends its wait at max(5, 3 + d): 2 s after A's moment for a late answer, up to
    # 4 s for a quick one
    assert offset_range(waited, asked) == pytest.approx((2.0, 4.0))
    # once B waits for something A signals after the confirm, they move in step
    joined = start.delayed(0).later(start.plus(3.0))
    assert not rigid([(joined, asked)])
    both = asked.later(start)  # the join of a block: the later arm decides
    assert rigid([(both.plus(4.0), asked)])
    assert offset_range(asked, start, {0: 10.0}) == (1.0, 11.0)
