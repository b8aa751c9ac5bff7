"""PowerCube codec: the reference's test vectors byte for byte, round trips, rejections."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from seqrun.errors import CodecError
from seqrun.powercube.codec import (
    AckKey,
    BroadcastRequest,
    CommandAck,
    CommandRequest,
    GetParam,
    GetParamAck,
    MotionAck,
    MotionExtAck,
    PosStateDio,
    SetMotion,
    SetParam,
    SetParamAck,
    ack_key,
    decode_ack,
    decode_request,
    encode,
    expected_ack_key,
)
from seqrun.powercube.protocol import (
    ADDRESSED_COMMANDS,
    BROADCAST_COMMANDS,
    PARAM_TYPES,
    BaudRate,
    CommandId,
    ConfigFlag,
    MotionMode,
    ParamId,
    ShortState,
    StateFlag,
    WireType,
)

P, M, C, S = ParamId, MotionMode, CommandId, ShortState


def f32(x: float) -> float:
    """``x`` rounded to float32, as it comes back from the wire."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def frame(text: str) -> tuple[int, bytes]:
    """``"0x0E2 : 08 4F B8"`` -> ``(0x0E2, b"\\x08\\x4f\\xb8")``."""
    can_id, data = text.split(":")
    return int(can_id, 16), bytes.fromhex(data)


# ------------------------------------------------------------------------------------
# Section H test vectors: (request, request frame, ack, ack frame)

VECTORS = [
    (1, SetParam(2, P.TARGET_VEL, f32(0.77)), "0x0E2 : 08 4F B8 1E 45 3F",
     SetParamAck(2, P.TARGET_VEL), "0x0A2 : 08 4F 64"),
    (2, SetParam(2, P.TARGET_ACC, f32(0.8)), "0x0E2 : 08 50 CD CC 4C 3F",
     SetParamAck(2, P.TARGET_ACC), "0x0A2 : 08 50 64"),
    (3, SetMotion(2, M.FRAMP, 1.0), "0x0E2 : 0B 04 00 00 80 3F",
     MotionAck(2, M.FRAMP), "0x0A2 : 0B 04 64"),
    (4, GetParam(3, P.ACT_POS), "0x0C3 : 0A 3C",
     GetParamAck(3, P.ACT_POS, 0.5), "0x0A3 : 0A 3C 00 00 00 3F"),
    (5, GetParam(1, P.CUBE_STATE), "0x0C1 : 0A 27",
     GetParamAck(1, P.CUBE_STATE, 0x8002), "0x0A1 : 0A 27 02 80 00 00"),
    (6, SetMotion(4, M.FSTEP_ACK, -0.25, 60), "0x0E4 : 0B 10 00 00 80 BE 3C 00",
     MotionExtAck(4, M.FSTEP_ACK, f32(-0.2), S.MOTION, 0), "0x0A4 : 0B 10 CD CC 4C BE 10 00"),
    (7, SetMotion(5, M.FVEL_ACK, f32(0.1)), "0x0E5 : 0B 11 CD CC CC 3D",
     MotionExtAck(5, M.FVEL_ACK, f32(0.3), S.RAMP_END, 0), "0x0A5 : 0B 11 9A 99 99 3E 20 00"),
    (8, SetMotion(5, M.FVEL, -0.5), "0x0E5 : 0B 07 00 00 00 BF",
     MotionAck(5, M.FVEL), "0x0A5 : 0B 07 64"),
    (9, SetMotion(2, M.FSTEP, f32(0.3), 100), "0x0E2 : 0B 06 9A 99 99 3E 64 00",
     MotionAck(2, M.FSTEP), "0x0A2 : 0B 06 64"),
    (10, SetMotion(2, M.ISTEP, 10000, 50), "0x0E2 : 0B 0B 10 27 00 00 32 00",
     MotionAck(2, M.ISTEP), "0x0A2 : 0B 0B 64"),
    (11, GetParam(6, P.FPOS_STATE_DIO), "0x0C6 : 0A 62",
     GetParamAck(6, P.FPOS_STATE_DIO, PosStateDio(f32(1.2), S.NOT_OK, 0)),
     "0x0A6 : 0A 62 9A 99 99 3F 01 00"),
    (12, CommandRequest(1, C.RESET), "0x0E1 : 00", CommandAck(1, C.RESET), "0x0A1 : 00 64"),
    (13, CommandRequest(7, C.HALT), "0x0E7 : 02", CommandAck(7, C.HALT), "0x0A7 : 02 64"),
    (14, CommandRequest(3, C.HOME), "0x0E3 : 01", CommandAck(3, C.HOME), "0x0A3 : 01 64"),
    (15, SetParam(2, P.CONFIG, 0x09000000), "0x0E2 : 08 39 00 00 00 09",
     SetParamAck(2, P.CONFIG), "0x0A2 : 08 39 64"),
    (16, SetParam(1, P.MAX_VEL, 1.0), "0x0E1 : 08 48 00 00 80 3F",
     SetParamAck(1, P.MAX_VEL), "0x0A1 : 08 48 64"),
    (17, GetParam(4, P.DEF_CUBE_VERSION), "0x0C4 : 0A 1D",
     GetParamAck(4, P.DEF_CUBE_VERSION, 0x4638), "0x0A4 : 0A 1D 38 46"),
]

