"""Shared by the two-arm run tests: the example campaign of two arms (each on its built-in
simulator) copied into a test's folder, with a short sequence in which B waits for A."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from projecttree import ROOT

EXAMPLE = ROOT / "examples" / "two-arms"

#: A moves and signals; B waits for it, then moves; both turn back together.
SHORT = """\
name: Short
description: Both arms turn, B after A has.
steps:
  - parallel:
      - arm: A
        steps: [include: startup.yaml, {move: {joints: {j1: 10}}}, signal: A_turned]
      - arm: B
        steps: [include: startup.yaml, wait_for: A_turned, {move: {joints: {j1: -10}}}]
  - parallel:
      - {arm: A, steps: [{move: {joints: {j1: 0}}}]}
      - {arm: B, steps: [{move: {joints: {j1: 0}}}]}
"""


def two_arm_campaign(folder: Path, mp: pytest.MonkeyPatch, ros: str = "") -> Path:
    """``folder/two-arms``: the example campaign with ``sequences/short.yaml`` (and ``ros``
    appended to its seqrun.toml), made the working folder; no CAN bus from the environment,
    HOME and the arms' state (zero records) inside ``folder``."""
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        mp.delenv(name, raising=False)
    mp.setenv("HOME", str(folder))
    mp.setenv("SEQRUN_STATE_DIR", str(folder / "state"))
    campaign = folder / "two-arms"
    shutil.copytree(EXAMPLE, campaign)
    (campaign / "sequences" / "short.yaml").write_text(SHORT)
    if ros:
        with (campaign / "seqrun.toml").open("a") as f:
            f.write(ros)
    mp.chdir(campaign)
    return campaign
