"""The commands beside a holder of the bus that serves no control socket (a `seqrun
reset` in progress, say, or a run before its socket is up), in process and fast: refused
with one line naming it (exit 2); `halt` still reaches the modules and says it could not
confirm (exit 3)."""

from __future__ import annotations

import re
import time

import can
import pytest
from typer.testing import CliRunner

from seqrun.cli import app
from seqrun.clock import RealClock
from seqrun.powercube.codec import GetParam, decode_ack, encode
from seqrun.powercube.protocol import ParamId, StateFlag
from seqrun.service.bus_claim import claim_bus
from seqrun.sim.arm import SimArm
from seqrun.sim.network import SimNetwork
from seqrun.sim.socketcand import SocketcandServer


@pytest.fixture
def held(tmp_path, monkeypatch):
    """A served arm and a claim of its bus held by this process."""
    monkeypatch.setenv("SEQRUN_RUNTIME_DIR", str(tmp_path / "rt"))
    clock = RealClock()
    server = SocketcandServer(SimNetwork(clock, SimArm(clock), spin_window=0.0), port=0)
    server.start()
    claim = claim_bus("socketcand", f"127.0.0.1:{server.port}/can0", "seqrun run held.yaml")
    yield server
    claim.release()
    server.shutdown()


def _args(server) -> list[str]:
    return ["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1", f"port={server.port}"]


HELD = (r"error: socketcand:127\.0\.0\.1:\d+/can0 is held by pid \d+ \(seqrun run "
        r"held\.yaml\) since \d\d:\d\d:\d\d: one controller per bus; 'seqrun status' and "
        r"'seqrun halt' talk to it")


@pytest.mark.parametrize("command", [["reset"], ["home"], ["limits", "show"], ["limits", "set"], ["status"], ["status", "--json"],
                                     ["pose", "save", "x", "-o", "{tmp}/x.yaml"]])
def test_commands_are_refused_naming_the_holder(held, command, tmp_path):
    command = [part.format(tmp=tmp_path) for part in command]
    result = CliRunner().invoke(app, [*command, *_args(held)])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and re.fullmatch(HELD, lines[0]), result.output


def test_halt_is_sent_all_the_same_but_not_claimed_as_confirmed(held):
    result = CliRunner().invoke(app, ["halt", *_args(held)])
    assert result.exit_code == 3, result.output
    first, last = result.output.strip().splitlines()
    assert first.startswith("arm ") and "socketcand" in first   # which arm, which bus
    assert re.fullmatch(r"error: Halt broadcast sent, but not confirmed: " + HELD[7:],
                        last), result.output
    # The broadcast reached the modules.
    with can.Bus(interface="socketcand", host="127.0.0.1", port=held.port, channel="can0",
                 ignore_config=True) as bus:
        # Two TCP sessions of the server are read independently: the Halt the command
        # handed to its session may be read after this client's first question.
        can_id, data = encode(GetParam(1, ParamId.CUBE_STATE))
        state = StateFlag(0)
        for _ in range(20):
            bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
            msg = bus.recv(2.0)
            while msg is not None and msg.arbitration_id != 0x0A1:   # (the Halt itself)
                msg = bus.recv(2.0)
            assert msg is not None
            state = StateFlag(decode_ack(msg.arbitration_id, bytes(msg.data)).value)
            if state & StateFlag.HALTED:
                break
            time.sleep(0.05)
        assert state & StateFlag.HALTED, state.describe()
