"""PowerCube (Schunk PRL / LWA 3) protocol: constants, pure codec and the bus client.

``protocol`` and ``codec`` are pure (no I/O); the client lives in
:mod:`seqrun.powercube.client` and is imported lazily so that the simulator can use the
codec without pulling in the client.
"""

from seqrun.powercube.codec import (
    Ack,
    AckKey,
    BroadcastRequest,
    CommandAck,
    CommandRequest,
    GetParam,
    GetParamAck,
    MotionAck,
    MotionExtAck,
    PosStateDio,
    Request,
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
    ACK_BASE,
    BROADCAST_ID,
    GET_BASE,
    MODULE_IDS,
    PARAM_TYPES,
    SET_BASE,
    STATE_BASE,
    BaudRate,
    CommandId,
    ConfigFlag,
    MotionMode,
    ParamId,
    SetupFlag,
    ShortState,
    StateFlag,
    WireType,
)

__all__ = [
    "ACK_BASE", "BROADCAST_ID", "GET_BASE", "MODULE_IDS", "PARAM_TYPES", "SET_BASE",
    "STATE_BASE", "Ack", "AckKey", "BaudRate", "BroadcastRequest", "CommandAck", "CommandId",
    "CommandRequest", "ConfigFlag", "GetParam", "GetParamAck", "MotionAck", "MotionExtAck",
    "MotionMode", "ParamId", "PosStateDio", "Request",
    "SetMotion", "SetParam", "SetParamAck", "SetupFlag", "ShortState", "StateFlag", "WireType",
    "ack_key", "decode_ack", "decode_request", "encode", "expected_ack_key",
]


def __getattr__(name: str):
    # The client imports python-can and threading; codec-only users (the simulator, the
    # benchmark) do not pay for it. Not in __all__ so that ``import *`` stays pure as well.
    if name in ("PowerCubeClient", "ModuleReading", "ClientStats"):
        from seqrun.powercube import client

        return getattr(client, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
