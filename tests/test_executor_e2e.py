"""End to end at virtual time: the operator's path (runner -> client -> simulated arm).

Each test runs a shipped or small sequence on a fresh simulated arm (powered on in Park)
and checks what the bus, the run folder and the arm show afterwards.
"""

from __future__ import annotations

import math
import shutil
import xml.etree.ElementTree as ET

import can
import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT
from runfolder import RunFolder
from seqrun.arm.description import load_arm
from seqrun.cli.app import app
from seqrun.clock import VirtualClock
from seqrun.service.connection import open_connection
from seqrun.results import EXIT_FAULT, EXIT_INVALID, EXIT_OK, EXIT_OPERATOR_ABORT
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.drivers.powercube.units import to_module_rad
from simrun import run_on_sim

HALT = (0x100, 0x02)


def is_halt(msg: can.Message) -> bool:
    return msg.arbitration_id == 0x100 and msg.data[:1] == b"\x02"


def is_motion(msg: can.Message) -> bool:
    return (0x0E1 <= msg.arbitration_id <= 0x0FF and not msg.is_rx
            and msg.data[:1] == b"\x0b")


def test_opsafe_from_power_on_to_a_passed_checkpoint(tmp_path, arm):
    outcome, sim, _ = run_on_sim("opsafe", tmp_path)
    result = outcome.result
    assert result.exit_code == EXIT_OK, result.message
    folder = outcome.log_dir
    report = RunFolder(folder).report()
    assert report["status"] == "passed" and report["exit_code"] == 0
    assert report["start"] and report["end"]
    [checkpoint] = report["checkpoints"]
    assert checkpoint["status"] == "passed" and checkpoint["position_error_mm"] < 1.0
    # The moves track their ruckig plans: executed / planned within 5 % per move and overall.
    moves = [s for s in report["steps"] if s["kind"] == "move"]
    assert len(moves) == 2
    for move in moves:
        assert move["executed_duration_s"] / move["planned_duration_s"] <= 1.05
        # A velocity_scale 0.5 move stays at half the arm's 30 deg/s (plus the reserve).
        assert max(move["peak_measured_velocity_deg_s"]) <= 15.0 / 0.95 + 0.2
    assert report["planned_duration_s"] == pytest.approx(
        sum(m["planned_duration_s"] for m in moves), abs=1e-3)
    # The simulated arm is at Op-safe (module = user + offset).
    opsafe = [70, 30, 0, 70, 20, 50, 0]
    for joint, want in zip(arm.joints, opsafe):
        assert math.degrees(sim.module(joint.module).position()) - joint.offset_deg == \
            pytest.approx(want, abs=0.2)
    # Run folder: readable trace with no Halt, events ending in run_finished, junit.
    trace = RunFolder(folder).trace()
    assert len(trace) > 1000 and not any(is_halt(m) for m in trace)
    assert any(m.is_rx for m in trace) and any(not m.is_rx for m in trace)
    assert RunFolder(folder).events()[-1]["type"] == "run_finished"
    suite = ET.parse(folder / "junit.xml").getroot().find("testsuite")
    assert suite.get("tests") == str(len(report["steps"])) and suite.get("failures") == "0"


def test_invalid_file_sends_nothing(tmp_path, monkeypatch):
    sent = []
    monkeypatch.setattr("seqrun.sim.bus.SimBus.send", lambda self, msg, timeout=None:
                        sent.append(msg))
    result = CliRunner().invoke(app, ["run", str(ROOT / "tests/data/bad/out_of_limit.yaml"),
                                      "--virtual-time", "--yes", "--plain",
                                      "--log-dir", str(tmp_path / "run")])
    assert result.exit_code == EXIT_INVALID
    assert "out_of_limit.yaml:7:33:" in result.output
    assert sent == [] and RunFolder(tmp_path / "run").trace_path() is None
    assert RunFolder(tmp_path / "run").report()["status"] == "refused"