BROADCAST_VECTORS = [
    # (row, message as m5api sends it, its frame, the 1-byte variant of other drivers)
    (18, BroadcastRequest(C.WATCHDOG_REFRESH, 0), "0x100 : 07 00", "0x100 : 07"),
    (19, BroadcastRequest(C.START_MOVE, 0), "0x100 : 0F 00", "0x100 : 0F"),
    (20, BroadcastRequest(C.SET_BAUD_ALL, BaudRate.BAUD_1M), "0x100 : 09 03", None),
    (21, BroadcastRequest(C.SAVE_POS_ALL, 0), "0x100 : 0E 00", "0x100 : 0E"),
]

_ids = [f"H{row}" for row, *_ in VECTORS]


@pytest.mark.parametrize(("row", "request_", "request_frame", "ack", "ack_frame"), VECTORS,
                         ids=_ids)
def test_vector_request_encodes_exactly(row, request_, request_frame, ack, ack_frame):
    assert encode(request_) == frame(request_frame)


@pytest.mark.parametrize(("row", "request_", "request_frame", "ack", "ack_frame"), VECTORS,
                         ids=_ids)
def test_vector_request_decodes_exactly(row, request_, request_frame, ack, ack_frame):
    assert decode_request(*frame(request_frame)) == request_


@pytest.mark.parametrize(("row", "request_", "request_frame", "ack", "ack_frame"), VECTORS,
                         ids=_ids)
def test_vector_ack_decodes_and_encodes_back(row, request_, request_frame, ack, ack_frame):
    assert decode_ack(*frame(ack_frame)) == ack
    assert encode(ack) == frame(ack_frame)


@pytest.mark.parametrize(("row", "request_", "request_frame", "ack", "ack_frame"), VECTORS,
                         ids=_ids)
def test_vector_ack_matches_its_request(row, request_, request_frame, ack, ack_frame):
    assert ack_key(decode_ack(*frame(ack_frame))) == expected_ack_key(request_)


@pytest.mark.parametrize("text", ["0x0A1 : 00", "0x0A1 : 00 64", "0x0A1 : 00 00 00"])
def test_command_ack_needs_only_byte_0(text):
    # Rows 12-14: only byte 0 is confirmed, the 0x64 trailer is an assumption.
    assert decode_ack(*frame(text)) == CommandAck(1, C.RESET)


@pytest.mark.parametrize(("row", "message", "long_frame", "short_frame"), BROADCAST_VECTORS,
                         ids=[f"H{v[0]}" for v in BROADCAST_VECTORS])
def test_vector_broadcast(row, message, long_frame, short_frame):
    assert encode(message) == frame(long_frame)
    assert decode_request(*frame(long_frame)) == message
    assert expected_ack_key(message) is None
    if short_frame is not None:
        short = BroadcastRequest(message.command)
        assert encode(short) == frame(short_frame)
        assert decode_request(*frame(short_frame)) == short


