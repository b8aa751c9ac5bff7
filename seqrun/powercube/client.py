"""PowerCube bus client: request / acknowledge exchanges over any :class:`can.BusABC` (or the
simulator's python-can-free :class:`~seqrun.sim.port.SimPort`).

The client is the only reader of its bus (no :class:`can.Notifier`): every exchange sends
its requests, then calls ``bus.recv(timeout)`` itself until each request is matched with
its acknowledge or its deadline passes. An :class:`~threading.RLock` around every exchange
lets other threads (a watchdog keeper, a console) use the same client. All deadlines come
from the injected :class:`~seqrun.clock.Clock`; a simulated bus on a
:class:`~seqrun.clock.VirtualClock` advances that clock inside ``recv``.

Matching
    An acknowledge answers a pending request when its :class:`~seqrun.powercube.codec.AckKey`
    (module, byte 0, parameter / motion byte) is equal to the request's expected key.
    Requests with equal keys in one batch are answered in send order. Broadcasts expect
    nothing. Frames that are not acknowledges, malformed frames, and acknowledges that no
    pending request expects (another module, a duplicate, nobody asked) are discarded,
    counted in :attr:`PowerCubeClient.stats` and reported to ``on_discard(msg, reason)``.

Stale acknowledges (the protocol has no sequence numbers)
    1. A frame received *before* a request was sent is never its answer: every exchange
       first reads what is already queued (non-blocking) and discards it.
    2. When a request times out, its key is *tainted* for a quarantine window of
       :attr:`~PowerCubeClient.QUARANTINE_TIMEOUTS` response timeouts (the longer of the
       exchange's and the default one), once per timed-out request. An acknowledge with a tainted key that arrives while no request with that
       key is pending is consumed as the late answer ("stale ack") and removes one taint.
    3. Before a request whose key is still tainted is sent, the client reads the bus until
       the taint is consumed by a late acknowledge or its window has passed.

    Hence a late acknowledge is never taken as the answer to a newer request, unless it
    arrives after the whole quarantine window - a module that late is treated as having
    never answered.

Watchdog
    With :attr:`PowerCubeClient.watchdog_period` set, a refresh broadcast ``[0x07, 0x00]``
    is sent whenever one is due during any exchange or wait, so a long wait for
    acknowledges never lets a module watchdog expire; :meth:`PowerCubeClient.service`
    sends one if due.

Frame listeners (:meth:`PowerCubeClient.add_frame_listener`) see every frame sent
(``is_rx=False``) and received (``is_rx=True``), both stamped with ``clock.now()`` so a
trace shares the time base of the run's events.
"""

from __future__ import annotations

import itertools
import logging
import threading
from collections import Counter, deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from seqrun.clock import Clock
from seqrun.errors import BusError, CodecError, ModuleFaultError, ModuleTimeoutError
from seqrun.powercube.codec import (
    Ack,
    AckKey,
    BroadcastRequest,
    CommandRequest,
    GetParam,
    MotionAck,
    MotionExtAck,
    PosStateDio,
    Request,
    SetMotion,
    SetParam,
    ack_key,
    decode_ack,
    encode,
    expected_ack_key,
)
from seqrun.powercube.protocol import (
    ACK_BASE,
    BROADCAST_ID,
    MODULE_IDS,
    PARAM_TYPES,
    BaudRate,
    CommandId,
    ConfigFlag,
    MotionMode,
    ParamId,
    ShortState,
    StateFlag,
)
from seqrun.powercube.wire_time import WireTime

if TYPE_CHECKING:  # python-can only for a bus of python-can's (see _message_class)
    import can

__all__ = ["ClientStats", "DiscardReason", "ModuleReading", "PowerCubeClient"]

logger = logging.getLogger(__name__)

FrameListener = Callable[["can.Message"], None]
DiscardCallback = Callable[["can.Message", str], None]
#: ``on_ack(request, ack)`` of :meth:`PowerCubeClient.transact`; raising ends the exchange.
AckInspector = Callable[[Request, Ack], None]


class DiscardReason:
    """Why a received frame was not used (the ``reason`` given to ``on_discard``)."""

    NOT_AN_ACK = "not an ack"
    MALFORMED = "malformed"
    UNEXPECTED = "unexpected ack"
    STALE = "stale ack"
    BEFORE_REQUEST = "received before the request was sent"


