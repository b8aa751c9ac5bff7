"""seqrun halt and seqrun reset from a second terminal, against `seqrun sim serve`: every
one reaches every module and is confirmed — 20 of 20, idle and mid-move."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time

import can
import pytest

from seqrun.powercube.codec import (
    BroadcastRequest,
    GetParam,
    SetMotion,
    SetParam,
    decode_ack,
    encode,
)
from seqrun.powercube.protocol import CommandId, MotionMode, ParamId, StateFlag

ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}
ROUNDS = 20


def frame(request) -> can.Message:
    can_id, data = encode(request)
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


def states(bus) -> dict[int, StateFlag]:
    """CubeState of modules 1-7, read by this (independent) client."""
    while bus.recv(0) is not None:  # what is already here is older than the question
        pass
    for module in range(1, 8):
        bus.send(frame(GetParam(module, ParamId.CUBE_STATE)))
    found: dict[int, StateFlag] = {}
    deadline = time.monotonic() + 5
    while len(found) < 7 and time.monotonic() < deadline:
        msg = bus.recv(0.5)
        if msg is None or not 0x0A1 <= msg.arbitration_id <= 0x0A7:
            continue
        ack = decode_ack(msg.arbitration_id, bytes(msg.data))
        if getattr(ack, "param", None) == ParamId.CUBE_STATE:
            found[ack.module] = StateFlag(ack.value)
    assert len(found) == 7, f"no state from modules {sorted(set(range(1, 8)) - set(found))}"
    return found


def start_moving(bus, target: float) -> None:
    """Another master: every module ramps slowly (0.05 rad/s) towards ``target``."""
    bus.send(frame(BroadcastRequest(CommandId.HOME, 0)))
    for module in range(1, 8):
        bus.send(frame(SetParam(module, ParamId.TARGET_VEL, 0.05)))
        bus.send(frame(SetMotion(module, MotionMode.FRAMP, target)))
    deadline = time.monotonic() + 5
    while not all(s & StateFlag.MOTION for s in states(bus).values()):
        assert time.monotonic() < deadline, "the modules did not start moving"


def seqrun(port: int, command: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "seqrun", command, "-i", "socketcand", "--bus-kwargs",
         "host=127.0.0.1", f"port={port}"],
        capture_output=True, text=True, env=ENV, timeout=60)


@pytest.mark.slow
def test_halt_and_reset_from_separate_processes_20_of_20():
    server = subprocess.Popen([sys.executable, "-m", "seqrun", "sim", "serve", "--port", "0"],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                              env=ENV)
    failures = []
    try:
        port = int(re.search(r"127\.0\.0\.1:(\d+)", server.stdout.readline()).group(1))
        with can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0",
                     ignore_config=True, tcp_tune=True) as other:
            for round_ in range(ROUNDS):
                moving = round_ % 2 == 0
                if moving:
                    start_moving(other, 1.5 if round_ % 4 == 0 else -1.5)
                halt = seqrun(port, "halt")
                after_halt = states(other)
                if halt.returncode != 0 or "Halt confirmed by modules 1, 2, 3, 4, 5, 6, 7" \
                        not in halt.stdout:
                    failures.append(f"round {round_} halt: exit {halt.returncode} "
                                    f"{halt.stdout}{halt.stderr}")
                if not all(s & StateFlag.HALTED for s in after_halt.values()):
                    failures.append(f"round {round_} halt ({'moving' if moving else 'idle'})"
                                    f" not everywhere: {after_halt}")
                if any(s & StateFlag.MOTION for s in after_halt.values()):
                    failures.append(f"round {round_}: still moving after halt: {after_halt}")
                reset = seqrun(port, "reset")
                after_reset = states(other)
                if reset.returncode != 0 or "Reset confirmed" not in reset.stdout:
                    failures.append(f"round {round_} reset: exit {reset.returncode} "
                                    f"{reset.stdout}{reset.stderr}")
                if any(s.is_fault for s in after_reset.values()):
                    failures.append(f"round {round_} reset not everywhere: {after_reset}")
    finally:
        server.terminate()
        server.wait(timeout=10)
    assert failures == [], "\n".join(failures)