def test_set_baud_all_decodes_as_broadcast_of_code_9():
    request = decode_request(0x100, b"\x09\x02")
    assert request == BroadcastRequest(C.SET_BAUD_ALL, BaudRate.BAUD_500K)
    assert request.command == 0x09


def test_short_set_acks_do_not_rely_on_the_trailer():
    assert decode_ack(0x0A2, bytes.fromhex("084F")) == SetParamAck(2, P.TARGET_VEL)
    assert decode_ack(0x0A2, bytes.fromhex("0B04")) == MotionAck(2, M.FRAMP)
    assert decode_ack(0x0A2, bytes.fromhex("0B0400")) == MotionAck(2, M.FRAMP)


def test_extended_ack_is_chosen_by_mode_not_by_0x64():
    # Position 0x64 in byte 2 (a float starting with 0x64) must not look like a short ack.
    position = struct.unpack("<f", bytes.fromhex("64000000"))[0]
    ack = decode_ack(0x0A3, bytes.fromhex("0B0E640000002100"))
    assert ack == MotionExtAck(3, M.FRAMP_ACK, position, S.NOT_OK | S.RAMP_END, 0)


def test_int_extended_ack_position_is_signed():
    ack = decode_ack(0x0A3, bytes.fromhex("0B13 FEFFFFFF 10 A5".replace(" ", "")))
    assert ack == MotionExtAck(3, M.IRAMP_ACK, -2, S.MOTION, 0xA5)


def test_int32_parameter_round_trips_signed():
    # m5api's 64-bit readLong does not sign-extend; we must.
    can_id, data = encode(GetParamAck(1, P.POS_COUNT, -1))
    assert data == bytes.fromhex("0A24FFFFFFFF")
    assert decode_ack(can_id, data).value == -1
    assert encode(SetParam(1, P.IPOS, -(2**31)))[1] == bytes.fromhex("08 5A 00 00 00 80")


@pytest.mark.parametrize("data", ["0B 0D 38 FF", "0B 0D 38 FF FF FF"])
def test_icur_accepts_both_layouts(data):
    assert decode_request(0x0E2, bytes.fromhex(data)) == SetMotion(2, M.ICUR, -200)


def test_icur_encodes_m5api_int32_layout():
    assert encode(SetMotion(2, M.ICUR, -200)) == (0x0E2, bytes.fromhex("0B0D38FFFFFF"))


def test_get_ack_ignores_bytes_after_the_value():
    assert decode_ack(0x0A4, bytes.fromhex("0A1D38460000")) == GetParamAck(4, P.DEF_CUBE_VERSION,
                                                                           0x4638)


def test_ack_keys():
    assert ack_key(CommandAck(3, C.HALT)) == AckKey(3, 0x02, None)
    assert ack_key(GetParamAck(3, P.ACT_POS, 0.0)) == (3, 0x0A, 0x3C)
    assert ack_key(SetParamAck(3, P.ACT_POS)) == (3, 0x08, 0x3C)
    assert ack_key(MotionExtAck(3, M.FSTEP_ACK, 0.0, S(0), 0)) == (3, 0x0B, 0x10)
    assert expected_ack_key(SetMotion(3, M.FSTEP_ACK, 0.0, 5)) == (3, 0x0B, 0x10)
    assert expected_ack_key(CommandRequest(3, C.HALT)) == (3, 0x02, None)


# ------------------------------------------------------------------------------------
# Malformed frames