def test_sequence_invalid_from_the_measured_state_moves_nothing(project, tmp_path):
    # Valid YAML, but on a freshly powered-on arm the modules refuse motion before Home.
    (project / "sequences" / "nohome.yaml").write_text(
        "name: no home\ndescription: moves without start-up\nsteps:\n  - move: totem\n")
    outcome, sim, _ = run_on_sim("nohome", tmp_path, root=project)
    assert outcome.result.exit_code == EXIT_INVALID
    assert "home" in outcome.result.message.lower()
    trace = RunFolder(outcome.log_dir).trace()
    assert trace and not any(is_motion(m) for m in trace)   # reads only


def test_operator_abort_mid_move_is_a_controlled_stop_and_the_arm_holds(tmp_path):
    def abort_at_two_seconds(executor):
        def listener(event):
            if event["type"] == "setpoint" and event["plan_t"] >= 2.0 and event.get("step") == 5:
                executor.abort("test: operator abort")
        executor.listeners.append(listener)

    outcome, sim, connection = run_on_sim("opsafe", tmp_path, on_executor=abort_at_two_seconds)
    assert outcome.result.exit_code == EXIT_OPERATOR_ABORT
    kinds = [e["type"] for e in RunFolder(outcome.log_dir).events()]
    assert "controlled_stop" in kinds and "holding" in kinds
    trace = RunFolder(outcome.log_dir).trace()
    assert not any(is_halt(m) for m in trace)        # a controlled stop, not a Halt
    # Stopped and holding: no velocity, and nothing moves when time goes on.
    clock = connection.clock
    before = sim.positions()
    assert all(abs(sim.module(m).velocity()) < 1e-9 for m in before)
    clock.advance(5.0)
    assert sim.positions() == pytest.approx(before, abs=1e-12)
    report = RunFolder(outcome.log_dir).report()
    assert report["status"] == "aborted" and report["exit_code"] == 130


def test_second_abort_halts(tmp_path):
    def abort_twice(executor):
        def listener(event):
            if event["type"] == "setpoint" and event["plan_t"] >= 2.0 and event.get("step") == 5:
                executor.abort("first")
            if event["type"] == "controlled_stop":
                executor.abort("second")
        executor.listeners.append(listener)

    outcome, sim, _ = run_on_sim("opsafe", tmp_path, on_executor=abort_twice)
    assert outcome.result.exit_code == EXIT_OPERATOR_ABORT
    trace = RunFolder(outcome.log_dir).trace()
    halts = [i for i, m in enumerate(trace) if is_halt(m)]
    assert halts, "a second abort must broadcast Halt"
    assert not any(is_motion(m) for m in trace[halts[0]:])


def test_speed_override_slows_every_move(tmp_path):
    fast, _, _ = run_on_sim("totem", tmp_path / "fast")
    slow, _, _ = run_on_sim("totem", tmp_path / "slow", speed=0.5)
    assert fast.result.exit_code == slow.result.exit_code == EXIT_OK
    assert slow.result.planned_duration_s > 1.8 * fast.result.planned_duration_s
    report = RunFolder(slow.log_dir).report()
    assert report["speed"] == 0.5


def test_from_step_refuses_an_arm_that_is_not_where_the_step_expects_it(tmp_path):
    # Step 6 of opsafe moves Totem -> Op-safe; a freshly powered-on arm is in Park.
    outcome, sim, _ = run_on_sim("opsafe", tmp_path, first_step=6)
    assert outcome.result.exit_code == EXIT_INVALID
    assert "--from 6: the arm is not where this step expects it" in outcome.result.message
    assert not any(is_motion(m) for m in RunFolder(outcome.log_dir).trace())


def test_from_step_runs_the_rest_when_the_arm_is_there(tmp_path, arm):
    at_totem = {j.module: to_module_rad(j, 0.0) for j in arm.joints}
    outcome, sim, _ = run_on_sim("opsafe", tmp_path, first_step=6, positions=at_totem, started=True)
    assert outcome.result.exit_code == EXIT_OK, outcome.result.message
    statuses = [s.status for s in outcome.result.steps]
    assert statuses[:5] == ["skipped"] * 5 and set(statuses[5:]) == {"passed"}


