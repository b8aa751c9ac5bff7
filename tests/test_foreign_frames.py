"""Another master on the bus: request frames this process did not send halt a run (exit 3,
"another controller is on the bus (frame ...)"); a Halt broadcast from another process is
named as one. And the premise: no transport hands a client its own frames back."""

from __future__ import annotations

import json
import time
from pathlib import Path

import can
import pytest

from seqrun.arm.description import load_arm
from seqrun.clock import RealClock, VirtualClock
from seqrun.service.connection import Connection, open_connection
from seqrun.service.runlog import read_trace
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.drivers.powercube.foreign import ForeignFrame, ForeignFrameWatch, is_request_frame
from seqrun.sim.arm import SimArm
from seqrun.sim.bus import SimBus
from seqrun.sim.network import SimNetwork
from seqrun.sim.socketcand import SocketcandServer
from runfolder import RunFolder

ROOT = Path(__file__).resolve().parents[1]
ARM = load_arm(ROOT / "arms" / "lwa3.yaml")
#: GetExtended DefCubeVersion of module 31: a request frame nobody answers.
PROBE = can.Message(arbitration_id=0x0DF, data=b"\x0a\x1d", is_extended_id=False)


def _received(bus, seconds: float) -> list[can.Message]:
    out, end = [], time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        msg = bus.recv(left)
        if msg is not None:
            out.append(msg)
    return out


def _own_frames_come_back(sender, other) -> tuple[bool, bool]:
    """(sender received its own frame, the other node received it)."""
    sender.send(PROBE)
    theirs = [m for m in _received(other, 0.3) if m.arbitration_id == PROBE.arbitration_id]
    ours = [m for m in _received(sender, 0.2) if m.arbitration_id == PROBE.arbitration_id]
    return bool(ours), bool(theirs)


def test_the_simulator_never_hands_a_node_its_own_frames():
    clock = RealClock()
    with SimBus(channel="own-frames", clock=clock) as a, \
            SimBus(channel="own-frames", clock=clock) as b:
        assert _own_frames_come_back(a, b) == (False, True)


def test_sim_serve_never_hands_a_client_its_own_frames():
    clock = RealClock()
    with SocketcandServer(SimNetwork(clock, SimArm(clock)), port=0, channel="can0") as server:
        server.start()
        buses = [can.Bus(interface="socketcand", host="127.0.0.1", port=server.port,
                         channel="can0", ignore_config=True) for _ in range(2)]
        try:
            assert _own_frames_come_back(*buses) == (False, True)
        finally:
            for bus in buses:
                bus.shutdown()


def test_python_can_virtual_bus_hands_back_own_frames_only_when_asked():
    with can.Bus(interface="virtual", channel="own", ignore_config=True) as a, \
            can.Bus(interface="virtual", channel="own", ignore_config=True) as b:
        assert _own_frames_come_back(a, b) == (False, True)
    with can.Bus(interface="virtual", channel="own2", receive_own_messages=True,
                 ignore_config=True) as a, \
            can.Bus(interface="virtual", channel="own2", ignore_config=True) as b:
        assert _own_frames_come_back(a, b) == (True, True)


def _msg(can_id: int, data: bytes, *, rx: bool = True, extended: bool = False) -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=extended, is_rx=rx)


def test_the_watch_reports_request_frames_received_only():
    seen: list[ForeignFrame] = []
    watch = ForeignFrameWatch(seen.append)
    watch(_msg(0x0C3, b"\x0a\x62", rx=False))           # ours, sent
    watch(_msg(0x0A3, b"\x0a\x62" + bytes(6)))           # an acknowledge
    watch(_msg(0x0C3, b"\x0a\x62", extended=True))       # a 29-bit id
    watch(_msg(0x05A, b"\x0a\x62"))                      # some other node's id
    assert seen == []
    for can_id in (0x0C1, 0x0DF, 0x0E1, 0x0FF, 0x100):
        watch(_msg(can_id, b"\x0a\x1d"))
    assert [f.can_id for f in seen] == [0x0C1, 0x0DF, 0x0E1, 0x0FF, 0x100]
    assert not is_request_frame(_msg(0x101, b"\x00")) and not is_request_frame(_msg(0xBF, b""))


def test_with_receive_own_messages_each_own_frame_is_expected_back_once():
    seen: list[ForeignFrame] = []
    watch = ForeignFrameWatch(seen.append, echoes_own=True)
    watch(_msg(0x0C3, b"\x0a\x62", rx=False))
    watch(_msg(0x0C3, b"\x0a\x62"))          # our echo
    assert seen == []
    watch(_msg(0x0C3, b"\x0a\x62"))          # the same question again: someone else's
    assert [f.frame() for f in seen] == ["frame 0x0C3 [0A 62]: GetExtended FPOS_STATE_DIO "
                                         "to module 3"]


