"""Typed PowerCube messages and their CAN frames: ``message <-> (can_id, bytes)``.

Pure functions, no I/O: the client and the simulator both use them.

Requests (host -> module)::

    CommandRequest(module, command)          0x0E0+m : [cmd]
    BroadcastRequest(command, arg=None)      0x100   : [cmd] or [cmd, arg]
    GetParam(module, param)                  0x0C0+m : [0x0A, par]
    SetParam(module, param, value)           0x0E0+m : [0x08, par, value LE]
    SetMotion(module, mode, value, time_ms)  0x0E0+m : [0x0B, mode, f32|i32 (, u16 ms)]

Acknowledges (module -> host, all on 0x0A0+m)::

    CommandAck(module, command)              [cmd, 0x64]
    SetParamAck(module, param)               [0x08, par, 0x64]
    GetParamAck(module, param, value)        [0x0A, par, value LE]  (0x62: PosStateDio)
    MotionAck(module, mode)                  [0x0B, mode, 0x64]
    MotionExtAck(module, mode, position, state, dio)
                                             [0x0B, mode, f32|i32, state, dio]

Decoding is lenient exactly where the sources disagree or say nothing, and strict
elsewhere:

- broadcasts: ``[cmd]`` and m5api's ``[cmd, 0x00]`` are both accepted; SetBaudAll needs
  its argument;
- ICUR / ICUR_ACK requests: m5api's int32 (DLC 6) and RobWork's int16 (DLC 4); encoding
  always uses int32;
- short acks (command, SetExtended, plain SetMotion) are accepted from the bytes that
  identify them on (DLC >= 1 resp. >= 2); the 0x64 trailer is never checked, because
  whether and when modules send it is undocumented;
- a GetExtended ack needs at least its value bytes; extra bytes are ignored;
- whether a SetMotion ack is extended is decided by the mode (``*_ACK``), never by
  looking for 0x64 in byte 2 (which there is the first byte of the position).

Everything else (short frames, unknown command / parameter / mode, ids outside the
ranges, module 0) raises :class:`~seqrun.errors.CodecError`.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple, Union

from seqrun.errors import CodecError
from seqrun.powercube.protocol import (
    ACK_BASE,
    ACK_OK,
    ADDRESSED_COMMANDS,
    BROADCAST_COMMANDS,
    BROADCAST_ID,
    GET_BASE,
    MAX_MODULE_ID,
    MIN_MODULE_ID,
    PARAM_TYPES,
    SET_BASE,
    BaudRate,
    CommandId,
    MotionMode,
    ParamId,
    ShortState,
    WireType,
)

__all__ = [
    "Ack", "AckKey", "BroadcastRequest", "CommandAck", "CommandRequest", "GetParam",
    "GetParamAck", "Message", "MotionAck", "MotionExtAck", "PosStateDio", "Request",
    "SetMotion", "SetParam", "SetParamAck", "ack_key", "decode_ack", "decode_request",
    "encode", "expected_ack_key",
]


# --------------------------------------------------------------------------------------
# Messages


@dataclass(frozen=True, slots=True)
class PosStateDio:
    """Value of parameter 0x62 FPosStateDio: position (rad), short state, digital I/O."""

    position: float
    state: ShortState
    dio: int


@dataclass(frozen=True, slots=True)
class CommandRequest:
    """A one-byte command to one module (Reset, Home, Halt, RecalcPID, SaveParams, ...)."""

    module: int
    command: CommandId


@dataclass(frozen=True, slots=True)
class BroadcastRequest:
    """A command to all modules on 0x100; ``arg`` is the optional second byte
    (the baud id for SetBaudAll, 0x00 in m5api's variant of the others). Never acked."""

    command: CommandId
    arg: int | None = None


@dataclass(frozen=True, slots=True)
class GetParam:
    """GetExtended: read a parameter."""

    module: int
    param: ParamId


@dataclass(frozen=True, slots=True)
class SetParam:
    """SetExtended: write a parameter; ``value`` has the parameter's wire type."""

    module: int
    param: ParamId
    value: float | int


@dataclass(frozen=True, slots=True)
class SetMotion:
    """SetMotion: start a motion; ``time_ms`` is required exactly for step/loop modes."""

    module: int
    mode: MotionMode
    value: float | int
    time_ms: int | None = None


@dataclass(frozen=True, slots=True)
class CommandAck:
    module: int
    command: CommandId


@dataclass(frozen=True, slots=True)
class SetParamAck:
    module: int
    param: ParamId


@dataclass(frozen=True, slots=True)
class GetParamAck:
    module: int
    param: ParamId
    #: Its type follows ``param``'s wire type (PARAM_TYPES): a float, an integer, or a
    #: PosStateDio for FPOS_STATE_DIO; typed Any so readers need not re-check it.
    value: Any


@dataclass(frozen=True, slots=True)
class MotionAck:
    """Simple acknowledge of a SetMotion in a non-``*_ACK`` mode."""

    module: int
    mode: MotionMode


@dataclass(frozen=True, slots=True)
class MotionExtAck:
    """Extended acknowledge of a ``*_ACK`` SetMotion: the actual position (rad, or ticks for
    the integer modes) when the command was received, the short state and the dio byte."""

    module: int
    mode: MotionMode
    position: float | int
    state: ShortState
    dio: int


Request = Union[CommandRequest, BroadcastRequest, GetParam, SetParam, SetMotion]
Ack = Union[CommandAck, SetParamAck, GetParamAck, MotionAck, MotionExtAck]
Message = Union[Request, Ack]


class AckKey(NamedTuple):
    """What an acknowledge is matched on: module, byte 0, byte 1 (None for commands)."""

    module: int
    command: int
    sub: int | None


# --------------------------------------------------------------------------------------
# Layouts: one struct per frame layout

_CMD = struct.Struct("<B")
_CMD_ARG = struct.Struct("<BB")
_CMD_ACK = struct.Struct("<BB")  # [cmd, 0x64]
_HEAD = struct.Struct("<BB")  # [cmd, param|mode]
_SHORT_ACK = struct.Struct("<BBB")  # [cmd, param|mode, 0x64]
_MOTION_F = struct.Struct("<BBf")
_MOTION_I = struct.Struct("<BBi")
_MOTION_I16 = struct.Struct("<BBh")  # RobWork's ICUR
_MOTION_F_TIME = struct.Struct("<BBfH")
_MOTION_I_TIME = struct.Struct("<BBiH")
_EXT_ACK_F = struct.Struct("<BBfBB")
_EXT_ACK_I = struct.Struct("<BBiBB")
#: SetExtended / GetExtended-ack layouts per wire type: [cmd, par, value...]
_PARAM_LAYOUT = {wt: struct.Struct("<BB" + wt.fmt[1:]) for wt in WireType}

_SET_EXTENDED = CommandId.SET_EXTENDED.value
_GET_EXTENDED = CommandId.GET_EXTENDED.value
_SET_MOTION = CommandId.SET_MOTION.value

# Fast value -> enum lookups (calling an IntEnum is comparatively slow on the hot path).
_PARAMS = {p.value: p for p in ParamId}
_PARAM_LAYOUT_BY_ID = {p.value: (p, wt, _PARAM_LAYOUT[wt]) for p, wt in PARAM_TYPES.items()}
_MODES = {m.value: m for m in MotionMode}
_COMMANDS = {c.value: c for c in CommandId}
_ADDRESSED = {c.value: c for c in ADDRESSED_COMMANDS}
_BROADCAST = {c.value: c for c in BROADCAST_COMMANDS}
_SHORT_STATES = [ShortState(i) for i in range(256)]

_MOTION_VALUE_LAYOUT = {
    # (is_float, has_time) -> request struct
    (True, False): _MOTION_F,
    (False, False): _MOTION_I,
    (True, True): _MOTION_F_TIME,
    (False, True): _MOTION_I_TIME,
}
#: mode value -> (mode, is_float, has_time, is_extended_ack, request struct): the mode's
#: properties looked up once (each is a property call and a set lookup).
_MODE_INFO = {m.value: (m, m.is_float, m.has_time, m.is_extended_ack,
                        _MOTION_VALUE_LAYOUT[m.is_float, m.has_time]) for m in MotionMode}
_ICUR_MODES = frozenset({MotionMode.ICUR, MotionMode.ICUR_ACK})
_F32, _F32_U8_U8 = WireType.F32, WireType.F32_U8_U8
_I32_MIN, _I32_MAX = -(2**31), 2**31 - 1


# --------------------------------------------------------------------------------------
# Validation helpers


def _check_module(module: int) -> int:
    if not isinstance(module, int) or not MIN_MODULE_ID <= module <= MAX_MODULE_ID:
        raise CodecError(f"module id {module!r} outside {MIN_MODULE_ID}..{MAX_MODULE_ID}")
    return module


def _check_int(value: object, lo: int, hi: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise CodecError(f"{what} must be an integer, got {value!r}")
    if not lo <= value <= hi:
        raise CodecError(f"{what} {value} outside {lo}..{hi}")
    return value


def _check_float(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CodecError(f"{what} must be a number, got {value!r}")
    value = float(value)
    # Values beyond float32 range would raise OverflowError in struct; infinities and NaN
    # are encoded as given (the caller decides what is sensible).
    if math.isfinite(value) and abs(value) > _F32_MAX:
        raise CodecError(f"{what} {value!r} does not fit a float32")
    return value


_F32_MAX = struct.unpack("<f", b"\xff\xff\x7f\x7f")[0]


def _pack_value(wire: WireType, value: object, param: ParamId) -> tuple:
    """The struct values of a parameter value; ``param`` names it in errors."""
    # Fast paths for valid floats and bytes (the checks below would pass them unchanged);
    # the names for the messages are only made when a check fails.
    if wire is _F32:
        if type(value) is float and -_F32_MAX <= value <= _F32_MAX:
            return (value,)
        return (_check_float(value, param.name),)
    if wire is _F32_U8_U8:
        if not isinstance(value, PosStateDio):
            raise CodecError(f"{param.name} must be a PosStateDio, got {value!r}")
        position = value.position
        if not (type(position) is float and -_F32_MAX <= position <= _F32_MAX):
            position = _check_float(position, f"{param.name} position")
        state = int(value.state)
        if not (type(state) is int and 0 <= state <= 255):
            state = _check_int(state, 0, 255, f"{param.name} state")
        dio = value.dio
        if not (type(dio) is int and 0 <= dio <= 255):
            dio = _check_int(dio, 0, 255, f"{param.name} dio")
        return (position, state, dio)
    return (_check_int(value, wire.minimum, wire.maximum, param.name),)  # type: ignore


def _param(param: object) -> tuple[ParamId, WireType, struct.Struct]:
    try:
        return _PARAM_LAYOUT_BY_ID[param]  # type: ignore[index]
    except (KeyError, TypeError):
        raise CodecError(f"unknown parameter id {_hex(param)}") from None


def _mode(mode: object) -> MotionMode:
    try:
        return _MODES[mode]  # type: ignore[index]
    except (KeyError, TypeError):
        raise CodecError(f"unknown motion mode {_hex(mode)}") from None


def _mode_info(mode: object) -> tuple[MotionMode, bool, bool, bool, struct.Struct]:
    """(mode, is_float, has_time, is_extended_ack, request struct); errors as :func:`_mode`."""
    try:
        return _MODE_INFO[mode]  # type: ignore[index]
    except (KeyError, TypeError):
        raise CodecError(f"unknown motion mode {_hex(mode)}") from None


def _hex(value: object) -> str:
    return f"0x{value:02X}" if isinstance(value, int) else repr(value)


def _hexdata(data: bytes) -> str:
    return data.hex(" ").upper() or "(empty)"


# --------------------------------------------------------------------------------------
# Encoding


def encode(msg: Message) -> tuple[int, bytes]:
    """Encode a request or an acknowledge to ``(can_id, data)``.

    :raises ~seqrun.errors.CodecError: a field that does not fit the wire (module id,
        unknown command/param/mode, integer out of range for its wire type, float beyond
        float32, missing or superfluous step time).
    """
    try:
        encoder = _ENCODERS[type(msg)]
    except KeyError:
        raise CodecError(f"not a PowerCube message: {msg!r}") from None
    return encoder(msg)


def _encode_command(msg: CommandRequest) -> tuple[int, bytes]:
    if msg.command not in _ADDRESSED:
        raise CodecError(f"command {_hex(msg.command)} cannot be addressed to a module")
    return SET_BASE + _check_module(msg.module), _CMD.pack(msg.command)


def _encode_broadcast(msg: BroadcastRequest) -> tuple[int, bytes]:
    if msg.command not in _BROADCAST:
        raise CodecError(f"command {_hex(msg.command)} cannot be broadcast")
    if msg.command == CommandId.SET_BAUD_ALL:
        if msg.arg is None:
            raise CodecError("SetBaudAll needs a baud-rate id")
        if msg.arg not in BaudRate._value2member_map_:
            raise CodecError(f"unknown baud-rate id {_hex(msg.arg)} (0..3)")
    if msg.arg is None:
        return BROADCAST_ID, _CMD.pack(msg.command)
    arg = _check_int(msg.arg, 0, 255, "broadcast argument")
    return BROADCAST_ID, _CMD_ARG.pack(msg.command, arg)


def _encode_get(msg: GetParam) -> tuple[int, bytes]:
    param, _, _ = _param(msg.param)
    return GET_BASE + _check_module(msg.module), _HEAD.pack(_GET_EXTENDED, param)


def _encode_set(msg: SetParam) -> tuple[int, bytes]:
    param, wire, layout = _param(msg.param)
    if wire is _F32_U8_U8:
        raise CodecError(f"parameter {param.name} is read only")
    values = _pack_value(wire, msg.value, param)
    return SET_BASE + _check_module(msg.module), layout.pack(_SET_EXTENDED, param, *values)


def _encode_motion(msg: SetMotion) -> tuple[int, bytes]:
    mode, is_float, has_time, _, layout = _mode_info(msg.mode)
    can_id = SET_BASE + _check_module(msg.module)
    value = msg.value
    if is_float:
        if not (type(value) is float and -_F32_MAX <= value <= _F32_MAX):
            value = _check_float(value, f"{mode.name} value")
    elif not (type(value) is int and _I32_MIN <= value <= _I32_MAX):
        value = _check_int(value, _I32_MIN, _I32_MAX, f"{mode.name} value")
    if has_time:
        if msg.time_ms is None:
            raise CodecError(f"{mode.name} needs a time in ms")
        time_ms = _check_int(msg.time_ms, 0, 0xFFFF, f"{mode.name} time_ms")
        return can_id, layout.pack(_SET_MOTION, mode, value, time_ms)
    if msg.time_ms is not None:
        raise CodecError(f"{mode.name} takes no time (got time_ms={msg.time_ms!r})")
    return can_id, layout.pack(_SET_MOTION, mode, value)


def _encode_command_ack(msg: CommandAck) -> tuple[int, bytes]:
    if msg.command not in _ADDRESSED:
        raise CodecError(f"command {_hex(msg.command)} is not acknowledged as a command")
    return ACK_BASE + _check_module(msg.module), _CMD_ACK.pack(msg.command, ACK_OK)


def _encode_set_ack(msg: SetParamAck) -> tuple[int, bytes]:
    param, _, _ = _param(msg.param)
    return ACK_BASE + _check_module(msg.module), _SHORT_ACK.pack(_SET_EXTENDED, param, ACK_OK)


def _encode_get_ack(msg: GetParamAck) -> tuple[int, bytes]:
    param, wire, layout = _param(msg.param)
    values = _pack_value(wire, msg.value, param)
    return ACK_BASE + _check_module(msg.module), layout.pack(_GET_EXTENDED, param, *values)


def _encode_motion_ack(msg: MotionAck) -> tuple[int, bytes]:
    mode = _mode(msg.mode)
    if mode.is_extended_ack:
        raise CodecError(f"{mode.name} is acknowledged with a MotionExtAck")
    return ACK_BASE + _check_module(msg.module), _SHORT_ACK.pack(_SET_MOTION, mode, ACK_OK)


def _encode_motion_ext_ack(msg: MotionExtAck) -> tuple[int, bytes]:
    mode, is_float, _, is_extended_ack, _ = _mode_info(msg.mode)
    if not is_extended_ack:
        raise CodecError(f"{mode.name} is acknowledged with a plain MotionAck")
    state = int(msg.state)
    if not (type(state) is int and 0 <= state <= 255):
        state = _check_int(state, 0, 255, "short state")
    dio = msg.dio
    if not (type(dio) is int and 0 <= dio <= 255):
        dio = _check_int(dio, 0, 255, "dio")
    position = msg.position
    if is_float:
        if not (type(position) is float and -_F32_MAX <= position <= _F32_MAX):
            position = _check_float(position, "position")
        data = _EXT_ACK_F.pack(_SET_MOTION, mode, position, state, dio)
    else:
        position = _check_int(position, _I32_MIN, _I32_MAX, "position")
        data = _EXT_ACK_I.pack(_SET_MOTION, mode, position, state, dio)
    return ACK_BASE + _check_module(msg.module), data


_ENCODERS: dict[type, Callable[[Any], tuple[int, bytes]]] = {
    CommandRequest: _encode_command,
    BroadcastRequest: _encode_broadcast,
    GetParam: _encode_get,
    SetParam: _encode_set,
    SetMotion: _encode_motion,
    CommandAck: _encode_command_ack,
    SetParamAck: _encode_set_ack,
    GetParamAck: _encode_get_ack,
    MotionAck: _encode_motion_ack,
    MotionExtAck: _encode_motion_ext_ack,
}


# --------------------------------------------------------------------------------------
# Decoding


def _unpack_value(wire: WireType, layout: struct.Struct, data: bytes):
    if wire is _F32_U8_U8:
        _, _, position, state, dio = layout.unpack_from(data)
        return PosStateDio(position, _SHORT_STATES[state], dio)
    return layout.unpack_from(data)[2]


#: Most decoded frames kept per direction (see _remember).
_DECODED_KEPT = 4096
_decoded_requests: dict[tuple[int, bytes], Request] = {}
_decoded_acks: dict[tuple[int, bytes], Ack] = {}


def _remember(memo: dict, key: tuple[int, bytes], message: Message) -> None:
    """Keep a decoded frame: decoding is a pure function of (id, data), its messages are
    immutable, and a bus carries the same frames over and over (every read of a module at
    rest, every request of a cycle's reads); bounded, since positions vary."""
    if len(memo) >= _DECODED_KEPT:
        memo.clear()
    memo[key] = message


def decode_request(can_id: int, data: bytes) -> Request:
    """Decode a host -> module frame (the simulator's side of the wire).

    :raises ~seqrun.errors.CodecError: the frame is not a valid PowerCube request.
    """
    key = (can_id, data if type(data) is bytes else bytes(data))
    request = _decoded_requests.get(key)
    if request is None:
        request = _decode_request(*key)
        _remember(_decoded_requests, key, request)
    return request


def _decode_request(can_id: int, data: bytes) -> Request:
    if can_id == BROADCAST_ID:
        return _decode_broadcast(data)
    if GET_BASE <= can_id < GET_BASE + 0x20:
        module = _module_from_id(can_id, GET_BASE, "GET")
        if len(data) != 2 or data[0] != _GET_EXTENDED:
            raise CodecError(f"module {module}: GET frame must be [0A, par], got "
                             f"{_hexdata(data)}")
        param, _, _ = _param(data[1])
        return GetParam(module, param)
    if SET_BASE <= can_id < SET_BASE + 0x20:
        module = _module_from_id(can_id, SET_BASE, "SET")
        if not data:
            raise CodecError(f"module {module}: empty SET frame")
        command = data[0]
        if command == _SET_EXTENDED:
            return _decode_set_param(module, data)
        if command == _SET_MOTION:
            return _decode_set_motion(module, data)
        if command in _ADDRESSED:
            if len(data) != 1:
                raise CodecError(f"module {module}: command {_COMMANDS[command].name} must be "
                                 f"1 byte, got {_hexdata(data)}")
            return CommandRequest(module, _ADDRESSED[command])
        name = _COMMANDS[command].name if command in _COMMANDS else "unknown"
        raise CodecError(f"module {module}: unsupported command {_hex(command)} ({name})")
    raise CodecError(f"CAN id 0x{can_id:03X} is not a PowerCube request id")


def _module_from_id(can_id: int, base: int, what: str) -> int:
    module = can_id - base
    if not MIN_MODULE_ID <= module <= MAX_MODULE_ID:
        raise CodecError(f"{what} id 0x{can_id:03X} addresses module {module} "
                         f"(valid {MIN_MODULE_ID}..{MAX_MODULE_ID})")
    return module


def _decode_broadcast(data: bytes) -> BroadcastRequest:
    if not 1 <= len(data) <= 2:
        raise CodecError(f"broadcast must be 1 or 2 bytes, got {_hexdata(data)}")
    command = _BROADCAST.get(data[0])
    if command is None:
        raise CodecError(f"command {_hex(data[0])} cannot be broadcast")
    arg = data[1] if len(data) == 2 else None
    if command == CommandId.SET_BAUD_ALL:  # 0x09 on the broadcast id is always SetBaudAll
        if arg is None or arg not in BaudRate._value2member_map_:
            raise CodecError(f"SetBaudAll needs a baud-rate id 0..3, got {_hexdata(data)}")
    return BroadcastRequest(command, arg)


def _decode_set_param(module: int, data: bytes) -> SetParam:
    if len(data) < 2:
        raise CodecError(f"module {module}: SetExtended without parameter id")
    param, wire, layout = _param(data[1])
    if wire is _F32_U8_U8:
        raise CodecError(f"module {module}: parameter {param.name} is read only")
    if len(data) != layout.size:
        raise CodecError(f"module {module}: SetExtended {param.name} needs {layout.size} "
                         f"bytes, got {_hexdata(data)}")
    return SetParam(module, param, _unpack_value(wire, layout, data))


def _decode_set_motion(module: int, data: bytes) -> SetMotion:
    if len(data) < 2:
        raise CodecError(f"module {module}: SetMotion without mode")
    mode, _, has_time, _, layout = _mode_info(data[1])
    if mode in _ICUR_MODES and len(data) == _MOTION_I16.size:
        return SetMotion(module, mode, _MOTION_I16.unpack(data)[2])
    if len(data) != layout.size:
        raise CodecError(f"module {module}: SetMotion {mode.name} needs {layout.size} bytes, "
                         f"got {_hexdata(data)}")
    if has_time:
        _, _, value, time_ms = layout.unpack(data)
        return SetMotion(module, mode, value, time_ms)
    return SetMotion(module, mode, layout.unpack(data)[2])


def decode_ack(can_id: int, data: bytes) -> Ack:
    """Decode a module -> host frame on ``0x0A0 + m`` (the client's side of the wire).

    :raises ~seqrun.errors.CodecError: the frame is not a valid PowerCube acknowledge.
    """
    key = (can_id, data if type(data) is bytes else bytes(data))
    ack = _decoded_acks.get(key)
    if ack is None:
        ack = _decode_ack(*key)
        _remember(_decoded_acks, key, ack)
    return ack


def _decode_ack(can_id: int, data: bytes) -> Ack:
    module = can_id - ACK_BASE
    if not MIN_MODULE_ID <= module <= MAX_MODULE_ID:
        if ACK_BASE <= can_id < ACK_BASE + 0x20:
            raise CodecError(f"ack id 0x{can_id:03X} names module {module} "
                             f"(valid {MIN_MODULE_ID}..{MAX_MODULE_ID})")
        raise CodecError(f"CAN id 0x{can_id:03X} is not a PowerCube ack id")
    if not data:
        raise CodecError(f"module {module}: empty ack")
    command = data[0]
    if command == _GET_EXTENDED:
        if len(data) < 2:
            raise CodecError(f"module {module}: GetExtended ack without parameter id")
        param, wire, layout = _param(data[1])
        if len(data) < layout.size:
            raise CodecError(f"module {module}: GetExtended ack of {param.name} needs "
                             f"{layout.size} bytes, got {_hexdata(data)}")
        return GetParamAck(module, param, _unpack_value(wire, layout, data))
    if command == _SET_MOTION:
        if len(data) < 2:
            raise CodecError(f"module {module}: SetMotion ack without mode")
        mode, is_float, _, is_extended_ack, _ = _mode_info(data[1])
        if not is_extended_ack:
            return MotionAck(module, mode)
        if len(data) < _EXT_ACK_F.size:
            raise CodecError(f"module {module}: {mode.name} ack needs 8 bytes, got "
                             f"{_hexdata(data)}")
        layout = _EXT_ACK_F if is_float else _EXT_ACK_I
        _, _, position, state, dio = layout.unpack_from(data)
        return MotionExtAck(module, mode, position, _SHORT_STATES[state], dio)
    if command == _SET_EXTENDED:
        if len(data) < 2:
            raise CodecError(f"module {module}: SetExtended ack without parameter id")
        return SetParamAck(module, _param(data[1])[0])
    addressed = _ADDRESSED.get(command)
    if addressed is not None:
        return CommandAck(module, addressed)
    raise CodecError(f"module {module}: ack of unknown command {_hex(command)}: "
                     f"{_hexdata(data)}")


# --------------------------------------------------------------------------------------
# Matching


#: Builds an AckKey without the named tuple's Python-level ``__new__`` (twice per frame pair).
_new_tuple = tuple.__new__


def ack_key(ack: Ack) -> AckKey:
    """The key an acknowledge is matched on."""
    kind = type(ack)
    if kind is GetParamAck:
        return _new_tuple(AckKey, (ack.module, _GET_EXTENDED, int(ack.param)))  # type: ignore
    if kind is MotionExtAck or kind is MotionAck:
        return _new_tuple(AckKey, (ack.module, _SET_MOTION, int(ack.mode)))  # type: ignore
    if kind is SetParamAck:
        return _new_tuple(AckKey, (ack.module, _SET_EXTENDED, int(ack.param)))  # type: ignore
    if kind is CommandAck:
        return _new_tuple(AckKey, (ack.module, int(ack.command), None))  # type: ignore
    raise CodecError(f"not an acknowledge: {ack!r}")


def expected_ack_key(request: Request) -> AckKey | None:
    """The key of the acknowledge ``request`` is answered with; None for broadcasts."""
    kind = type(request)
    if kind is GetParam:
        return _new_tuple(AckKey, (request.module, _GET_EXTENDED, int(request.param)))  # type: ignore
    if kind is SetMotion:
        return _new_tuple(AckKey, (request.module, _SET_MOTION, int(request.mode)))  # type: ignore
    if kind is SetParam:
        return _new_tuple(AckKey, (request.module, _SET_EXTENDED, int(request.param)))  # type: ignore
    if kind is CommandRequest:
        return _new_tuple(AckKey, (request.module, int(request.command), None))  # type: ignore
    if kind is BroadcastRequest:
        return None
    raise CodecError(f"not a request: {request!r}")
