"""When a received frame was on the wire, on the host's clock (pure).

The host's own time stamp of a frame is taken when its thread gets the frame out of the
interface; a host that stalls there (the interpreter lock held elsewhere, the thread kept
off the CPU) stamps late. A velocity computed over such stamps invents speed: a stalled
sample and the punctual one after it are close in time but far apart in position. The CAN
interface stamps every frame itself when it arrives (SocketCAN: the kernel; socketcand: the
server; the simulator: its delivery time), in a time base of its own. :class:`WireTime`
maps that stamp onto the host's clock by the smallest delay seen between the two (a frame
taken at once shows the true offset; a late one only adds to it), over a sliding window so
that slow drift between the two clocks is followed.
"""

from __future__ import annotations

import math

#: The smallest delay is taken over the last one to two windows (s).
WINDOW_S = 2.0


class WireTime:
    """``place(own, now)``: the host-clock time a frame was on the wire, from the
    interface's stamp ``own`` and the host's ``now`` at reception (``now`` itself when the
    interface gives no usable stamp)."""

    def __init__(self, window_s: float = WINDOW_S) -> None:
        self.window_s = window_s
        self._started: float | None = None
        self._current = math.inf
        self._previous = math.inf

    def place(self, own: float | None, now: float) -> float:
        if not isinstance(own, (int, float)) or not own or not math.isfinite(own):
            return now
        delay = now - own
        if self._started is None or now - self._started > self.window_s:
            self._previous, self._current, self._started = self._current, delay, now
        elif delay < self._current:
            self._current = delay
        offset = min(self._current, self._previous)
        return min(now, own + offset)
