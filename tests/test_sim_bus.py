"""SimBus through python-can's own entry point, and end to end with codec frames."""

from __future__ import annotations

import itertools
import math
import time

import can
import pytest

from seqrun.clock import RealClock, VirtualClock
from seqrun.powercube.codec import (
    BroadcastRequest,
    GetParam,
    SetMotion,
    SetParam,
    decode_ack,
    encode,
)
from seqrun.powercube.protocol import CommandId, MotionMode, ParamId, ShortState, StateFlag
from seqrun.sim.bus import SimBus, get_network

_names = itertools.count()


@pytest.fixture
def channel():
    return f"test-sim-bus-{next(_names)}"


@pytest.fixture
def clock():
    return VirtualClock()


def frame(req) -> can.Message:
    can_id, data = encode(req)
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


def sim_bus(channel, clock, **kwargs):
    return can.Bus(interface="seqrun-sim", channel=channel, clock=clock, ignore_config=True,
                   **kwargs)


def test_entry_point_gives_a_sim_bus(channel, clock):
    with sim_bus(channel, clock) as bus:
        assert isinstance(bus, SimBus)
        assert bus.bitrate == 1_000_000
        assert "simulated LWA 3" in bus.channel_info
        assert get_network(channel).arm is bus.arm


def test_config_env_vars_leak_unless_ignored(channel, clock, monkeypatch):
    monkeypatch.setenv("CAN_BITRATE", "125000")
    monkeypatch.setenv("CAN_CONFIG", '{"receive_own_messages": true}')
    with sim_bus(channel, clock) as bus:
        assert bus.bitrate == 1_000_000 and not bus.receive_own_messages
    # The pitfall the simulator's callers avoid with ignore_config=True:
    with can.Bus(interface="seqrun-sim", channel=channel + "-leaky", clock=clock) as leaky:
        assert leaky.bitrate == 125_000 and leaky.receive_own_messages


def test_recv_in_virtual_time_does_not_spin(channel, clock):
    with sim_bus(channel, clock) as bus:
        started = time.perf_counter()
        assert bus.recv(timeout=30.0) is None
        assert time.perf_counter() - started < 0.5
        assert clock.now() == 30.0
        assert bus.recv(timeout=0) is None and clock.now() == 30.0


def test_ack_through_the_bus(channel, clock):
    with sim_bus(channel, clock) as bus:
        bus.send(frame(GetParam(4, ParamId.DEF_CUBE_VERSION)))
        msg = bus.recv(timeout=0.05)
        assert msg.arbitration_id == 0x0A4 and not msg.is_extended_id and msg.is_rx
        assert bytes(msg.data) == bytes.fromhex("0A1D3846")
        assert msg.timestamp == clock.now() and 0 < msg.timestamp < 0.001
        assert msg.channel == channel


def test_buses_on_one_channel_share_the_arm(channel, clock):
    a = sim_bus(channel, clock)
    b = sim_bus(channel, clock, faults="2:halt@0")  # a joining bus may add faults
    try:
        a.send(can.Message(arbitration_id=0x123, data=b"\x01", is_extended_id=False))
        assert b.recv(0.01).arbitration_id == 0x123
        assert a.recv(0.01) is None  # not its own frame
        assert a.arm.states()[2] & StateFlag.HALTED
        with pytest.raises(can.CanInitializationError, match="another clock"):
            SimBus(channel, clock=VirtualClock())
        with pytest.raises(can.CanInitializationError, match="runs at 1000000 bit/s"):
            SimBus(channel, bitrate=500_000)
        with pytest.raises(can.CanInitializationError, match="seed can only be given"):
            SimBus(channel, seed=3)
    finally:
        a.shutdown()
        assert get_network(channel) is b.network
        b.shutdown()
    with pytest.raises(LookupError, match="no seqrun-sim bus is open"):
        get_network(channel)
    with sim_bus(channel, clock) as fresh:  # power cycle: a new arm
        assert not fresh.arm.states()[2] & StateFlag.HALTED


def test_receive_own_messages(channel, clock):
    with sim_bus(channel, clock, receive_own_messages=True) as bus:
        bus.send(frame(GetParam(1, ParamId.ACT_POS)))
        own = bus.recv(0.01)
        assert own.arbitration_id == 0x0C1 and not own.is_rx
        assert bus.recv(0.01).arbitration_id == 0x0A1