def test_a_checkpoint_that_is_not_met_halts_with_exit_3(tmp_path):
    """The arm ends somewhere else (a joint nudged after the last move): the checkpoint
    compares the measured FK with the expected pose and aborts."""
    def nudge_before_checkpoint(executor):
        def listener(event):
            if event["type"] == "step_started" and event["kind"] == "checkpoint":
                module = executor.client  # the simulator is reached through the bus
                sim = connection_holder["sim"]
                sim.module(1).set_position(sim.module(1).position() + math.radians(5))
                del module
        executor.listeners.append(listener)

    connection_holder: dict = {}
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    arm = load_arm(loaded.arm_path)
    connection = open_connection(force_sim=True, clock=VirtualClock())
    connection_holder["sim"] = connection.bus.arm
    try:
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               confirm=lambda p: True, on_executor=nudge_before_checkpoint,
                               html_report=False)
    finally:
        connection.close()
    assert outcome.result.exit_code == EXIT_FAULT
    assert outcome.result.fault["cause"] == "checkpoint"
    report = RunFolder(tmp_path / "run").report()
    [checkpoint] = report["checkpoints"]
    assert checkpoint["status"] == "failed" and checkpoint["position_error_mm"] > 7.0
    assert any(is_halt(m) for m in RunFolder(tmp_path / "run").trace())


def test_injected_tow_error_halts_and_names_the_module(tmp_path):
    outcome, sim, _ = run_on_sim("opsafe", tmp_path, faults=["4:tow_error@3"])
    result = outcome.result
    assert result.exit_code == EXIT_FAULT
    assert result.fault["module"] == 4 and result.fault["cause"] == "tow_error"
    trace = RunFolder(outcome.log_dir).trace()
    first_halt = next(m for m in trace if is_halt(m))
    assert 3.0 <= first_halt.timestamp - trace[0].timestamp <= 3.0 + 0.1 + 0.02
    assert not any(is_motion(m) for m in trace[trace.index(first_halt):])


def test_watchdog_is_fed_during_the_run_and_disarmed_after_it(project, tmp_path):
    arm_file = project / "arms" / "lwa3.yaml"
    arm_file.write_text(arm_file.read_text().replace("    enabled: false", "    enabled: true"))
    shutil.copy(ROOT / "sequences" / "totem.yaml", project / "sequences")
    outcome, sim, connection = run_on_sim("totem", tmp_path, root=project)
    assert outcome.result.exit_code == EXIT_OK, outcome.result.message
    kinds = [e["type"] for e in RunFolder(outcome.log_dir).events()]
    assert "watchdog_enabled" in kinds and "watchdog_disabled" in kinds
    refreshes = [m for m in RunFolder(outcome.log_dir).trace()
                 if m.arbitration_id == 0x100 and m.data[:1] == b"\x07"]
    gaps = [b.timestamp - a.timestamp for a, b in zip(refreshes, refreshes[1:])]
    assert refreshes and max(gaps) < 0.05        # never a gap the 50 ms watchdog would see
    # Disarmed at the clean end: the arm keeps holding, it does not halt on its own.
    connection.clock.advance(1.0)
    assert not any(s & 0x4 for s in sim.states().values())   # no HALTED


def test_cli_run_virtual_time_end_to_end(tmp_path):
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "opsafe.yaml"),
                                      "--virtual-time", "--yes", "--plain",
                                      "--log-dir", str(tmp_path / "run")])
    assert result.exit_code == 0, result.output
    assert "PASSED (exit 0)" in result.output and "Traceback" not in result.output
    assert RunFolder(tmp_path / "run").report()["status"] == "passed"


