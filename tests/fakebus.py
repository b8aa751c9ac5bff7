"""A scripted stand-in for a PowerCube arm: a :class:`can.BusABC` on a VirtualClock.

Every frame sent is decoded with the codec and handed to a *handler*, which returns the
replies: acknowledges (answered after :attr:`FakeBus.latency`), :class:`Reply` objects with
their own delay, raw ``(can_id, data)`` frames or ready ``can.Message`` objects. Returning
nothing drops the request. :meth:`FakeBus.inject` queues any frame at any time.

Like the real simulator, :meth:`recv` delivers the next frame due within the timeout and
advances the clock to it, or advances the clock by the whole timeout and returns None.
:attr:`FakeBus.events` records ``("send" | "recv", time, message)`` in order, so tests can
check pipelining.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import can

from seqrun.clock import VirtualClock
from seqrun.errors import CodecError
from seqrun.powercube.codec import (
    Ack,
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
    decode_request,
    encode,
)
from seqrun.powercube.protocol import PARAM_TYPES, ParamId, ShortState, WireType


@dataclass
class Reply:
    """One frame to answer with, ``delay`` seconds after the request (None: bus latency)."""

    frame: Ack | tuple[int, bytes] | can.Message
    delay: float | None = None


Handler = Callable[[Request], Iterable[Reply | Ack | tuple[int, bytes] | can.Message] | None]


def _to_message(frame: Ack | tuple[int, bytes] | can.Message) -> can.Message:
    if isinstance(frame, can.Message):
        return frame
    if isinstance(frame, tuple):
        can_id, data = frame
    else:
        can_id, data = encode(frame)
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


class FakeBus(can.BusABC):
    """Answers requests from a handler function, on virtual time."""

    def __init__(self, clock: VirtualClock, handler: Handler | None = None, *,
                 latency: float = 0.0002, channel: str = "fake", **kwargs: object) -> None:
        self.clock = clock
        self.handler: Handler = handler or (lambda request: None)
        self.latency = latency
        #: Every frame sent, in order.
        self.sent: list[can.Message] = []
        #: Requests decoded from ``sent`` (None where a frame did not decode).
        self.requests: list[Request | None] = []
        #: ``("send" | "recv", time, msg)`` in order.
        self.events: list[tuple[str, float, can.Message]] = []
        #: Raise this from the next ``send`` (then reset).
        self.fail_next_send: Exception | None = None
        self.shutdown_calls = 0
        self._queue: list[tuple[float, int, can.Message]] = []
        self._seq = itertools.count()
        super().__init__(channel=channel, **kwargs)

    # ------------------------------------------------------------------ scripting
    def inject(self, frame: Ack | tuple[int, bytes] | can.Message,
               at: float | None = None) -> None:
        """Queue ``frame`` for delivery at time ``at`` (default: now)."""
        msg = _to_message(frame)
        heapq.heappush(self._queue, (self.clock.now() if at is None else at,
                                     next(self._seq), msg))

    def sent_requests(self, kind: type | None = None) -> list[Request]:
        return [r for r in self.requests if r is not None and (kind is None or
                                                                isinstance(r, kind))]

    @property
    def pending(self) -> int:
        return len(self._queue)

    # ------------------------------------------------------------------ BusABC
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.fail_next_send is not None:
            exc, self.fail_next_send = self.fail_next_send, None
            raise exc
        now = self.clock.now()
        self.sent.append(msg)
        self.events.append(("send", now, msg))
        try:
            request = decode_request(msg.arbitration_id, bytes(msg.data))
        except CodecError:
            self.requests.append(None)
            return
        self.requests.append(request)
        for reply in self.handler(request) or ():
            if not isinstance(reply, Reply):
                reply = Reply(reply)
            delay = self.latency if reply.delay is None else reply.delay
            self.inject(reply.frame, at=now + delay)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        deadline = None if timeout is None else self.clock.now() + timeout
        if self._queue and (deadline is None or self._queue[0][0] <= deadline):
            due, _, msg = heapq.heappop(self._queue)
            self.clock.sleep_until(due)
            msg = can.Message(arbitration_id=msg.arbitration_id, data=msg.data,
                              is_extended_id=msg.is_extended_id,
                              is_remote_frame=msg.is_remote_frame,
                              is_error_frame=msg.is_error_frame, dlc=msg.dlc,
                              timestamp=self.clock.now(), is_rx=True)
            self.events.append(("recv", self.clock.now(), msg))
            return msg
        if deadline is not None:
            self.clock.sleep_until(deadline)
        return None

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return self.recv(timeout), True

    def shutdown(self) -> None:
        self.shutdown_calls += 1
        super().shutdown()


def _default_value(param: ParamId) -> float | int | PosStateDio:
    wire = PARAM_TYPES[param]
    if wire is WireType.F32_U8_U8:
        return PosStateDio(0.0, ShortState.RAMP_END, 0)
    return 0.0 if wire is WireType.F32 else 0


class ArmHandler:
    """A healthy arm: every addressed request to one of ``modules`` is acknowledged
    correctly; parameters are stored in :attr:`params`; motion sets the position at once."""

    def __init__(self, modules: Iterable[int] = range(1, 8), version: int = 0x4638) -> None:
        self.modules = set(modules)
        self.params: dict[tuple[int, ParamId], float | int | PosStateDio] = {}
        self.positions = {m: 0.0 for m in self.modules}
        self.state = {m: ShortState.RAMP_END for m in self.modules}
        self.version = version

    def value(self, module: int, param: ParamId) -> float | int | PosStateDio:
        if param == ParamId.FPOS_STATE_DIO:
            return PosStateDio(self.positions[module], self.state[module], 0)
        if param == ParamId.ACT_POS:
            return self.positions[module]
        if param == ParamId.DEF_CUBE_VERSION:
            return self.version
        return self.params.get((module, param), _default_value(param))

    def __call__(self, request: Request) -> list[Ack]:
        if isinstance(request, BroadcastRequest) or request.module not in self.modules:
            return []
        m = request.module
        if isinstance(request, GetParam):
            return [GetParamAck(m, request.param, self.value(m, request.param))]
        if isinstance(request, SetParam):
            self.params[(m, request.param)] = request.value
            return [SetParamAck(m, request.param)]
        if isinstance(request, SetMotion):
            before = self.positions[m]
            if request.mode.is_float and "VEL" not in request.mode.name:
                self.positions[m] = request.value
            if request.mode.is_extended_ack:
                position = before if request.mode.is_float else 0
                return [MotionExtAck(m, request.mode, position, self.state[m], 0)]
            return [MotionAck(m, request.mode)]
        if isinstance(request, CommandRequest):
            return [CommandAck(m, request.command)]
        return []