@pytest.mark.parametrize(("can_id", "data", "message"), [
    (0x0A0, "00 64", "module 0"),
    (0x0C0, "0A 3C", "not a PowerCube ack id"),
    (0x0A1, "", "empty"),
    (0x0A1, "0A", "without parameter"),
    (0x0A1, "0A 3C 00 00 00", "needs 6 bytes"),
    (0x0A1, "0A 62 00 00 00 00 01", "needs 8 bytes"),
    (0x0A1, "0A FF 00 00 00 00", "unknown parameter id 0xFF"),
    (0x0A1, "0A 11 00 00 00 00", "unknown parameter id 0x11"),
    (0x0A1, "0B 05 64", "unknown motion mode 0x05"),
    (0x0A1, "0B 0E 00 00 80 3F 00", "needs 8 bytes"),
    (0x0A1, "0B", "without mode"),
    (0x0A1, "08", "without parameter"),
    (0x0A1, "77 64", "unknown command 0x77"),
    (0x060 + 1, "00 00 00 00", "not a PowerCube ack id"),
])
def test_decode_ack_rejects(can_id, data, message):
    with pytest.raises(CodecError, match=message):
        decode_ack(can_id, bytes.fromhex(data))


@pytest.mark.parametrize(("can_id", "data", "message"), [
    (0x0C0, "0A 3C", "module 0"),
    (0x0E0, "00", "module 0"),
    (0x0A1, "00", "not a PowerCube request id"),
    (0x101, "00", "not a PowerCube request id"),
    (0x0C1, "0A", r"\[0A, par\]"),
    (0x0C1, "0A 3C 00", r"\[0A, par\]"),
    (0x0C1, "08 3C", r"\[0A, par\]"),
    (0x0C1, "0A 11", "unknown parameter id 0x11"),
    (0x0E1, "", "empty"),
    (0x0E1, "08 4F 00 00 80", "needs 6 bytes"),
    (0x0E1, "08 4F 00 00 80 3F 00", "needs 6 bytes"),
    (0x0E1, "08 1D 38", "needs 4 bytes"),
    (0x0E1, "08 62 00 00 00 00 00 00", "read only"),
    (0x0E1, "0B 06 00 00 80 3F", "needs 8 bytes"),
    (0x0E1, "0B 04 00 00 80 3F 00 00", "needs 6 bytes"),
    (0x0E1, "0B 05 00 00 80 3F", "unknown motion mode"),
    (0x0E1, "0B 04 00 00", "needs 6 bytes"),
    (0x0E1, "00 00", "must be 1 byte"),
    (0x0E1, "0A 3C", "unsupported command 0x0A"),
    (0x0E1, "0E", "unsupported command 0x0E"),
    (0x0E1, "04 01 02 03 04 05 06 07", "unsupported command 0x04"),
    (0x100, "", "1 or 2 bytes"),
    (0x100, "07 00 00", "1 or 2 bytes"),
    (0x100, "0B", "cannot be broadcast"),
    (0x100, "09", "baud-rate id"),
    (0x100, "09 04", "baud-rate id"),
])
def test_decode_request_rejects(can_id, data, message):
    with pytest.raises(CodecError, match=message):
        decode_request(can_id, bytes.fromhex(data))