def test_an_unexpected_error_in_a_step_halts_and_is_reported_without_traceback(tmp_path,
                                                                              monkeypatch):
    from seqrun.steps import registry as steps

    def broken(step, ex):
        raise ZeroDivisionError("simulated bug")
    monkeypatch.setitem(steps.HANDLERS, "wait", broken)
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "opsafe.yaml"),
                                      "--virtual-time", "--yes", "--plain", "--no-report",
                                      "--log-dir", str(tmp_path / "run")])
    assert result.exit_code == EXIT_FAULT
    assert "internal error (ZeroDivisionError: simulated bug)" in result.output
    assert "Traceback" not in result.output
    assert any(is_halt(m) for m in RunFolder(tmp_path / "run").trace())
    [internal] = [e for e in RunFolder(tmp_path / "run").events() if e["type"] == "internal_error"]
    assert "ZeroDivisionError" in internal["traceback"]


def test_frames_that_answer_nothing_are_logged_as_discarded(tmp_path):
    from seqrun.sim.bus import SimBus

    loaded = load_sequence(ROOT / "sequences" / "totem.yaml")
    arm = load_arm(loaded.arm_path)
    connection = open_connection(force_sim=True, clock=VirtualClock())
    intruder = SimBus(channel=connection.bus.channel, clock=connection.clock)

    def inject_once(executor):
        def listener(event):
            if event["type"] == "setpoint" and not getattr(listener, "done", False):
                listener.done = True   # an ack of a CubeState read nobody asked for
                intruder.send(can.Message(arbitration_id=0x0A5, is_extended_id=False,
                                          data=[0x0A, 0x27, 0x02, 0x80, 0, 0]))
        executor.listeners.append(listener)
    try:
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               confirm=lambda p: True, on_executor=inject_once,
                               html_report=False)
    finally:
        intruder.shutdown()
        connection.close()
    assert outcome.result.exit_code == EXIT_OK
    [discarded] = [e for e in RunFolder(tmp_path / "run").events() if e["type"] == "frame_discarded"]
    assert discarded["can_id"] == "0x0A5" and discarded["data"].startswith("0a 27")


def test_a_display_that_raises_systemexit_cannot_end_the_run(tmp_path):
    """rich answers a closed stdout pipe with SystemExit from inside the listener."""
    def broken_display(executor):
        def listener(event):
            if event["type"] == "setpoint":
                raise SystemExit(1)
        executor.listeners.append(listener)

    outcome, sim, _ = run_on_sim("totem", tmp_path, on_executor=broken_display)
    assert outcome.result.exit_code == EXIT_OK
    assert any(e["type"] == "listener_failed" for e in RunFolder(outcome.log_dir).events())


def test_keyboardinterrupt_escaping_a_step_still_halts(tmp_path, monkeypatch):
    from seqrun.steps import registry as steps

    def interrupted(step, ex):
        raise KeyboardInterrupt
    monkeypatch.setitem(steps.HANDLERS, "wait", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_on_sim("opsafe", tmp_path)
    trace = RunFolder(tmp_path / "run").trace()
    assert any(is_halt(m) for m in trace)
    assert [e for e in RunFolder(tmp_path / "run").events() if e["type"] == "fault"][0]["cause"] == "interrupted"


def test_step_mode_asks_before_each_step_and_a_no_ends_the_run(tmp_path):
    args = ["run", str(ROOT / "sequences" / "totem.yaml"), "--virtual-time", "--yes", "--plain",
            "--step", "--no-report"]
    # Yes to the three start-up steps and the confirm step, no to the move.
    declined = CliRunner().invoke(app, args + ["--log-dir", str(tmp_path / "no")],
                                  input="y\ny\ny\ny\nn\n")
    assert declined.exit_code == EXIT_OPERATOR_ABORT, declined.output
    assert "Run step 5/6: Up to Totem" in declined.output
    assert not any(is_motion(m) for m in RunFolder(tmp_path / "no").trace())
    accepted = CliRunner().invoke(app, args + ["--log-dir", str(tmp_path / "yes")],
                                  input="y\n" * 6)
    assert accepted.exit_code == EXIT_OK, accepted.output
    assert accepted.output.count("Run step ") == 6
