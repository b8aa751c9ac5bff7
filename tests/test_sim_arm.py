"""SimArm: frames in, acknowledges out."""

from __future__ import annotations

import pytest

from seqrun.clock import VirtualClock
from seqrun.powercube.codec import (
    BroadcastRequest,
    CommandRequest,
    GetParam,
    GetParamAck,
    SetMotion,
    decode_ack,
    encode,
)
from seqrun.powercube.protocol import CommandId, MotionMode, ParamId, StateFlag
from seqrun.sim.arm import SimArm
from seqrun.sim.module import ModuleOptions


@pytest.fixture
def clock():
    return VirtualClock(start=10.0)


def test_addressed_request_gets_one_ack_after_the_latency(clock):
    arm = SimArm(clock, module_latency=250e-6)
    (reply,) = arm.handle_frame(0x0C4, bytes.fromhex("0A1D"), 10.5)
    assert (reply.module, reply.can_id, reply.data) == (4, 0x0A4, bytes.fromhex("0A1D3846"))
    assert reply.ready_at == pytest.approx(10.50025)


def test_reference_vectors_1_to_3_and_12(clock):
    arm = SimArm(clock)
    assert [(r.can_id, r.data.hex()) for r in arm.handle_frame(
        0x0E2, bytes.fromhex("084FB81E453F"))] == [(0x0A2, "084f64")]
    assert [(r.can_id, r.data.hex()) for r in arm.handle_frame(
        0x0E2, bytes.fromhex("0850CDCC4C3F"))] == [(0x0A2, "085064")]
    assert [(r.can_id, r.data.hex()) for r in arm.handle_frame(
        0x0E2, bytes.fromhex("0B040000803F"))] == [(0x0A2, "0b0464")]
    assert [(r.can_id, r.data.hex()) for r in arm.handle_frame(
        0x0E1, bytes.fromhex("00"))] == [(0x0A1, "0064")]


def test_command_ack_without_trailer_option(clock):
    arm = SimArm(clock, options=ModuleOptions(command_ack_trailer=False))
    assert [r.data for r in arm.handle_frame(0x0E1, b"\x00")] == [b"\x00"]


@pytest.mark.parametrize("can_id, data", [
    (0x0C1, bytes.fromhex("0A")),            # GET without parameter
    (0x0C1, bytes.fromhex("0AFF")),          # unknown parameter
    (0x0E1, bytes.fromhex("0B04000080")),    # FRAMP one byte short
    (0x0A1, bytes.fromhex("0A3C0000003F")),  # another module's ack
    (0x0C9, bytes.fromhex("0A3C")),          # module 9 is not on this arm
    (0x123, bytes.fromhex("0102")),          # not PowerCube
    (0x100, bytes.fromhex("55")),            # unknown broadcast
])
def test_invalid_frames_are_ignored(clock, can_id, data):
    arm = SimArm(clock)
    assert arm.handle_frame(can_id, data) == []
    assert all(s == StateFlag.BRAKEACTIVE | StateFlag.RAMP_END for s in arm.states().values())


@pytest.mark.parametrize("data", ["01", "0100"])
def test_broadcasts_act_on_all_and_are_never_acked(clock, data):
    arm = SimArm(clock)
    assert arm.handle_frame(0x100, bytes.fromhex(data)) == []
    assert all(s & StateFlag.HOME_OK for s in arm.states().values())
    assert arm.handle_frame(0x100, bytes.fromhex("0903")) == []  # SetBaudAll: accepted


def test_positions_and_set_positions(clock):
    arm = SimArm(clock, positions=[0.1 * m for m in range(1, 8)])
    assert arm.positions() == {m: pytest.approx(0.1 * m) for m in range(1, 8)}
    arm.set_positions({4: -0.5})
    assert arm.positions()[4] == -0.5
    can_id, data = encode(GetParam(4, ParamId.ACT_POS))
    (reply,) = arm.handle_frame(can_id, data)
    assert decode_ack(reply.can_id, reply.data) == GetParamAck(4, ParamId.ACT_POS, -0.5)
    with pytest.raises(ValueError, match="expected 7 positions"):
        arm.set_positions([0.0])
    with pytest.raises(KeyError, match="no module 8"):
        arm.module(8)


def test_fewer_modules(clock):
    arm = SimArm(clock, modules=[1, 2])
    assert arm.module_ids == [1, 2]
    can_id, data = encode(GetParam(3, ParamId.ACT_POS))
    assert arm.handle_frame(can_id, data) == []


def test_motion_through_frames(clock):
    arm = SimArm(clock)
    for req in (BroadcastRequest(CommandId.RESET), BroadcastRequest(CommandId.HOME)):
        arm.handle_frame(*encode(req))
    (reply,) = arm.handle_frame(*encode(SetMotion(7, MotionMode.FRAMP_ACK, 0.2)))
    ack = decode_ack(reply.can_id, reply.data)
    assert ack.position == 0.0 and int(ack.state) == 0x20
    clock.advance(2.0)
    assert arm.positions()[7] == pytest.approx(0.2, abs=1e-7)
    arm.handle_frame(*encode(CommandRequest(7, CommandId.HALT)))
    assert arm.states()[7] & StateFlag.HALTED