@dataclass(frozen=True, slots=True)
class ModuleReading:
    """Position (rad, module coordinates), short state and dio of one module."""

    module: int
    position: float
    state: ShortState
    dio: int


@dataclass
class ClientStats:
    """Counters of a :class:`PowerCubeClient` (read them, do not rely on their identity)."""

    frames_sent: int = 0
    frames_received: int = 0
    acks_matched: int = 0
    timeouts: int = 0
    watchdog_refreshes: int = 0
    #: Discarded frames per :class:`DiscardReason` (stale acks included).
    discarded: Counter = field(default_factory=Counter)

    @property
    def stale_acks(self) -> int:
        return self.discarded[DiscardReason.STALE]

    @property
    def discarded_total(self) -> int:
        return sum(self.discarded.values())


@dataclass(slots=True)
class _Taint:
    count: int
    until: float


class PowerCubeClient:
    """Synchronous PowerCube client over ``bus``; see the module docstring for the rules.

    :param bus: any python-can bus (real adapter, ``seqrun-sim``, a test double).
    :param clock: where deadlines come from (never the wall clock directly).
    :param response_timeout: seconds to wait for each acknowledge, from its request's send.
    :param watchdog_period: send a watchdog refresh at least this often (None: never).
    :param on_discard: called with ``(msg, reason)`` for every frame not used.
    :param owns_bus: :meth:`close` also shuts the bus down.
    """

    #: Default seconds to wait for an acknowledge (m5api's SocketCAN back-end waits 100 ms
    #: per read; a healthy module answers within about a millisecond at 1 Mbit/s).
    RESPONSE_TIMEOUT = 0.05
    #: Length of the quarantine of a timed-out request's key, in response timeouts.
    QUARANTINE_TIMEOUTS = 4.0
    #: At most this many already-queued frames are flushed before a send (bounds the loop
    #: on a bus with foreign traffic).
    MAX_FLUSH_FRAMES = 1000
    #: Timeout handed to ``bus.send`` (seconds).
    SEND_TIMEOUT = 0.1
    #: One request in flight per module (see :meth:`_send_ready`). False restores the
    #: old fully pipelined sending, for benchmarks and regression tests only.
    ONE_REQUEST_PER_MODULE = True
    #: In an exchange that inspects its acknowledges (``on_ack``: a move cycle), at most
    #: this many requests wait for their answers at a time. A few keep the wire busy
    #: (request, ~100 µs module latency, answer); more would only fill the adapter's
    #: transmit queue, where the Halt that an inspected acknowledge calls for would queue
    #: behind them. Other exchanges (reads, scans) send everything at once.
    MAX_IN_FLIGHT = 3

    def __init__(self, bus: can.BusABC, clock: Clock, *,
                 response_timeout: float = RESPONSE_TIMEOUT,
                 watchdog_period: float | None = None,
                 on_discard: DiscardCallback | None = None,
                 owns_bus: bool = False) -> None:
        if response_timeout <= 0:
            raise ValueError(f"response_timeout must be positive, got {response_timeout!r}")
        self.bus = bus
        self._message = _message_class(bus)
        self.clock = clock
        self.response_timeout = float(response_timeout)
        #: Called with ``(msg, reason)`` for every received frame that is not used.
        self.on_discard = on_discard
        self.stats = ClientStats()
        self._owns_bus = owns_bus
        self._lock = threading.RLock()
        self._listeners: list[FrameListener] = []
        self._taints: dict[AckKey, _Taint] = {}
        self._watchdog_period: float | None = None
        self._watchdog_due: float | None = None
        self._closed = False
        self.watchdog_period = watchdog_period
        self._wire_time = WireTime()
        #: When the last frame received was on the wire (clock time, from the interface's
        #: own stamp; None before the first): a reading's time, even after a host stall.
        self.last_rx_at: float | None = None
        #: Per request of the last exchange: when its acknowledge was on the wire (None:
        #: not answered, or a broadcast).
        self.last_ack_times: list[float | None] = []

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Stop using the bus (and shut it down if owned). Safe to call twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            if self._owns_bus:
                self.bus.shutdown()

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self) -> PowerCubeClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ------------------------------------------------------------------ listeners
    def add_frame_listener(self, listener: FrameListener) -> None:
        """Call ``listener(msg)`` for every frame sent and received."""
        with self._lock:
            self._listeners.append(listener)

    def remove_frame_listener(self, listener: FrameListener) -> None:
        with self._lock:
            self._listeners.remove(listener)

    # ------------------------------------------------------------------ watchdog
    @property
    def watchdog_period(self) -> float | None:
        """Refresh period of the module watchdogs in seconds, or None for no refreshes.
        Setting it makes the first refresh due at once."""
        return self._watchdog_period

    @watchdog_period.setter
    def watchdog_period(self, period: float | None) -> None:
        if period is not None and period <= 0:
            raise ValueError(f"watchdog_period must be positive, got {period!r}")
        with self._lock:
            self._watchdog_period = period
            self._watchdog_due = None if period is None else self.clock.now()

    def service(self) -> bool:
        """Send a watchdog refresh if one is due; True if one was sent."""
        with self._lock:
            self._check_open()
            return self._service_watchdog(self.clock.now())

    def idle(self, seconds: float) -> None:
        """Let ``seconds`` pass while reading the bus (stale acks are consumed, other frames
        discarded) and keeping the watchdog refreshed."""
        with self._lock:
            self._check_open()
            until = self.clock.now() + seconds
            while (got := self._next_ack(until)) is not None:
                self._unsolicited(*got)

    # ------------------------------------------------------------------ core exchange
    def transact(self, requests: Sequence[Request], timeout: float | None = None, *,
                 on_ack: AckInspector | None = None) -> list[Ack | None]:
        """Send all ``requests``, then collect their acknowledges (pipelined).

        :param timeout: per-request response timeout; default :attr:`response_timeout`.
        :param on_ack: called as ``on_ack(request, ack)`` the moment each acknowledge is
            matched; an exception it raises ends the exchange at once (the requests still
            unanswered are tainted) and propagates, so a caller can act on the first bad
            acknowledge without waiting for the rest of the batch.
        :return: one entry per request, in order; None for broadcasts.
        :raises ~seqrun.errors.ModuleTimeoutError: an acknowledge did not come in time
            (names the first such request's module; the others are tainted as well).
        :raises ~seqrun.errors.CodecError: a request cannot be encoded (nothing is sent).
        :raises ~seqrun.errors.BusError: the bus refused a frame or the client is closed.
        """
        return self._exchange(requests, timeout, raise_on_timeout=True, on_ack=on_ack)

    def is_tainted(self, request: Request) -> bool:
        """True while ``request``'s acknowledge key is in quarantine (sending it now would
        first wait for the quarantine to pass)."""
        if not self._taints:  # the common case: nothing in quarantine, no lock needed
            return False
        key = expected_ack_key(request)
        with self._lock:
            taint = self._taints.get(key) if key is not None else None
            return taint is not None and taint.until > self.clock.now()

    def transact_partial(self, requests: Sequence[Request], timeout: float | None = None, *,
                         on_ack: AckInspector | None = None) -> list[Ack | None]:
        """Like :meth:`transact`, but an unanswered request gives None instead of raising
        (its key is tainted all the same). Lets a caller retry only what is safe to retry."""
        return self._exchange(requests, timeout, raise_on_timeout=False, on_ack=on_ack)

    def _exchange(self, requests: Sequence[Request], timeout: float | None, *,
                  raise_on_timeout: bool, on_ack: AckInspector | None = None
                  ) -> list[Ack | None]:
        timeout = self.response_timeout if timeout is None else float(timeout)
        # Encode everything first: a bad request in a batch sends nothing.
        frames = [encode(r) for r in requests]
        keys = [expected_ack_key(r) for r in requests]
        results: list[Ack | None] = [None] * len(requests)
        with self._lock:
            self.last_ack_times = [None] * len(requests)
            self._check_open()
            if self._taints:  # (nothing in quarantine, the usual case: nothing to wait for)
                self._drain_tainted({k for k in keys if k is not None})
            self._flush_queued()
            self._service_watchdog(self.clock.now())
            pending: dict[AckKey, deque[int]] = {}
            deadlines: dict[int, float] = {}
            held = deque(range(len(frames)))
            window = self.MAX_IN_FLIGHT if on_ack is not None else len(frames)
            busy: dict[int, int] = {}  # module -> index of its unanswered request
            try:
                while True:
                    self._send_ready(held, busy, requests, frames, keys, pending, deadlines,
                                     timeout, window)
                    if not held:
                        self._collect(pending, deadlines, results, raise_on_timeout,
                                      requests, on_ack, busy)
                        break
                    # A request waits for its module's previous answer: collect until
                    # some module is free again (or its request timed out).
                    if self._collect(pending, deadlines, results, raise_on_timeout,
                                     requests, on_ack, busy, stop_after_one=True):
                        continue
                    if raise_on_timeout:
                        break  # the timeout is raised below; the held requests stay unsent
                    self._expire_overdue(held, busy, requests, pending, deadlines, timeout)
            except BaseException:
                # Whatever broke the exchange (a send error, a watchdog refresh that could
                # not be sent, KeyboardInterrupt), unanswered requests may still be answered.
                self._taint_all(pending, timeout)
                raise
            if deadlines:
                self._taint_all(pending, timeout)
                if raise_on_timeout:  # a silent id in a scan is not a timeout
                    self.stats.timeouts += len(deadlines)
                    raise self._timeout_error(requests, sorted(deadlines), timeout)
        return results

    def _send_ready(self, held: deque[int], busy: dict[int, int],
                    requests: Sequence[Request], frames: list[tuple[int, bytes]],
                    keys: list[AckKey | None], pending: dict[AckKey, deque[int]],
                    deadlines: dict[int, float], timeout: float, window: int) -> None:
        """Send every held request whose module has no unanswered request (one request in
        flight per module, as every published PowerCube driver does; a module may drop a
        request that arrives before it has answered the previous one). Requests to one
        module keep their order; a broadcast waits until everything before it is sent, and
        everything after it waits for the broadcast."""
        if not self.ONE_REQUEST_PER_MODULE:
            busy = {}
        blocked: set[int | None] = set(busy)
        barrier = False
        still: deque[int] = deque()
        in_flight = len(deadlines)
        for position, index in enumerate(held):
            if in_flight >= window:
                # Nothing more goes out now: the rest stays held, in order.
                still.extend(itertools.islice(held, position, None))
                break
            module = getattr(requests[index], "module", None)  # None: a broadcast
            if barrier or (module in blocked and self.ONE_REQUEST_PER_MODULE) or (
                    module is None and still):
                still.append(index)
                if module is None:
                    barrier = True
                else:
                    blocked.add(module)
                continue
            self._send(*frames[index])
            key = keys[index]
            if key is not None:
                pending.setdefault(key, deque()).append(index)
                deadlines[index] = self.clock.now() + timeout
                busy[module] = index  # type: ignore[index]
                blocked.add(module)
                in_flight += 1
        held.clear()
        held.extend(still)

    def _expire_overdue(self, held: deque[int], busy: dict[int, int],
                        requests: Sequence[Request], pending: dict[AckKey, deque[int]],
                        deadlines: dict[int, float], timeout: float) -> None:
        """Give up on the requests whose deadline has passed (tainted as usual) and on the
        held requests to the same modules: a module that did not answer one request of
        the batch is not asked again in it (a lost read costs one timeout, not several)."""
        now = self.clock.now()
        silent = set()
        for index in [i for i, d in deadlines.items() if d <= now]:
            del deadlines[index]
            module = requests[index].module  # type: ignore[union-attr]
            silent.add(module)
            busy.pop(module, None)
            key = expected_ack_key(requests[index])
            queue = pending[key]  # type: ignore[index]
            queue.remove(index)
            if not queue:
                del pending[key]  # type: ignore[arg-type]
            self._taint_all({key: deque([index])}, timeout)  # type: ignore[dict-item]
        kept = [i for i in held if getattr(requests[i], "module", None) not in silent]
        held.clear()
        held.extend(kept)

    def _collect(self, pending: dict[AckKey, deque[int]], deadlines: dict[int, float],
                 results: list[Ack | None], raise_on_timeout: bool,
                 requests: Sequence[Request] | None = None,
                 on_ack: AckInspector | None = None, busy: dict[int, int] | None = None,
                 *, stop_after_one: bool = False) -> bool:
        """Match acks to ``pending`` until all are answered or the deadline has come;
        answered requests leave ``pending``, ``deadlines`` and ``busy``. With
        ``stop_after_one``, return after the first match (True) or at the first deadline
        (False)."""
        while deadlines:
            # Stop at the first deadline when a timeout is an error; otherwise give every
            # request its full time (scan).
            if stop_after_one or raise_on_timeout:
                stop = min(deadlines.values())
            else:
                stop = max(deadlines.values())
            got = self._next_ack(stop)
            if got is None:
                return False
            msg, ack = got
            key = ack_key(ack)
            queue = pending.get(key)
            if not queue:
                self._unsolicited(msg, ack)
                continue
            index = queue.popleft()
            if not queue:
                del pending[key]
            del deadlines[index]
            results[index] = ack
            self.last_ack_times[index] = self.last_rx_at
            self.stats.acks_matched += 1
            if busy is not None:
                busy.pop(ack.module, None)
            if on_ack is not None:
                on_ack(requests[index], ack)  # type: ignore[index]
            if stop_after_one:
                return True
        return True

    def _timeout_error(self, requests: Sequence[Request], missing: list[int],
                       timeout: float) -> ModuleTimeoutError:
        first = requests[missing[0]]
        what = _describe(first)
        others = sorted({requests[i].module for i in missing[1:]}  # type: ignore[union-attr]
                        - {first.module})  # type: ignore[union-attr]
        if others:
            what += f" (modules {', '.join(map(str, others))} did not answer either)"
        return ModuleTimeoutError(first.module, what, timeout,  # type: ignore[union-attr]
                                  request=first)

    # ------------------------------------------------------------------ stale-ack rules
    def _taint_all(self, pending: dict[AckKey, deque[int]], timeout: float) -> None:
        # The window scales with the longer of the timeout used and the default one.
        window = self.QUARANTINE_TIMEOUTS * max(timeout, self.response_timeout)
        until = self.clock.now() + window
        for key, queue in pending.items():
            taint = self._taints.get(key)
            if taint is None:
                self._taints[key] = _Taint(len(queue), until)
            else:
                taint.count += len(queue)
                taint.until = max(taint.until, until)

    def _consume_taint(self, key: AckKey) -> bool:
        """True if an ack with ``key`` is the late answer of a timed-out request."""
        taint = self._taints.get(key)
        if taint is None:
            return False
        if taint.until <= self.clock.now():
            del self._taints[key]
            return False
        taint.count -= 1
        if taint.count <= 0:
            del self._taints[key]
        return True

    def _drain_tainted(self, keys: set[AckKey]) -> None:
        """Read the bus until none of ``keys`` is tainted any more (rule 3)."""
        while True:
            now = self.clock.now()
            untils = []
            for key in keys:
                taint = self._taints.get(key)
                if taint is None:
                    continue
                if taint.until <= now:
                    del self._taints[key]
                else:
                    untils.append(taint.until)
            if not untils:
                return
            got = self._next_ack(min(untils))
            if got is not None:
                self._unsolicited(*got)

    def _flush_queued(self) -> None:
        """Discard what arrived before the next request is sent (rule 1)."""
        for _ in range(self.MAX_FLUSH_FRAMES):
            msg = self._recv_now()
            if msg is None:
                return
            ack = self._decode(msg)
            if ack is None:
                continue
            if self._consume_taint(ack_key(ack)):
                self._discard(msg, DiscardReason.STALE)
            else:
                self._discard(msg, DiscardReason.BEFORE_REQUEST)

    def _unsolicited(self, msg: can.Message, ack: Ack) -> None:
        if self._consume_taint(ack_key(ack)):
            self._discard(msg, DiscardReason.STALE)
        else:
            self._discard(msg, DiscardReason.UNEXPECTED)

    # ------------------------------------------------------------------ bus I/O
    def _check_open(self) -> None:
        if self._closed:
            raise BusError("PowerCube client is closed")

    def _send(self, can_id: int, data: bytes) -> None:
        msg = self._message(arbitration_id=can_id, data=data, is_extended_id=False,
                            is_rx=False, timestamp=self.clock.now())
        try:
            self.bus.send(msg, timeout=self.SEND_TIMEOUT)
        except Exception as exc:
            # Not only can.CanError: a lost connection (socketcand server gone) raises
            # BrokenPipeError/OSError from python-can, and every such failure is a bus fault.
            raise BusError(f"sending 0x{can_id:03X} [{data.hex(' ').upper()}] failed: "
                           f"{_what(exc)}") from exc
        self.stats.frames_sent += 1
        if can_id == BROADCAST_ID and data[:1] == b"\x07" and self._watchdog_period:
            self._watchdog_due = msg.timestamp + self._watchdog_period
        self._notify(msg)

    def _service_watchdog(self, now: float) -> bool:
        if self._watchdog_due is None or now < self._watchdog_due:
            return False
        self._send(*_WATCHDOG_FRAME)
        self.stats.watchdog_refreshes += 1
        return True

    def _next_ack(self, until: float) -> tuple[can.Message, Ack] | None:
        """Read until the next decodable acknowledge, or None once ``until`` has come.
        Refreshes the watchdog on the way.

        At the deadline, what has already arrived is still read (without waiting): after a
        host stall the acknowledges are queued although the deadline has passed, and they
        were on the wire in time."""
        late_reads = 0
        while True:
            now = self.clock.now()
            if now >= until:
                if late_reads >= self.MAX_FLUSH_FRAMES:
                    return None  # a flood of other frames: give up as before
                late_reads += 1
                msg = self._recv_now()
                if msg is None:
                    return None
                ack = self._decode(msg)
                if ack is not None:
                    return msg, ack
                continue
            due = self._watchdog_due
            if due is None:
                wake = until
            elif now >= due:
                self._service_watchdog(now)
                continue
            else:
                wake = min(until, due)
            msg = self._recv(wake)
            if msg is None:
                continue
            ack = self._decode(msg)
            if ack is not None:
                return msg, ack

    def _bus_recv(self, timeout: float) -> can.Message | None:
        """The next frame within ``timeout`` (None: none came), stamped with the clock's
        now, counted and shown to the frame listeners; :attr:`last_rx_at` is when it was
        on the wire (from the interface's own time stamp)."""
        try:
            msg = self.bus.recv(timeout=timeout)
        except Exception as exc:  # a lost connection is a bus fault, whatever raised it
            raise BusError(f"receiving from the bus failed: {_what(exc)}") from exc
        if msg is not None:
            now = self.clock.now()
            self.last_rx_at = self._wire_time.place(msg.timestamp, now)
            msg.is_rx = True
            msg.timestamp = now
            self.stats.frames_received += 1
            self._notify(msg)
        return msg

    def _recv(self, wake: float) -> can.Message | None:
        clock = self.clock
        timeout = wake - clock.now()
        msg = self._bus_recv(timeout if timeout > 0.0 else 0.0)
        if msg is None:
            # A bus that does not know our virtual clock returns without advancing it.
            if clock.is_virtual and clock.now() < wake:
                clock.sleep_until(wake)
        return msg

    def _recv_now(self) -> can.Message | None:
        return self._bus_recv(0.0)

    def _decode(self, msg: can.Message) -> Ack | None:
        can_id = msg.arbitration_id
        if (msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame
                or not ACK_BASE <= can_id < ACK_BASE + 0x20):
            self._discard(msg, DiscardReason.NOT_AN_ACK)
            return None
        try:
            return decode_ack(can_id, bytes(msg.data))
        except CodecError as exc:
            self._discard(msg, f"{DiscardReason.MALFORMED}: {exc}")
            return None

    def _discard(self, msg: can.Message, reason: str) -> None:
        key = DiscardReason.MALFORMED if reason.startswith(DiscardReason.MALFORMED) else reason
        self.stats.discarded[key] += 1
        logger.debug("discarded 0x%03X [%s]: %s", msg.arbitration_id,
                     bytes(msg.data).hex(" ").upper(), reason)
        if self.on_discard is not None:
            try:
                self.on_discard(msg, reason)
            except Exception:  # a broken logger must not break the bus exchange
                logger.exception("on_discard callback failed")

    def _notify(self, msg: can.Message) -> None:
        for listener in self._listeners:
            try:
                listener(msg)
            except Exception:  # a broken trace writer must not break the bus exchange
                logger.exception("frame listener %r failed", listener)

    # ------------------------------------------------------------------ commands
    def _command(self, command: CommandId, module: int | None) -> None:
        if module is None:
            self.transact([BroadcastRequest(command, 0)])  # m5api's [cmd, 0x00]
        else:
            self.transact([CommandRequest(module, command)])

    def reset(self, module: int | None = None) -> None:
        """Reset (clear errors) one module, or all with a broadcast when ``module`` is None."""
        self._command(CommandId.RESET, module)

    def home(self, module: int | None = None) -> None:
        """Start homing one module, or all (broadcast)."""
        self._command(CommandId.HOME, module)

    def halt(self, module: int | None = None) -> None:
        """Emergency-stop one module, or all (broadcast, not acknowledged)."""
        self._command(CommandId.HALT, module)

    def halt_now(self, *, wait: bool = True) -> None:
        """Broadcast Halt ``[0x02, 0x00]`` at once: unlike :meth:`halt`, nothing queued on
        the bus is read first (a flooded receive queue must not delay an emergency stop),
        and no quarantine is waited for. Confirm it with
        :func:`seqrun.drivers.powercube.confirm_command`.

        ``wait=False`` (an operator's STOP from another thread): when another thread's
        exchange holds the client, the frame is sent without waiting for it (python-can
        buses accept sends from two threads); the exchange goes on, the modules halt.

        :raises ~seqrun.errors.BusError: the frame could not be sent.
        """
        locked = self._lock.acquire(blocking=wait)
        try:
            self._check_open()
            self._send(*_HALT_FRAME)
        finally:
            if locked:
                self._lock.release()

    def refresh_watchdog(self) -> None:
        """Broadcast a watchdog refresh ``[0x07, 0x00]`` now."""
        self.transact([BroadcastRequest(CommandId.WATCHDOG_REFRESH, 0)])
        with self._lock:
            self.stats.watchdog_refreshes += 1

    def sync_start(self) -> None:
        """Broadcast StartMove ``[0x0F, 0x00]``: modules in sync mode start their motion."""
        self.transact([BroadcastRequest(CommandId.START_MOVE, 0)])

    def save_pos_all(self) -> None:
        """Broadcast SavePosAll ``[0x0E, 0x00]``."""
        self.transact([BroadcastRequest(CommandId.SAVE_POS_ALL, 0)])

    def set_baud_all(self, baud: BaudRate | int) -> None:
        """Broadcast SetBaudAll; the adapter must be reopened at the new rate afterwards."""
        self.transact([BroadcastRequest(CommandId.SET_BAUD_ALL, int(baud))])

    # ------------------------------------------------------------------ parameters
    def get_param(self, module: int, param: ParamId) -> float | int | PosStateDio:
        """Read a parameter; the value has the parameter's wire type."""
        (ack,) = self.transact([GetParam(module, param)])
        return ack.value  # type: ignore[union-attr]

    def set_param(self, module: int, param: ParamId, value: float | int) -> None:
        """Write a parameter, converting ``value`` to its wire type (float32 or an integer,
        range-checked)."""
        wire = PARAM_TYPES.get(param)
        if wire is not None and wire.is_float and isinstance(value, int):
            value = float(value)
        self.transact([SetParam(module, param, value)])

    def read_state(self, module: int) -> StateFlag:
        return StateFlag(self.get_param(module, ParamId.CUBE_STATE))  # type: ignore[arg-type]

    def read_config(self, module: int) -> ConfigFlag:
        return ConfigFlag(self.get_param(module, ParamId.CONFIG))  # type: ignore[arg-type]

    def read_position(self, module: int) -> float:
        """Actual position in rad (module coordinates)."""
        return self.get_param(module, ParamId.ACT_POS)  # type: ignore[return-value]

    def read_velocity(self, module: int) -> float:
        """Actual velocity in rad/s."""
        return self.get_param(module, ParamId.ACT_VEL)  # type: ignore[return-value]

    def read_pos_state_dio(self, module: int) -> ModuleReading:
        return self.read_arm([module])[0]

    def read_arm(self, modules: Iterable[int]) -> list[ModuleReading]:
        """Position, short state and dio of every module in one pipelined exchange."""
        modules = list(modules)
        acks = self.transact([GetParam(m, ParamId.FPOS_STATE_DIO) for m in modules])
        readings = []
        for module, ack in zip(modules, acks):
            value: PosStateDio = ack.value  # type: ignore[union-attr]
            readings.append(ModuleReading(module, value.position, value.state, value.dio))
        return readings

    def check_ok(self, module: int) -> StateFlag:
        """Read the state word; raise :class:`~seqrun.errors.ModuleFaultError` on a fault."""
        state = self.read_state(module)
        self.raise_for_state(module, state)
        return state

    @staticmethod
    def raise_for_state(module: int, state: StateFlag | ShortState, detail: str = "") -> None:
        """Raise :class:`~seqrun.errors.ModuleFaultError` if ``state`` has a fault bit
        (:attr:`StateFlag.FAULTS`) or, for a short state, NOT_OK."""
        if isinstance(state, ShortState):
            if state & ShortState.NOT_OK:
                raise ModuleFaultError(module, state, detail)
            return
        if StateFlag(state) & StateFlag.FAULTS:
            raise ModuleFaultError(module, StateFlag(state), detail)

    # ------------------------------------------------------------------ motion
    def move_ramp(self, module: int, position: float, velocity: float,
                  acceleration: float | None = None, ext_ack: bool = False
                  ) -> MotionAck | MotionExtAck:
        """Ramp to ``position`` (rad) with at most ``velocity`` (rad/s) and ``acceleration``
        (rad/s², None keeps the module's TargetAcc), like m5api ``moveRamp``, but the
        parameter writes and the motion are sent in one pipelined exchange."""
        requests: list[Request] = [SetParam(module, ParamId.TARGET_VEL, float(velocity))]
        if acceleration is not None:
            requests.append(SetParam(module, ParamId.TARGET_ACC, float(acceleration)))
        mode = MotionMode.FRAMP_ACK if ext_ack else MotionMode.FRAMP
        requests.append(SetMotion(module, mode, float(position)))
        return self.transact(requests)[-1]  # type: ignore[return-value]

    def move_step(self, module: int, position: float, ms: int, ext_ack: bool = False
                  ) -> MotionAck | MotionExtAck:
        """Step mode: reach ``position`` (rad) in ``ms`` milliseconds (0..65535)."""
        mode = MotionMode.FSTEP_ACK if ext_ack else MotionMode.FSTEP
        (ack,) = self.transact([SetMotion(module, mode, float(position), ms)])
        return ack  # type: ignore[return-value]

    def move_velocity(self, module: int, velocity: float, ext_ack: bool = False
                      ) -> MotionAck | MotionExtAck:
        """Velocity mode at ``velocity`` rad/s."""
        mode = MotionMode.FVEL_ACK if ext_ack else MotionMode.FVEL
        (ack,) = self.transact([SetMotion(module, mode, float(velocity))])
        return ack  # type: ignore[return-value]

    # ------------------------------------------------------------------ discovery
    def scan(self, ids: Iterable[int] = MODULE_IDS, timeout: float | None = None
             ) -> dict[int, int]:
        """Ping ``ids`` with GetExtended DefCubeVersion (pipelined).

        :return: ``{module: firmware version}`` of the modules that answered; absent
            modules are simply missing (their keys are tainted like any timeout).
        """
        ids = list(ids)
        acks = self._exchange([GetParam(m, ParamId.DEF_CUBE_VERSION) for m in ids], timeout,
                              raise_on_timeout=False)
        return {m: ack.value for m, ack in zip(ids, acks)  # type: ignore[union-attr]
                if ack is not None}


