"""A python-can bus that wraps another one and lets a test act around send and recv.

Tests use it to stall the host (advance a virtual clock inside ``recv``), to break the
connection mid-run (``send``/``recv`` raising what python-can raises when a socket dies),
or to watch the order of sends and receives. Everything else goes to the wrapped bus.
"""

from __future__ import annotations

from collections.abc import Callable

import can


class WrapBus(can.BusABC):
    """Delegates to ``inner``; ``before_send(msg)`` / ``before_recv(timeout)`` run first
    and may raise. ``calls`` records ``("send" | "recv", msg_or_None)`` in order."""

    def __init__(self, inner: can.BusABC, *,
                 before_send: Callable[[can.Message], None] | None = None,
                 before_recv: Callable[[float | None], None] | None = None) -> None:
        self.inner = inner
        self.before_send = before_send
        self.before_recv = before_recv
        self.calls: list[tuple[str, can.Message | None]] = []
        self.sends = 0
        super().__init__(channel=getattr(inner, "channel", "wrapped"))

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.before_send is not None:
            self.before_send(msg)
        self.sends += 1
        self.calls.append(("send", msg))
        self.inner.send(msg, timeout=timeout)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self.before_recv is not None:
            self.before_recv(timeout)
        msg = self.inner.recv(timeout)
        self.calls.append(("recv", msg))
        return msg

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return self.recv(timeout), True

    def shutdown(self) -> None:
        self.inner.shutdown()
        super().shutdown()

    def __getattr__(self, name: str):
        # Only reached for attributes this class lacks (e.g. the simulator's ``arm``).
        inner = self.__dict__.get("inner")
        if inner is None:
            raise AttributeError(name)
        return getattr(inner, name)