@pytest.mark.parametrize(("message", "error"), [
    (GetParam(0, P.ACT_POS), "module id 0"),
    (GetParam(32, P.ACT_POS), "module id 32"),
    (GetParam(1, 0x11), "unknown parameter id 0x11"),
    (SetParam(1, P.DEF_CUBE_VERSION, 70000), "DEF_CUBE_VERSION 70000 outside 0..65535"),
    (SetParam(1, P.CONFIG, -1), "outside 0..4294967295"),
    (SetParam(1, P.POS_COUNT, 2**31), "outside"),
    (SetParam(1, P.RAW_CUR, 40000), "outside -32768..32767"),
    (SetParam(1, P.DEF_ADDRESS, 256), "outside 0..255"),
    (SetParam(1, P.CONFIG, 1.5), "must be an integer"),
    (SetParam(1, P.MAX_VEL, "1"), "must be a number"),
    (SetParam(1, P.MAX_VEL, 1e39), "float32"),
    (SetParam(1, P.FPOS_STATE_DIO, PosStateDio(0.0, S(0), 0)), "read only"),
    (SetMotion(1, M.FSTEP, 0.5), "needs a time"),
    (SetMotion(1, M.FSTEP, 0.5, 65536), "outside 0..65535"),
    (SetMotion(1, M.FSTEP, 0.5, -1), "outside 0..65535"),
    (SetMotion(1, M.FRAMP, 0.5, 10), "takes no time"),
    (SetMotion(1, M.IRAMP, 0.5), "must be an integer"),
    (SetMotion(1, 0x05, 0.5), "unknown motion mode"),
    (CommandRequest(1, C.SET_MOTION), "cannot be addressed"),
    (BroadcastRequest(C.SET_MOTION), "cannot be broadcast"),
    (BroadcastRequest(C.SET_BAUD_ALL), "needs a baud-rate id"),
    (BroadcastRequest(C.SET_BAUD_ALL, 4), "unknown baud-rate id"),
    (BroadcastRequest(C.HALT, 256), "outside 0..255"),
    (MotionAck(1, M.FRAMP_ACK), "MotionExtAck"),
    (MotionExtAck(1, M.FRAMP, 0.0, S(0), 0), "plain MotionAck"),
    (MotionExtAck(1, M.FRAMP_ACK, 0.0, S(0), 256), "dio 256"),
    (GetParamAck(1, P.FPOS_STATE_DIO, 0.5), "must be a PosStateDio"),
    ("not a message", "not a PowerCube message"),
])
def test_encode_rejects(message, error):
    with pytest.raises(CodecError, match=error):
        encode(message)


def test_encode_passes_non_finite_floats_through():
    # The codec encodes what it is given; deciding what is sensible is the caller's job.
    assert encode(SetParam(1, P.MAX_VEL, float("inf")))[1] == bytes.fromhex("08480000807F")


# ------------------------------------------------------------------------------------
# Round trips (hypothesis)

modules = st.integers(1, 31)
params = st.sampled_from(list(ParamId))
float32s = st.floats(width=32, allow_nan=False)
short_states = st.integers(0, 255).map(ShortState)
bytes_ = st.integers(0, 255)


def value_for(wire: WireType) -> st.SearchStrategy:
    if wire is WireType.F32:
        return float32s
    if wire is WireType.F32_U8_U8:
        return st.builds(PosStateDio, float32s, short_states, bytes_)
    return st.integers(wire.minimum, wire.maximum)


@st.composite
def param_with_value(draw, writable: bool = False):
    choices = [p for p in ParamId if not (writable and PARAM_TYPES[p] is WireType.F32_U8_U8)]
    param = draw(st.sampled_from(choices))
    return param, draw(value_for(PARAM_TYPES[param]))


@st.composite
def motion_value(draw, mode: MotionMode):
    if mode.is_float:
        return draw(float32s)
    return draw(st.integers(-(2**31), 2**31 - 1))


@st.composite
def set_motions(draw):
    mode = draw(st.sampled_from(list(MotionMode)))
    time_ms = draw(st.integers(0, 0xFFFF)) if mode.has_time else None
    return SetMotion(draw(modules), mode, draw(motion_value(mode)), time_ms)


@st.composite
def motion_acks(draw):
    mode = draw(st.sampled_from(list(MotionMode)))
    if not mode.is_extended_ack:
        return MotionAck(draw(modules), mode)
    return MotionExtAck(draw(modules), mode, draw(motion_value(mode)), draw(short_states),
                        draw(bytes_))


requests = st.one_of(
    st.builds(CommandRequest, modules, st.sampled_from(sorted(ADDRESSED_COMMANDS))),
    st.builds(GetParam, modules, params),
    param_with_value(writable=True).flatmap(
        lambda pv: st.builds(SetParam, modules, st.just(pv[0]), st.just(pv[1]))),
    set_motions(),
    st.builds(BroadcastRequest, st.sampled_from(sorted(BROADCAST_COMMANDS - {C.SET_BAUD_ALL})),
              st.none() | bytes_),
    st.builds(BroadcastRequest, st.just(C.SET_BAUD_ALL), st.sampled_from(list(BaudRate))),
)

