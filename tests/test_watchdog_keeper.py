"""The watchdog keeper refreshes the modules only while the control loop makes progress.

In real time a background thread refreshes the modules' watchdogs while the run loop is not
on the bus. Before, it refreshed unconditionally: a runner alive but stuck (a deadlock, a
hung call) kept the modules going for as long as the hang lasted. Now it refreshes only
while the loop showed a sign of life within one refresh period, or waits for the
operator's answer. In process, real time, on the simulated arm with its watchdog armed.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from projecttree import make_project, shipped_arm
from seqrun.arm.description import load_arm
from seqrun.service.connection import open_connection
from seqrun.service.dryrun import prepare_started
from seqrun.results import EXIT_FAULT, EXIT_OK
from seqrun.powercube.protocol import StateFlag
from seqrun.service.runlog import read_trace
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence

SEQUENCE = """\
name: Keeper
description: A question, then one slow move of j1 (modules already started).
steps:
  - confirm: Ready?
  - move: {joints: {j1: 20}, velocity_deg_s: {j1: 10}, label: Slow move}
"""
STALL_S = 0.4


def project(tmp_path: Path) -> Path:
    root = make_project(tmp_path / "project", sequences=(),
                        arm_changes={"    enabled: false": "    enabled: true"})
    path = root / "sequences" / "keeper.yaml"
    path.write_text(SEQUENCE, encoding="utf-8")
    return path


def run(tmp_path: Path, *, confirm, stall_loop: bool):
    loaded = load_sequence(project(tmp_path))
    arm = load_arm(loaded.arm_path)
    assert arm.can.watchdog.enabled
    connection = open_connection(force_sim=True)          # real time
    stalled: list[float] = []

    def attach(executor) -> None:
        if not stall_loop:
            return
        check_guards = executor.check_guards
        calls = [0]

        def stuck(m):  # the loop hangs in the middle of the move (no bus, no sign of life)
            calls[0] += 1
            if calls[0] == 30:
                stalled.append(time.monotonic())
                time.sleep(STALL_S)
            return check_guards(m)

        executor.check_guards = stuck

    try:
        prepare_started(connection, arm)
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               confirm=confirm, on_executor=attach, html_report=False)
        states = [connection.bus.arm.module(m).state() for m in arm.module_ids]
        return outcome, states, stalled
    finally:
        connection.close()


def refresh_gaps(folder: Path) -> list[float]:
    times = [m.timestamp for m in read_trace(folder) if not m.is_rx
             and m.arbitration_id == 0x100 and bytes(m.data[:1]) == b"\x07"]
    return [b - a for a, b in zip(times, times[1:])]


@pytest.mark.slow
def test_a_stuck_loop_lets_the_watchdog_stop_the_modules(tmp_path):
    outcome, states, stalled = run(tmp_path, confirm=lambda prompt: True, stall_loop=True)
    assert stalled, "the loop never reached the stall"
    # No refresh while the loop was stuck: the modules stopped by themselves ...
    assert max(refresh_gaps(tmp_path / "run")) >= STALL_S * 0.9
    for flags in states:
        assert flags & StateFlag.HALTED and flags & StateFlag.COMM_ERROR, flags.describe()
    # ... and the loop, once it went on, saw it and ended with a fault.
    assert outcome.result.exit_code == EXIT_FAULT, outcome.result.message


@pytest.mark.slow
def test_a_question_keeps_the_modules_alive(tmp_path):
    """The operator takes his time: the loop waits for the answer, not stuck."""
    def slow_operator(prompt: str) -> bool:
        time.sleep(STALL_S)
        return True

    outcome, states, _ = run(tmp_path, confirm=slow_operator, stall_loop=False)
    assert outcome.result.exit_code == EXIT_OK, outcome.result.message
    assert max(refresh_gaps(tmp_path / "run")) < arm_refresh_period() * 2
    for flags in states:
        assert not flags & (StateFlag.HALTED | StateFlag.ERROR), flags.describe()


def arm_refresh_period() -> float:
    return shipped_arm().can.watchdog.refresh_period_s
