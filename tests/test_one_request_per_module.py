"""Issue 9.3: never two requests in flight to one module.

The simulator's ``drop_request_while_busy`` switch makes a module drop an addressed request
that arrives before it has sent the acknowledge of the previous one. The client keeps one
request in flight per module, so ``opsafe.yaml`` completes under it and nothing is dropped.
"""

from __future__ import annotations

import itertools
import os
import subprocess
import sys

import can
import pytest

from projecttree import ROOT
from runfolder import RunFolder
from seqrun.clock import VirtualClock
from seqrun.service.connection import sim_options_from_env
from seqrun.errors import UserInputError
from seqrun.powercube.codec import GetParam, SetParam, encode
from seqrun.powercube.protocol import ParamId
from seqrun.sim.bus import SimBus
from seqrun.sim.module import ModuleOptions
from seqrun.sim.options import parse_module_options
from simrun import run_on_sim

BUSY = ModuleOptions(drop_request_while_busy=True)
_channels = itertools.count()


def test_a_module_drops_a_request_that_arrives_before_its_previous_answer_was_sent():
    clock = VirtualClock()
    bus = SimBus(channel=f"test-busy-{next(_channels)}", clock=clock, options=BUSY)
    try:
        for request in (SetParam(2, ParamId.TARGET_VEL, 0.1), GetParam(2, ParamId.ACT_POS),
                        GetParam(3, ParamId.ACT_POS)):
            can_id, data = encode(request)
            bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        answers = []
        while (msg := bus.recv(0.01)) is not None:
            answers.append(msg.arbitration_id)
        # Module 2 answered the first request only; module 3 was not busy.
        assert sorted(answers) == [0x0A2, 0x0A3]
        (dropped,) = bus.arm.dropped_while_busy
        assert dropped[1] == 2
        # Once its answer is on the wire, module 2 takes requests again.
        can_id, data = encode(GetParam(2, ParamId.ACT_POS))
        bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        assert bus.recv(0.01).arbitration_id == 0x0A2
    finally:
        bus.shutdown()


def test_the_ramp_cycle_keeps_one_request_in_flight_per_module(tmp_path, monkeypatch):
    # The simulator option comes from the environment, as on the command line.
    monkeypatch.setenv("SEQRUN_SIM_OPTIONS", "drop_request_while_busy")
    outcome, sim, _ = run_on_sim("opsafe", tmp_path)
    assert sim.options.drop_request_while_busy
    assert outcome.result.exit_code == 0, outcome.result.message
    assert sim.dropped_while_busy == []
    for move in (s for s in outcome.result.steps if s.kind == "move"):
        assert move.detail["executed_duration_s"] / move.planned_duration_s <= 1.05


def test_step_mode_under_the_switch_completes_too(tmp_path, monkeypatch):
    monkeypatch.setenv("SEQRUN_SIM_OPTIONS", "drop_request_while_busy")
    outcome, sim, _ = run_on_sim("opsafe", tmp_path, command_mode="step")
    assert outcome.result.exit_code == 0, outcome.result.message
    assert sim.dropped_while_busy == []


def test_sim_options_spec():
    options = parse_module_options("framp_from_standstill, watchdog_timeout=0.1 "
                                   "ack_refused_motion=false")
    assert options.framp_from_standstill and options.watchdog_timeout == 0.1
    assert options.ack_refused_motion is False
    with pytest.raises(ValueError, match="unknown simulator option 'nope'"):
        parse_module_options("nope")
    with pytest.raises(UserInputError, match="SEQRUN_SIM_OPTIONS"):
        sim_options_from_env({"SEQRUN_SIM_OPTIONS": "step_buffering=maybe"})
    assert sim_options_from_env({}) is None


@pytest.mark.slow   # two real processes (the fast tier reads the variable in process:
#                     test_the_switch_catches_a_client_that_pipelines_two_requests_to_one_module)
def test_cli_takes_simulator_options_from_the_environment(tmp_path):
    env = dict(os.environ, SEQRUN_SIM_OPTIONS="drop_request_while_busy",
               PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-m", "seqrun", "run", "sequences/opsafe.yaml",
                           "--virtual-time", "--yes", "--plain", "--no-report", "--log-dir",
                           str(tmp_path / "run")], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "options drop_request_while_busy" in " ".join(proc.stdout.split())
    report = RunFolder(tmp_path / "run").report()
    assert report["status"] == "passed"
    bad = subprocess.run([sys.executable, "-m", "seqrun", "run", "sequences/opsafe.yaml",
                          "--virtual-time", "--yes", "--plain", "--log-dir",
                          str(tmp_path / "bad")], cwd=ROOT, capture_output=True, text=True,
                         env=dict(env, SEQRUN_SIM_OPTIONS="nope"), timeout=300)
    assert bad.returncode == 2
    assert "unknown simulator option 'nope'" in bad.stdout + bad.stderr
    assert "Traceback" not in bad.stdout + bad.stderr


def test_the_switch_catches_a_client_that_pipelines_two_requests_to_one_module(
        tmp_path, monkeypatch):
    # The old sending (everything at once, TargetVel and FRAMP_ACK to one module back to
    # back) loses answers under the switch: the run halts instead of completing.
    from seqrun.powercube.client import PowerCubeClient

    monkeypatch.setenv("SEQRUN_SIM_OPTIONS", "drop_request_while_busy")
    monkeypatch.setattr(PowerCubeClient, "ONE_REQUEST_PER_MODULE", False)
    outcome, sim, _ = run_on_sim("opsafe", tmp_path)
    assert outcome.result.exit_code == 3
    assert outcome.result.fault["cause"] == "no_acknowledge"
    assert sim.dropped_while_busy