acks = st.one_of(
    st.builds(CommandAck, modules, st.sampled_from(sorted(ADDRESSED_COMMANDS))),
    st.builds(SetParamAck, modules, params),
    param_with_value().flatmap(
        lambda pv: st.builds(GetParamAck, modules, st.just(pv[0]), st.just(pv[1]))),
    motion_acks(),
)


@given(requests)
def test_request_round_trip(request_):
    can_id, data = encode(request_)
    assert len(data) <= 8
    assert decode_request(can_id, data) == request_


@given(acks)
def test_ack_round_trip(ack):
    can_id, data = encode(ack)
    assert len(data) <= 8
    decoded = decode_ack(can_id, data)
    assert decoded == ack
    assert ack_key(decoded) == ack_key(ack)


@given(st.sampled_from(list(ParamId)), st.data())
def test_every_param_type_round_trips(param, data):
    wire = PARAM_TYPES[param]
    value = data.draw(value_for(wire))
    ack = GetParamAck(5, param, value)
    can_id, payload = encode(ack)
    assert len(payload) == 2 + wire.size
    assert decode_ack(can_id, payload).value == value
    if wire is not WireType.F32_U8_U8:
        request = SetParam(5, param, value)
        assert decode_request(*encode(request)) == request
        assert expected_ack_key(request) == ack_key(SetParamAck(5, param))


@given(st.binary(min_size=4, max_size=4), st.sampled_from([P.ACT_POS, P.MAX_VEL]))
def test_any_float32_bit_pattern_survives_bytes_round_trip(raw, param):
    data = bytes([0x0A, param]) + raw
    value = decode_ack(0x0A1, data).value
    can_id, encoded = encode(GetParamAck(1, param, value))
    if math.isnan(value):
        # Python floats quieten signalling NaNs; a NaN stays a NaN.
        assert math.isnan(struct.unpack("<f", encoded[2:])[0])
    else:
        assert (can_id, encoded) == (0x0A1, data)


@given(st.integers(0x0A0, 0x0BF), st.binary(max_size=8))
def test_decode_ack_never_fails_other_than_codec_error(can_id, data):
    try:
        ack = decode_ack(can_id, data)
    except CodecError:
        return
    assert ack.module == can_id - 0x0A0
    assert ack_key(ack).command == data[0]


@given(st.sampled_from([0x0C0, 0x0E0, 0x100]).flatmap(
    lambda base: st.integers(base, base + 0x1F) if base != 0x100 else st.just(base)),
    st.binary(max_size=8))
def test_decode_request_never_fails_other_than_codec_error(can_id, data):
    try:
        request = decode_request(can_id, data)
    except CodecError:
        return
    # What decodes re-encodes to a frame that decodes the same.
    assert decode_request(*encode(request)) == request


# ------------------------------------------------------------------------------------
# Protocol tables and flags

def test_every_parameter_of_section_c_is_known_with_its_type():
    expected = {
        WireType.F32: [*range(0x00, 0x11), 0x3B, 0x3C, 0x3D, 0x3E, 0x3F, 0x40, 0x41, 0x42,
                       0x45, 0x46, 0x48, 0x4A, 0x4C, 0x4D, 0x4E, 0x4F, 0x50, 0x59, 0x63, 0x64,
                       *range(0x70, 0x7A), 0x81],
        WireType.U32: [0x19, 0x1A, 0x1B, 0x1C, 0x26, 0x27, 0x39, 0x58],
        WireType.U16: [0x1D, 0x1E, 0x1F, 0x69],
        WireType.U8: [0x20, 0x22, 0x23, 0x3A, 0x57],
        WireType.I32: [0x24, 0x25, 0x28, 0x29, 0x2A, 0x2B, 0x2C, 0x36, *range(0x5A, 0x62), 0x65,
                       0x67, 0x68, *range(0x7A, 0x80), 0x80, 0x82],
        WireType.I16: [0x35, *range(0x51, 0x57), 0x66, *range(0x6C, 0x70)],
        WireType.F32_U8_U8: [0x62],
    }
    got = {p.value: PARAM_TYPES[p] for p in ParamId}
    want = {pid: wire for wire, ids in expected.items() for pid in ids}
    assert got == want


