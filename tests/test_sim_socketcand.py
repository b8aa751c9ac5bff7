"""socketcand server in real time, driven by python-can's own socketcand client."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import can
import pytest
from typer.testing import CliRunner

from seqrun.cli import app
from seqrun.clock import RealClock, VirtualClock
from seqrun.powercube.codec import (
    BroadcastRequest,
    GetParam,
    GetParamAck,
    SetMotion,
    decode_ack,
    encode,
)
from seqrun.powercube.protocol import CommandId, MotionMode, ParamId, ShortState
from seqrun.sim.arm import SimArm
from seqrun.sim.network import SimNetwork, WireFrame
from seqrun.sim.socketcand import SocketcandServer, check_loopback, format_frame, parse_send


@pytest.fixture
def server():
    clock = RealClock()
    network = SimNetwork(clock, SimArm(clock, faults=["5:no_ack@0"]))
    with SocketcandServer(network, port=0, channel="can0") as srv:
        srv.start()
        yield srv


def connect(server, channel="can0"):
    return can.Bus(interface="socketcand", host="127.0.0.1", port=server.port,
                   channel=channel, ignore_config=True)


def message(req) -> can.Message:
    can_id, data = encode(req)
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


def receive_ack(bus, timeout=1.0):
    msg = bus.recv(timeout)
    assert msg is not None, "no frame from the server"
    return msg, decode_ack(msg.arbitration_id, bytes(msg.data))


def test_requests_and_acks_over_socketcand(server):
    with connect(server) as bus:
        bus.send(message(GetParam(3, ParamId.DEF_CUBE_VERSION)))
        msg, ack = receive_ack(bus)
        assert ack == GetParamAck(3, ParamId.DEF_CUBE_VERSION, 0x4638)
        assert not msg.is_extended_id and msg.is_rx
        assert abs(msg.timestamp - time.time()) < 5  # epoch, like socketcand
        bus.send(message(BroadcastRequest(CommandId.HOME, 0)))
        bus.send(message(SetMotion(2, MotionMode.FRAMP_ACK, 0.01)))
        _, ack = receive_ack(bus)  # the broadcast got no ack; this is the motion's
        assert ack.mode == MotionMode.FRAMP_ACK and ack.state == ShortState.RAMP_END
        bus.send(message(GetParam(5, ParamId.ACT_POS)))  # module 5: no_ack fault
        assert bus.recv(0.1) is None


def test_two_clients_see_each_other(server):
    with connect(server) as first, connect(server) as second:
        first.send(can.Message(arbitration_id=0x321, data=b"\x01\x02", is_extended_id=False))
        seen = second.recv(1.0)
        assert seen.arbitration_id == 0x321 and bytes(seen.data) == b"\x01\x02"
        second.send(message(GetParam(1, ParamId.ACT_POS)))
        request = first.recv(1.0)
        assert request.arbitration_id == 0x0C1  # the other client's request...
        _, ack = receive_ack(first)  # ...and the module's answer
        assert ack == GetParamAck(1, ParamId.ACT_POS, 0.0)
        _, ack = receive_ack(second)
        assert ack == GetParamAck(1, ParamId.ACT_POS, 0.0)
        assert first.recv(0.05) is None  # nothing else, and not its own frame
        assert server.client_count == 2


def test_unknown_channel_is_refused(server):
    with pytest.raises(can.CanError, match="error could not open bus vcan9"):
        connect(server, channel="vcan9")


def test_only_loopback_addresses():
    assert check_loopback("localhost") == "127.0.0.1"
    assert check_loopback("::1") == "::1"
    with pytest.raises(ValueError, match="not a loopback address"):
        check_loopback("0.0.0.0")
    with pytest.raises(ValueError, match="loopback IP address"):
        check_loopback("example.org")
    clock = VirtualClock()
    with pytest.raises(ValueError, match="real time"):
        SocketcandServer(SimNetwork(clock, SimArm(clock)), port=0)


def test_ascii_frames_match_python_can():
    line = format_frame(WireFrame(0x0A1, bytes.fromhex("0B0464")), 1700000000.1234567)
    assert line == "< frame 0A1 1700000000.123457 0B0464 >"
    parsed = can.interfaces.socketcand.socketcand.convert_ascii_message_to_can_message(line)
    assert parsed.arbitration_id == 0x0A1 and bytes(parsed.data) == bytes.fromhex("0B0464")
    assert not parsed.is_extended_id
    sent = can.interfaces.socketcand.socketcand.convert_can_message_to_ascii_message(
        message(SetMotion(1, MotionMode.FRAMP, 1.0)))
    words = re.fullmatch(r"< (.*) >", sent).group(1).split()
    assert words[0] == "send"
    assert parse_send(words[1:]) == WireFrame(0x0E1, bytes.fromhex("0B040000803F"))
    with pytest.raises(ValueError, match="length 3 but 1 data bytes"):
        parse_send(["0E1", "3", "0"])


def test_cli_refuses_a_non_loopback_host():
    result = CliRunner().invoke(app, ["sim", "serve", "--host", "0.0.0.0"])
    assert result.exit_code == 2
    assert "not a loopback address" in result.output


@pytest.mark.slow  # a real `seqrun sim serve` process, stopped by a real Ctrl-C
def test_cli_serves_until_ctrl_c():
    process = subprocess.Popen(
        [sys.executable, "-m", "seqrun", "sim", "serve", "--port", "0",
         "--fault", "2:halt@0"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        banner = process.stdout.readline()
        port = int(re.search(r"127\.0\.0\.1:(\d+)", banner).group(1))
        with can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0",
                     ignore_config=True) as bus:
            bus.send(message(GetParam(2, ParamId.CUBE_STATE)))
            _, ack = receive_ack(bus, timeout=2.0)
            assert ack.value & 0x4  # HALTED by the --fault
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=5)
        assert process.returncode == 0
        assert "stopping" in output and "Traceback" not in output
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