_WATCHDOG_FRAME = encode(BroadcastRequest(CommandId.WATCHDOG_REFRESH, 0))
_HALT_FRAME = encode(BroadcastRequest(CommandId.HALT, 0))


def _message_class(bus: Any) -> Any:
    """The message type ``bus`` takes: its ``message_class`` (the simulator's python-can-free
    :class:`~seqrun.sim.port.SimPort`), else python-can's :class:`can.Message` (imported
    only then: it costs more than a dry run)."""
    message_class = getattr(bus, "message_class", None)
    if message_class is None:
        import can

        message_class = can.Message
    return message_class


def _what(exc: BaseException) -> str:
    """One line naming the exception (python-can's socketcand client puts a whole
    traceback into its CanError message: only the part before it is kept)."""
    text = str(exc).split("Traceback (most recent call last)")[0].strip()
    text = text.splitlines()[0].strip() if text else ""
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _describe(request: Request) -> str:
    if isinstance(request, GetParam):
        return f"GetExtended {ParamId(request.param).name}"
    if isinstance(request, SetParam):
        return f"SetExtended {ParamId(request.param).name} = {request.value!r}"
    if isinstance(request, SetMotion):
        text = f"SetMotion {MotionMode(request.mode).name} {request.value!r}"
        return text + (f" in {request.time_ms} ms" if request.time_ms is not None else "")
    if isinstance(request, CommandRequest):
        return f"command {CommandId(request.command).name}"
    return repr(request)