def test_software_filters_use_the_simulation_clock(channel, clock):
    with sim_bus(channel, clock, can_filters=[{"can_id": 0x0A3, "can_mask": 0x7FF}]) as bus:
        for module in (1, 2, 3):
            bus.send(frame(GetParam(module, ParamId.ACT_POS)))
        assert bus.recv(0.01).arbitration_id == 0x0A3
        assert bus.recv(0.01) is None


def test_send_refuses_what_classic_can_cannot_carry(channel, clock):
    with sim_bus(channel, clock) as bus:
        with pytest.raises(can.CanOperationError, match="CAN FD"):
            bus.send(can.Message(arbitration_id=1, is_fd=True, data=bytes(12)))
        with pytest.raises(can.CanOperationError, match="error frames"):
            bus.send(can.Message(arbitration_id=1, is_error_frame=True))
        with pytest.raises(can.CanOperationError, match="standard CAN id"):
            bus.send(can.Message(arbitration_id=0x800, is_extended_id=False))
    with pytest.raises(can.CanInitializationError, match="fd=True"):
        SimBus(channel, fd=True)
    with pytest.raises(can.CanInitializationError, match="unknown kind"):
        SimBus(channel, faults=["1:boom@0"])


def test_shutdown_twice_and_use_after_shutdown(channel, clock):
    bus = sim_bus(channel, clock)
    bus.shutdown()
    bus.shutdown()
    with pytest.raises(can.CanOperationError, match="closed bus"):
        bus.send(frame(GetParam(1, ParamId.ACT_POS)))
    with pytest.raises(can.CanOperationError, match="closed bus"):
        bus.recv(0.01)


def test_detect_available_configs_lists_open_channels(channel, clock):
    with sim_bus(channel, clock):
        configs = can.detect_available_configs(interfaces=["seqrun-sim"])
        assert {"interface": "seqrun-sim", "channel": channel} in configs


def test_real_clock_recv_blocks_until_the_frame_is_due(channel):
    clock = RealClock()
    with sim_bus(channel, clock) as bus:
        sent = clock.now()
        bus.send(frame(GetParam(1, ParamId.ACT_POS)))
        msg = bus.recv(timeout=1.0)
        assert msg is not None and msg.arbitration_id == 0x0A1
        assert 250e-6 < msg.timestamp - sent  # 2 frames + 100 us latency at least
        assert clock.now() - sent < 0.5
        started = clock.now()
        assert bus.recv(timeout=0.05) is None
        assert 0.045 < clock.now() - started < 0.5


def _transact(bus, req):
    bus.send(frame(req))
    msg = bus.recv(0.05)
    return None if msg is None else decode_ack(msg.arbitration_id, msg.data)


def test_end_to_end_startup_and_ramp_with_raw_frames(channel, clock):
    """The thesis start-up (Reset, Home, limits), then TargetVel + FRAMP, over raw frames."""
    with sim_bus(channel, clock, faults="7:no_ack@0") as bus:
        assert _transact(bus, SetMotion(1, MotionMode.FRAMP_ACK, 1.0)).state & ShortState.NOT_OK
        bus.send(frame(BroadcastRequest(CommandId.RESET, 0)))
        bus.send(frame(BroadcastRequest(CommandId.HOME, 0)))
        assert bus.recv(0.01) is None  # broadcasts are never acknowledged
        for module in range(1, 8):
            _transact(bus, SetParam(module, ParamId.MIN_POS, -math.pi))
            _transact(bus, SetParam(module, ParamId.MAX_POS, math.pi))
        assert _transact(bus, SetParam(1, ParamId.TARGET_VEL, 0.5)) is not None
        assert _transact(bus, SetParam(1, ParamId.TARGET_ACC, 1.0)) is not None
        ack = _transact(bus, SetMotion(1, MotionMode.FRAMP_ACK, -3.0))
        started = ack and clock.now()
        assert ack.state == ShortState.RAMP_END and ack.position == 0.0
        # Poll FPosStateDio every 10 ms until the ramp ends: 3.0 rad at 0.5 rad/s, 1 rad/s^2
        # takes 6.5 s; the poll sees it within one period.
        while True:
            clock.advance(0.01)
            reading = _transact(bus, GetParam(1, ParamId.FPOS_STATE_DIO)).value
            if reading.state & ShortState.RAMP_END:
                break
        assert reading.position == pytest.approx(-3.0, abs=1e-6)
        assert 6.5 <= clock.now() - started < 6.52
        assert _transact(bus, GetParam(7, ParamId.ACT_POS)) is None  # injected no_ack