def test_motion_mode_helpers():
    assert {m for m in MotionMode if m.is_extended_ack} == {
        M.FRAMP_ACK, M.FSTEP_ACK, M.FVEL_ACK, M.FCUR_ACK, M.IRAMP_ACK, M.ISTEP_ACK,
        M.IVEL_ACK, M.ICUR_ACK}
    assert {m for m in MotionMode if m.has_time} == {
        M.FSTEP, M.ISTEP, M.FSTEP_ACK, M.ISTEP_ACK, M.FCOSLOOP, M.FRAMPLOOP}
    assert {m for m in MotionMode if not m.is_float} == {
        M.IRAMP, M.ISTEP, M.IVEL, M.ICUR, M.IRAMP_ACK, M.ISTEP_ACK, M.IVEL_ACK, M.ICUR_ACK}
    assert M.FSTEP.with_ext_ack() is M.FSTEP_ACK
    assert M.FSTEP_ACK.without_ext_ack() is M.FSTEP
    assert M.FCOSLOOP.with_ext_ack() is M.FCOSLOOP


def test_command_codes_including_shared_0x09():
    assert C.SET_BAUD_ALL == C.RECALC_PID == 0x09
    assert C.SYNC_MOTION_ALL == C.START_MOVE == 0x0F
    assert C.SET_BAUD_ALL in BROADCAST_COMMANDS and C.RECALC_PID in ADDRESSED_COMMANDS


def test_state_flag_describe_and_faults():
    state = StateFlag.ERROR | StateFlag.TOW_ERROR | StateFlag.HALTED | StateFlag.HOME_OK
    assert state.describe() == "ERROR|HOME_OK|HALTED|TOW_ERROR"
    assert state.faults.describe() == "ERROR|HALTED|TOW_ERROR"
    assert StateFlag(0).describe() == "none"
    assert StateFlag(0x80000000 | 0x2).describe() == "HOME_OK|0x80000000"
    assert StateFlag(0x08000000).describe() == "POW_SETUP_ERR"
    for flag in (StateFlag.ERROR, StateFlag.HALTED, StateFlag.POWERFAULT, StateFlag.TOW_ERROR,
                 StateFlag.COMM_ERROR, StateFlag.BEYOND_HARD, StateFlag.BEYOND_SOFT,
                 StateFlag.CPU_OVERLOAD, StateFlag.POW_VOLT_ERR):
        assert flag & StateFlag.FAULTS, flag
    for flag in (StateFlag.HOME_OK, StateFlag.MOTION, StateFlag.RAMP_END, StateFlag.CURLIMIT,
                 StateFlag.BRAKEACTIVE, StateFlag.SWR):
        assert not flag & StateFlag.FAULTS, flag
    assert not (StateFlag.HOME_OK | StateFlag.RAMP_END).is_fault


def test_short_state_to_state_flags_like_m5api():
    assert ShortState(0).describe() == "OK"
    assert ShortState(0x31).describe() == "NOT_OK|MOTION|RAMP_END"
    expected = {0x01: 0x1, 0x02: 0x40, 0x04: 0x80, 0x08: 0x100, 0x10: 0x800, 0x20: 0x8000,
                0x40: 0x10000, 0x80: 0x20000}
    for short, long in expected.items():
        assert ShortState(short).to_state_flags() == long
    assert ShortState(0xFF).to_state_flags() == sum(expected.values())


def test_config_flag_describe():
    assert ConfigFlag(0x09000000).describe() == "WATCHDOG_ENABLE|SYNC_MOTION"
    assert ConfigFlag(0).describe() == "none"


def test_baud_rate():
    assert BaudRate.BAUD_1M == 3 and BaudRate.BAUD_1M.bits_per_second == 1_000_000
    assert BaudRate.from_bits_per_second(500_000) is BaudRate.BAUD_500K
    with pytest.raises(ValueError):
        BaudRate.from_bits_per_second(800_000)
