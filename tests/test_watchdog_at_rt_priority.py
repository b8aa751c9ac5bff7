"""The modules' watchdog on by default for the facility arm when the control loop runs at
real-time priority (issue 42): arms/lwa3.yaml's ``can.watchdog.with_rt_priority`` arms it
for the whole run with ``--rt-priority``, never at normal priority (where a busy PC
deschedules the loop past the modules' 50 ms: docs/safety.md has the measurements). A
watchdog that trips stops the modules, the run ends with a fault, and nothing resets or
moves them again by itself."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands on the app)
from projecttree import ROOT, make_project, shipped_arm
from runfolder import RunFolder
from seqrun.cli.app import app
from seqrun.powercube.protocol import StateFlag
from seqrun.results import EXIT_FAULT
from seqrun.sequence.loader import load_sequence
from seqrun.service import realtime
from seqrun.service.connection import open_connection
from seqrun.service.dryrun import prepare_started
from seqrun.service.runlog import read_trace
from seqrun.service.runner import run_sequence


def test_the_facility_arm_arms_it_at_real_time_priority_only():
    arm = shipped_arm()
    assert arm.can.watchdog.enabled is False and arm.can.watchdog.with_rt_priority is True
    assert arm.at_loop_priority(False) is arm
    assert arm.at_loop_priority(True).can.watchdog.enabled is True
    plain = arm.model_copy(update={"can": arm.can.model_copy(update={
        "watchdog": arm.can.watchdog.model_copy(update={"with_rt_priority": False})})})
    assert plain.at_loop_priority(True).can.watchdog.enabled is False


def _run(tmp_path: Path, *extra: str) -> tuple[int, str, list[dict]]:
    folder = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "totem.yaml"),
                                      "--virtual-time", "--yes", "--plain", "--no-report",
                                      "--log-dir", str(folder), *extra])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    events = RunFolder(folder).events()
    return result.exit_code, result.output, events


@pytest.fixture
def real_time_granted(monkeypatch):
    """The scheduler grants real-time priority (this test process keeps its own policy)."""
    monkeypatch.setattr(realtime, "use_round_robin", lambda *a: None)
    monkeypatch.setattr(realtime, "use_fifo", lambda priority: None)
    monkeypatch.setattr(realtime, "hand_over_the_lock_often", lambda: None)


def test_a_run_at_real_time_priority_arms_it_for_the_whole_run(tmp_path, real_time_granted):
    code, output, events = _run(tmp_path, "--rt-priority", "20")
    assert code == 0, output
    assert "watchdog: armed for the whole run (real-time priority" in output
    types = [e["type"] for e in events]
    assert "watchdog_enabled" in types
    first_move = next(i for i, e in enumerate(events)
                      if e["type"] == "step_started" and e.get("kind") == "move")
    assert types.index("watchdog_enabled") < first_move  # before anything moves
    assert "watchdog_disabled" in types  # a clean end disarms it again


def test_a_run_at_normal_priority_leaves_it_off(tmp_path):
    code, output, events = _run(tmp_path)
    assert code == 0, output
    assert "watchdog" not in output
    assert "watchdog_enabled" not in [e["type"] for e in events]


def test_real_time_refused_leaves_it_off(tmp_path, monkeypatch):
    monkeypatch.setattr(realtime, "use_round_robin", lambda *a: "not permitted")
    code, output, events = _run(tmp_path, "--rt-priority", "20")
    assert code == 0, output
    assert "real-time scheduling not available" in output
    assert "watchdog_enabled" not in [e["type"] for e in events]


SEQUENCE = """\
name: Stall
description: One slow move of j1 (modules already started); the loop hangs in it.
steps:
  - move: {joints: {j1: 20}, velocity_deg_s: {j1: 10}, label: Slow move}
"""


@pytest.mark.slow  # real time, in process, with a 0.4 s hang of the loop
def test_a_tripped_watchdog_stops_the_arm_and_nothing_restarts_it(tmp_path):
    root = make_project(tmp_path / "p", sequences=())
    (root / "sequences" / "stall.yaml").write_text(SEQUENCE, encoding="utf-8")
    loaded = load_sequence(root / "sequences" / "stall.yaml")
    arm = shipped_arm().at_loop_priority(True)  # what --rt-priority runs with
    connection = open_connection(force_sim=True)          # real time
    stalled: list[float] = []

    def attach(executor) -> None:
        check_guards = executor.check_guards
        calls = [0]

        def stuck(m):  # the loop hangs in the middle of the move (no bus, no sign of life)
            calls[0] += 1
            if calls[0] == 30:
                stalled.append(time.time())
                time.sleep(0.4)
            return check_guards(m)

        executor.check_guards = stuck

    try:
        prepare_started(connection, arm)
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               confirm=lambda prompt: True, on_executor=attach,
                               html_report=False)
        ended = connection.bus.arm.positions()
        time.sleep(0.3)  # a while after the run: still nothing moves by itself
        states = [connection.bus.arm.module(m).state() for m in arm.module_ids]
        later = connection.bus.arm.positions()
    finally:
        connection.close()
    # (the hang makes the trip certain; a busy host may trip it earlier: the same story)
    assert outcome.result.exit_code == EXIT_FAULT, outcome.result.message
    assert "COMM_ERROR" in outcome.result.message  # the modules' watchdogs stopped them
    for flags in states:  # stopped by their watchdogs, and still stopped
        assert flags & StateFlag.HALTED, flags.describe()
    assert later == ended
    sent = [m for m in read_trace(tmp_path / "run") if not m.is_rx]
    # (the cycle the loop hung in may still send its one setpoint; from the Halt on, nothing)
    halt = next(m.timestamp for m in sent
                if m.arbitration_id == 0x100 and bytes(m.data[:1]) == b"\x02")
    after = [m for m in sent if m.timestamp > halt]
    motion = [m for m in after if bytes(m.data[:1]) == b"\x0b"]  # SetMotion
    resets = [m for m in after if m.arbitration_id == 0x100 and bytes(m.data[:1]) == b"\x00"]
    homes = [m for m in after if m.arbitration_id == 0x100 and bytes(m.data[:1]) == b"\x01"]
    assert (motion, resets, homes) == ([], [], []), (motion, resets, homes)
