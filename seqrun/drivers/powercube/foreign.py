"""Another master on the bus: request frames this process did not send.

Only a master sends on the request identifiers (GetExtended ``0x0C0 + m``, every other
addressed request ``0x0E0 + m``, broadcasts ``0x100``); the modules answer on
``0x0A0 + m``. The protocol has no sequence numbers, so a second master's answers cannot be
told from ours: during a run a request frame we did not send is a fault (Halt, exit 3);
while only watching (``seqrun status --watch``) it is a warning.

A Halt broadcast is told apart: ``seqrun halt`` in another terminal sends one straight to
the bus, and it is named as what it is, not as a mystery.

None of the transports seqrun uses hands a client its own frames back (python-can's
SocketCAN and virtual buses do not unless ``receive_own_messages`` is set, the simulator
never does, and ``seqrun sim serve`` sends a client every other client's frames, never its
own; tests/test_foreign_frames.py checks each). With ``receive_own_messages`` set, each
frame we send is expected back once and not counted.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Callable

from seqrun.powercube.protocol import BROADCAST_ID, GET_BASE, SET_BASE, CommandId

#: 11-bit identifiers only a master sends on.
REQUEST_IDS = range(GET_BASE, SET_BASE + 0x20)


def is_request_frame(msg) -> bool:
    """A data frame on a request identifier (GET, SET or broadcast)."""
    if msg.is_extended_id or getattr(msg, "is_remote_frame", False) or \
            getattr(msg, "is_error_frame", False):
        return False
    return msg.arbitration_id in REQUEST_IDS or msg.arbitration_id == BROADCAST_ID


@dataclass(frozen=True)
class ForeignFrame:
    """A request frame this process did not send."""

    can_id: int
    data: bytes

    @property
    def is_halt(self) -> bool:
        """A Halt broadcast (``seqrun halt`` from another terminal, or another master's
        emergency stop)."""
        return self.can_id == BROADCAST_ID and self.data[:1] == bytes([CommandId.HALT])

    def frame(self) -> str:
        """``frame 0x0C3 [0A 62]: GetExtended FPOS_STATE_DIO to module 3``."""
        text = f"frame 0x{self.can_id:03X} [{self.data.hex(' ').upper()}]"
        what = _decoded(self.can_id, self.data)
        return f"{text}: {what}" if what else text

    def message(self) -> str:
        """The one line the operator reads."""
        if self.is_halt:
            return (f"Halt broadcast from another process "
                    f"(frame 0x{self.can_id:03X} [{self.data.hex(' ').upper()}])")
        return f"another controller is on the bus ({self.frame()})"


def _decoded(can_id: int, data: bytes) -> str:
    from seqrun.errors import CodecError
    from seqrun.powercube.codec import (BroadcastRequest, CommandRequest, GetParam, SetMotion,
                                        SetParam, decode_request)

    try:
        request = decode_request(can_id, bytes(data))
    except (CodecError, ValueError):
        return ""
    if isinstance(request, BroadcastRequest):
        return f"{CommandId(request.command).name.title().replace('_', '')} broadcast"
    module = f"to module {request.module}"
    if isinstance(request, GetParam):
        return f"GetExtended {request.param.name} {module}"
    if isinstance(request, SetParam):
        return f"SetExtended {request.param.name} {module}"
    if isinstance(request, SetMotion):
        return f"SetMotion {request.mode.name} {module}"
    if isinstance(request, CommandRequest):
        return f"{CommandId(request.command).name.title()} {module}"
    return ""


class ForeignFrameWatch:
    """A frame listener (:meth:`PowerCubeClient.add_frame_listener`) that calls
    ``on_foreign`` for every request frame received that this process did not send.

    :param echoes_own: the transport hands our own frames back (``receive_own_messages``):
        each one sent is expected back once and not reported.
    """

    def __init__(self, on_foreign: Callable[[ForeignFrame], None], *,
                 echoes_own: bool = False) -> None:
        self.on_foreign = on_foreign
        self.echoes_own = echoes_own
        self.seen = 0
        self._sent: Counter[tuple[int, bytes]] = Counter()

    def __call__(self, msg) -> None:
        if not msg.is_rx:  # one of ours, as it leaves (every request: no key made for it)
            if self.echoes_own and is_request_frame(msg):
                self._sent[msg.arbitration_id, bytes(msg.data)] += 1
            return
        if not is_request_frame(msg):
            return
        key = (msg.arbitration_id, bytes(msg.data))
        if self._sent[key] > 0:
            self._sent[key] -= 1
            return
        self.seen += 1
        self.on_foreign(ForeignFrame(*key))