def test_messages_name_the_frame_and_a_halt_broadcast():
    assert ForeignFrame(0x0E4, bytes.fromhex("0b040000803f")).message() == (
        "another controller is on the bus (frame 0x0E4 [0B 04 00 00 80 3F]: SetMotion FRAMP "
        "to module 4)")
    halt = ForeignFrame(0x100, b"\x02\x00")
    assert halt.is_halt and halt.message() == \
        "Halt broadcast from another process (frame 0x100 [02 00])"
    assert ForeignFrame(0x100, b"\x07").message() == (
        "another controller is on the bus (frame 0x100 [07]: WatchdogRefresh broadcast)")
    assert ForeignFrame(0x0C5, b"\xff").message() == \
        "another controller is on the bus (frame 0x0C5 [FF])"


def _run_with_intruder(tmp_path: Path, frame: can.Message, at_s: float):
    """opsafe.yaml at virtual time; a second node sends ``frame`` once the run's clock
    passes ``at_s`` (right after one of the run's own requests)."""
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    clock = VirtualClock()
    connection = open_connection(force_sim=True, clock=clock)
    intruder = SimBus(channel=connection.bus.channel, clock=clock)
    sent: list[float] = []

    def hook(executor) -> None:
        def on_frame(msg: can.Message) -> None:
            if not msg.is_rx and not sent and clock.now() >= at_s:
                sent.append(clock.now())
                intruder.send(frame)
        executor.client.add_frame_listener(on_frame)

    try:
        outcome = run_sequence(loaded, ARM, Connection(connection.bus, clock, True, "sim"),
                               log_dir=tmp_path / "run", confirm=lambda prompt: True,
                               on_executor=hook, html_report=False)
    finally:
        intruder.shutdown()
        connection.close()
    trace = read_trace(tmp_path / "run", run_clock=True)
    halts = [m.timestamp for m in trace if not m.is_rx and m.arbitration_id == 0x100
             and m.data[:1] == b"\x02"]
    return outcome, sent[0], halts


@pytest.mark.parametrize("at_s", [3.0, 14.0], ids=["during-a-move", "during-the-dwell"])
def test_another_masters_request_during_a_run_halts_it(tmp_path, at_s):
    outcome, t_sent, halts = _run_with_intruder(
        tmp_path, can.Message(arbitration_id=0x0C3, data=b"\x0a\x62", is_extended_id=False),
        at_s)
    result = outcome.result
    assert (result.status, result.exit_code) == ("failed", 3)
    assert result.fault["cause"] == "foreign_master"
    assert result.message.startswith(
        "another controller is on the bus (frame 0x0C3 [0A 62]: GetExtended FPOS_STATE_DIO "
        "to module 3): Halt"), result.message
    assert result.fault["halt_sent"] and result.fault["halt_confirmed"]
    # The Halt goes out within a control cycle of the frame (plus one exchange).
    assert halts and 0 <= halts[0] - t_sent < 0.03, (t_sent, halts)


def test_a_halt_broadcast_from_another_process_is_named(tmp_path):
    outcome, t_sent, halts = _run_with_intruder(
        tmp_path, can.Message(arbitration_id=0x100, data=b"\x02\x00", is_extended_id=False),
        3.0)
    result = outcome.result
    assert (result.status, result.exit_code) == ("failed", 3)
    assert result.fault["cause"] == "remote_halt"
    assert result.message.startswith(
        "Halt broadcast from another process (frame 0x100 [02 00])"), result.message
    assert "HALTED" in result.message
    events = RunFolder(tmp_path / "run").events()
    assert [e["reason"] for e in events if e["type"] == "halt_requested"] == [
        "Halt broadcast from another process (frame 0x100 [02 00])"]
    assert halts and halts[0] - t_sent < 0.03


def test_status_warns_when_another_master_asks_while_it_reads():
    from seqrun.cli.bus_owner import StatusSource
    from seqrun.drivers.registry import open_driver

    clock = RealClock()
    connection = open_connection(force_sim=True, clock=clock)
    intruder = SimBus(channel=connection.bus.channel, clock=clock)

    def open_bus():
        return connection, open_driver(ARM, connection, response_timeout_s=0.2)

    warnings: list[str] = []
    source = StatusSource(ARM, None, open_bus, warnings.append)
    try:
        first = source.read(tolerate_loss=True)
        assert warnings == [] and len(first["joints"]) == 7
        intruder.send(can.Message(arbitration_id=0x0C2, data=b"\x0a\x62",
                                  is_extended_id=False))
        intruder.send(can.Message(arbitration_id=0x0C4, data=b"\x0a\x62",
                                  is_extended_id=False))
        second = source.read(first, tolerate_loss=True)
        assert not any(j["stale"] for j in second["joints"])
        assert warnings == ["another controller is on the bus (frame 0x0C2 [0A 62]: "
                            "GetExtended FPOS_STATE_DIO to module 2) (+1 more frames): its "
                            "questions and ours cannot be told apart"]
        intruder.send(can.Message(arbitration_id=0x100, data=b"\x02\x00",
                                  is_extended_id=False))
        source.read(second, tolerate_loss=True)
        assert warnings[-1].startswith("Halt broadcast from another process (frame 0x100")
    finally:
        intruder.shutdown()
        source.close()
