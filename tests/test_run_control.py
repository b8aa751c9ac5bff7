"""`seqrun run` as the bus owner: what its control socket answers (status from the run's
own readings; halt confirmed by the run, or by its driver when the loop does not act)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from seqrun.arm.description import load_arm
from seqrun.clock import RealClock
from seqrun.service.connection import open_connection
from seqrun.arm.kinematics import Chain, fk
from seqrun.service.runner import build_executor
from seqrun.sequence.loader import load_sequence
from seqrun.service import run_control
from seqrun.service.run_control import RunControl
from seqrun.stop_requests import REMOTE_HALT, StopRequests

ROOT = Path(__file__).resolve().parents[1]
ARM = load_arm(ROOT / "arms" / "lwa3.yaml")


def test_status_is_the_runs_last_reading_with_velocity_and_end_effector():
    control = RunControl(ARM, StopRequests(), "sim")
    assert all(j["stale"] and j["position_deg"] is None for j in control.status_dict()["joints"])
    for k in range(12):   # j2 at 10 deg/s, 10 ms apart
        control.on_event({"type": "setpoint", "t": 1.0 + 0.01 * k,
                          "measured_deg": [0.0, 0.1 * k, 0, -30, 0, 20, 0],
                          "state": [32, 16, 32, 32, 32, 32, 32]})
    control.on_event({"type": "step_started", "step": 5, "label": "Up", "kind": "move"})
    status = control.status_dict()
    j2 = status["joints"][1]
    assert j2["position_deg"] == pytest.approx(1.1) and j2["velocity_deg_s"] == pytest.approx(10)
    assert j2["state"] == "MOTION" and not j2["fault"] and not j2["stale"]
    T = fk(Chain.from_arm(ARM), np.radians([0.0, 1.1, 0, -30, 0, 20, 0]))
    assert status["end_effector"]["position_mm"] == pytest.approx(T[:3, 3], abs=1e-3)
    assert status["step"] == {"step": 5, "label": "Up", "kind": "move"}
    # A reading after a Halt carries the state words: those are shown.
    control.on_event({"type": "measurement", "t": 2.0, "joints_deg": [0] * 7,
                      "state": [33] * 7, "states": {"2": "HOME_OK|HALTED|RAMP_END"}})
    assert control.status_dict()["joints"][1]["state"] == "HOME_OK|HALTED|RAMP_END"
    assert control.status_dict()["joints"][1]["fault"]


def test_halt_the_loop_does_not_act_on_is_confirmed_through_the_driver(monkeypatch):
    monkeypatch.setattr(run_control, "HALT_WAIT_S", 0.2)
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    connection = open_connection(force_sim=True, clock=RealClock())
    requests = StopRequests()
    try:
        executor, client = build_executor(loaded, ARM, connection, requests=requests)
        control = RunControl(ARM, requests, connection.description)
        control.attach(executor)   # the run's loop never runs: e.g. it waits for an answer
        answer = control.halt("seqrun halt from another process (pid 7)")
        assert answer["confirmed"] and answer["confirmed_by"] == "the run's process"
        assert answer["modules_confirmed"] == [1, 2, 3, 4, 5, 6, 7]
        assert all("HALTED" in text for text in answer["states"].values())
        # The request stays posted: the run ends as a fault when its loop comes back.
        (posted,) = requests.take()
        assert (posted.kind, posted.cause) == ("halt", REMOTE_HALT)
        client.close()
    finally:
        connection.close()


def test_halt_before_the_run_started_is_not_claimed_as_confirmed(monkeypatch):
    monkeypatch.setattr(run_control, "HALT_WAIT_S", 0.05)
    answer = RunControl(ARM, StopRequests()).halt("x")
    assert not answer["confirmed"] and "not started" in answer["error"]
