"""SimNetwork: the shared CAN wire between host endpoints and the simulated arm.

Every frame occupies the bus for its exact wire time (:mod:`seqrun.powercube.can_timing`: stuff
bits, CRC, EOF and intermission at the configured bitrate); frames go out one at a time.
When the bus becomes free, the frames that are ready compete and the lowest identifier
wins, as in CAN arbitration (standard before extended with the same base id); each node
sends its own frames in order (a FIFO transmit queue). So the modules' acks (0x0A0+m)
overtake requests still waiting in the host's queue, exactly as on the real bus.

A frame is *delivered* at the end of its end-of-frame field (before the intermission):
every other endpoint (and, with ``receive_own``, the sender) gets it with that
``timestamp``, and the arm receives it at that instant; the arm's acknowledges become
ready ``module_latency`` later and join the competition for the wire.

Time is a :class:`~seqrun.clock.Clock`. Nothing runs by itself: the wire is simulated up
to "now" whenever an endpoint sends or receives. With a virtual clock, waiting for a frame
*advances* the clock to the next event instead of sleeping. Thread-safe: one condition
variable guards everything, so endpoints in several threads (the socketcand server) share
one wire in real time.

Not simulated: error frames, ACK errors (a frame always finds a receiver), bus-off,
retransmission, bit errors, CAN FD.
"""

from __future__ import annotations

import functools
import itertools
import math
import threading
import time
from collections import deque
from typing import NamedTuple

from seqrun.powercube.can_timing import INTERMISSION_BITS, frame_bit_length
from seqrun.clock import Clock
from seqrun.errors import BusError
from seqrun.powercube.protocol import ACK_BASE
from seqrun.sim.arm import SimArm

#: Frames a host endpoint may have waiting for the wire before ``send`` waits [I].
DEFAULT_TX_QUEUE_SIZE = 256
#: See :attr:`SimNetwork.spin_window`.
DEFAULT_SPIN_WINDOW = 0.0005


class NetworkClosedError(BusError):
    """The endpoint (or its network) was closed."""


class TransmitTimeoutError(BusError):
    """``send`` found the transmit queue full until its timeout ran out."""


class WireFrame(NamedTuple):
    """A classic CAN frame on the simulated wire; ``timestamp`` is the delivery time.

    Immutable. A named tuple rather than a frozen dataclass: the wire makes two per frame,
    and a frozen dataclass' ``__init__`` costs several times a tuple's (the network
    builds them with ``tuple.__new__``, without even the named tuple's ``__new__``)."""

    can_id: int
    data: bytes = b""
    is_extended: bool = False
    is_remote: bool = False
    #: Length code of a remote frame (data frames: ``len(data)``).
    dlc: int | None = None
    timestamp: float = 0.0
    #: Name of the transmitting endpoint or ``"moduleN"``; set by the network.
    sender: str = ""

    @property
    def length(self) -> int:
        return self.dlc if self.is_remote and self.dlc is not None else len(self.data)


@functools.lru_cache(maxsize=4096)
def _bit_length(can_id: int, data: bytes, extended: bool, remote: bool,
                dlc: int | None) -> int:
    # Cached: computing stuffing and CRC bit by bit is slow in Python, and a bus mostly
    # carries the same requests and acks over and over.
    return frame_bit_length(can_id, data, extended=extended, remote=remote, dlc=dlc)


def _arbitration_key(frame: WireFrame) -> int:
    """Orders frames as bitwise arbitration does (dominant 0 wins): the fields of the
    arbitration field in wire order — base id (11 bits), RTR resp. SRR, IDE, extension
    (18 bits), RTR of an extended frame — packed into one integer, so that comparing keys
    compares those fields one after the other."""
    if frame.is_extended:
        base, extension = frame.can_id >> 18, frame.can_id & 0x3FFFF
        # SRR and IDE recessive
        return base << 21 | 1 << 20 | 1 << 19 | extension << 1 | int(frame.is_remote)
    return frame.can_id << 21 | int(frame.is_remote) << 20


#: Frame durations a network keeps (see SimNetwork.frame_durations).
_DURATIONS_KEPT = 4096

#: ``_Pending.rank`` = arbitration key << _SEQ_BITS | sequence number: frames with equal
#: keys (one node's, or two nodes sending the same identifier) go in queueing order.
_SEQ_BITS = 64


#: ``tuple.__new__``: builds the named tuples below without their Python-level ``__new__``.
_new_tuple = tuple.__new__


class _Pending(NamedTuple):
    """A frame waiting in its node's transmit queue."""

    frame: WireFrame
    ready_at: float
    rank: int
    #: Bus time until delivery (end of EOF) and until the bus is free again.
    to_delivery: float
    occupancy: float


class _Node:
    """A transmitter: a host endpoint or one module."""

    __slots__ = ("is_module", "name", "queue")

    def __init__(self, name: str, is_module: bool = False) -> None:
        self.name = name
        self.is_module = is_module
        self.queue: deque[_Pending] = deque()


class _InFlight(NamedTuple):
    node: _Node
    pending: _Pending
    start: float
    end: float  # delivery time


class Endpoint:
    """One host connection to the wire (a :class:`~seqrun.sim.bus.SimBus`, a socketcand
    client). Receives every frame other endpoints send and every module reply."""

    def __init__(self, network: SimNetwork, name: str, receive_own: bool,
                 tx_queue_size: int) -> None:
        self.network = network
        self.name = name
        self.receive_own = receive_own
        self.tx_queue_size = tx_queue_size
        self._node = _Node(name)
        self._inbox: deque[WireFrame] = deque()
        self.closed = False

    def __repr__(self) -> str:
        return f"<Endpoint {self.name} on {self.network!r}>"

    def send(self, frame: WireFrame, timeout: float | None = None) -> None:
        """Queue ``frame`` for the wire at the clock's now. Waits (on the clock) only while
        ``tx_queue_size`` frames of this endpoint are still waiting; never forever, since
        the simulated wire always drains.

        :raises ValueError: the frame cannot exist on a classic CAN bus.
        :raises TransmitTimeoutError: the queue stayed full for ``timeout`` seconds.
        """
        self.network._send(self, frame, timeout)

    def receive(self, deadline: float | None) -> WireFrame | None:
        """The next frame delivered to this endpoint, waiting until ``deadline`` (clock
        time; None = no limit). A virtual clock is advanced to the delivery time (or to the
        deadline when nothing comes)."""
        return self.network._receive(self, deadline)

    def pending(self) -> int:
        """Frames received and not yet taken."""
        with self.network._lock:
            return len(self._inbox)

    def close(self) -> None:
        """Detach from the wire: nothing more is received or accepted, but the frames
        already accepted still go out, in order (a closing client's last Halt must reach
        the modules). Safe to call twice."""
        self.network._detach(self)


class SimNetwork:
    """The wire: host endpoints (:meth:`attach`) plus the modules of ``arm``.

    :param bitrate: bit/s; sets every frame's duration.
    :param spin_window: see the attribute of that name.
    """

    def __init__(self, clock: Clock, arm: SimArm, bitrate: int = 1_000_000, *,
                 spin_window: float = DEFAULT_SPIN_WINDOW) -> None:
        if bitrate <= 0:
            raise ValueError(f"bitrate must be positive, got {bitrate}")
        self.clock = clock
        #: Real time only: the last ``spin_window`` seconds before a wire event a receiver
        #: busy-waits (yielding the GIL) instead of sleeping, because a sleeping thread can
        #: wake as late as a whole request frame lasts. 0 never spins.
        self.spin_window = spin_window
        self.arm = arm
        self.bitrate = int(bitrate)
        # ``with self._lock`` is ``with self._cond`` without Condition's Python-level
        # __enter__/__exit__ (the lock is entered several times per frame).
        self._lock = threading.RLock()
        self._cond = threading.Condition(self._lock)
        self._endpoints: list[Endpoint] = []
        self._module_nodes: dict[int, _Node] = {}
        self._nodes: list[_Node] = []
        #: The nodes whose queue is not empty (any order: the competition picks by rank).
        self._active: list[_Node] = []
        self._seq = itertools.count()
        self._names = itertools.count(1)
        self._in_flight: _InFlight | None = None
        self._bus_free_at = clock.now()
        #: (seconds until delivery, seconds of bus occupancy) by the frame's first five
        #: fields (id, data, extended, remote, dlc): most frames repeat (see _bit_length).
        self._durations: dict[tuple, tuple[float, float]] = {}
        #: Statistics: frames that went over the wire and the bus time they used (with
        #: intermission).
        self.frames_transmitted = 0
        self.busy_time = 0.0

    def __repr__(self) -> str:
        return f"<SimNetwork {self.bitrate} bit/s, {len(self._endpoints)} endpoints>"

    # -- endpoints --------------------------------------------------------------------------

    def attach(self, *, receive_own: bool = False, name: str | None = None,
               tx_queue_size: int = DEFAULT_TX_QUEUE_SIZE) -> Endpoint:
        """A new host connection to the wire."""
        if tx_queue_size < 1:
            raise ValueError(f"tx_queue_size must be >= 1, got {tx_queue_size}")
        with self._lock:
            endpoint = Endpoint(self, name or f"host{next(self._names)}", receive_own,
                                tx_queue_size)
            self._endpoints.append(endpoint)
            self._nodes.append(endpoint._node)
            return endpoint

    @property
    def endpoint_count(self) -> int:
        with self._lock:
            return len(self._endpoints)

    def _detach(self, endpoint: Endpoint) -> None:
        with self._lock:
            if endpoint.closed:
                return
            endpoint.closed = True
            self._endpoints.remove(endpoint)
            self._nodes.remove(endpoint._node)
            # Its queue stays in the competition for the wire: every frame accepted is
            # delivered (at the time it would have been, whoever advances the wire next).
            endpoint._inbox.clear()
            self._cond.notify_all()

    # -- timing -------------------------------------------------------------------------------

    def frame_durations(self, frame: WireFrame) -> tuple[float, float]:
        """(seconds until delivery, seconds the bus is occupied) for ``frame``.

        :raises ValueError: a frame classic CAN cannot carry.
        """
        key = frame[:5]
        durations = self._durations.get(key)
        if durations is None:
            bits = _bit_length(frame.can_id, frame.data, frame.is_extended, frame.is_remote,
                               frame.dlc if frame.is_remote else None)
            durations = (bits - INTERMISSION_BITS) / self.bitrate, bits / self.bitrate
            if len(self._durations) >= _DURATIONS_KEPT:
                self._durations.clear()  # bounded: positions make the data of a long run vary
            self._durations[key] = durations
        return durations

    def run_until(self, t: float | None = None) -> None:
        """Simulate the wire up to ``t`` (default now); for tests and tools."""
        with self._lock:
            self._advance(self.clock.now() if t is None else t)

    def _advance(self, horizon: float, *, start_at_horizon: bool = True) -> None:
        """Process every event up to ``horizon``; lock held.

        ``start_at_horizon=False`` leaves a frame that would start exactly at ``horizon``
        waiting, so that frames other nodes queue at that same instant still compete with
        it in arbitration (``send`` uses this).
        """
        flight = self._in_flight
        if flight is not None and flight.end > horizon:
            return  # the frame on the wire is the next event, and it lies ahead
        if flight is None and not (self._active and self._bus_free_at <= horizon):
            # the wire is idle and nothing can start by then: nothing queued, or the
            # intermission after the last frame lasts (the usual case right after a send)
            return
        delivered = False
        while True:
            if flight is None:
                flight = self._start_next(horizon, start_at_horizon)
                if flight is None:
                    break
            if flight.end > horizon:
                break
            self._in_flight = None
            self._deliver(flight)
            delivered = True
            flight = None
        if delivered:
            self._notify_all()

    def _run_until_received(self, inbox: deque[WireFrame], horizon: float) -> float | None:
        """Virtual time: :meth:`_advance` towards ``horizon``, but stop at the delivery that
        puts a frame into ``inbox``. Returns the time of the last event processed (None:
        none), where a clock stepping from event to event would stand. Lock held.

        Same events in the same order as stepping the clock to every event and advancing
        to it: a delivery is never followed by another event at the same instant (the
        intermission keeps the bus busy), and the simulation reads no clock.
        """
        last = None
        flight = self._in_flight
        delivered = False
        while True:
            if flight is None:
                flight = self._start_next(horizon, True)
                if flight is None:
                    break
                last = flight.start
            if flight.end > horizon:
                break
            self._in_flight = None
            self._deliver(flight)
            delivered = True
            last = flight.end
            flight = None
            if inbox:
                break
        if delivered:
            self._notify_all()
        return last

    def _start_next(self, horizon: float, start_at_horizon: bool) -> _InFlight | None:
        """Put the next frame on the idle wire if it starts by ``horizon``; lock held."""
        active = self._active
        if not active:
            return None
        # The bus is free from _bus_free_at; the frames ready by then (or, if none is,
        # those ready first) compete and the lowest rank wins.
        if len(active) == 1:
            node = active[0]
            pending = node.queue[0]
            start = max(pending.ready_at, self._bus_free_at)
        else:
            start = max(min([n.queue[0].ready_at for n in active]), self._bus_free_at)
            pending = None
            for n in active:
                head = n.queue[0]
                if head.ready_at <= start and (pending is None or head.rank < pending.rank):
                    node, pending = n, head
        assert pending is not None  # start >= the earliest ready_at: a head qualifies
        if start > horizon or (start == horizon and not start_at_horizon):
            return None
        queue = node.queue
        queue.popleft()
        if not queue:
            active.remove(node)
        flight = self._in_flight = _new_tuple(
            _InFlight, (node, pending, start, start + pending.to_delivery))
        self._bus_free_at = start + pending.occupancy
        self.frames_transmitted += 1
        self.busy_time += pending.occupancy
        return flight

    def _next_event_time(self) -> float | None:
        if self._in_flight is not None:
            return self._in_flight.end
        active = self._active
        if not active:
            return None
        ready = min([node.queue[0].ready_at for node in active])
        return max(ready, self._bus_free_at)

    def _deliver(self, flight: _InFlight) -> None:
        sender, pending, _, end = flight
        can_id, data, is_extended, is_remote, dlc, _, name = pending.frame
        frame = _new_tuple(WireFrame, (can_id, data, is_extended, is_remote, dlc, end, name))
        for endpoint in self._endpoints:
            if endpoint._node is not sender or endpoint.receive_own:
                endpoint._inbox.append(frame)
        if sender.is_module:
            self.arm.ack_sent(can_id - ACK_BASE)  # that module is free again
            return  # the modules ignore each other's acks
        if is_extended or is_remote:
            return  # the modules speak 11-bit data frames
        for reply in self.arm.handle_frame(can_id, data, end):
            module, ack_id, ack_data, ready_at = reply
            node = self._module_nodes.get(module)
            if node is None:
                node = _Node(f"module{module}", is_module=True)
                self._module_nodes[module] = node
                self._nodes.append(node)
            ack = _new_tuple(WireFrame, (ack_id, ack_data, False, False, None, 0.0, node.name))
            self._queue(node, ack, ready_at)

    def _queue(self, node: _Node, frame: WireFrame, ready_at: float,
               durations: tuple[float, float] | None = None) -> None:
        if durations is None:
            durations = self.frame_durations(frame)
        queue = node.queue
        if not queue:
            self._active.append(node)
        key = _arbitration_key(frame) << _SEQ_BITS | next(self._seq)
        queue.append(_new_tuple(_Pending, (frame, ready_at, key, *durations)))

    def _notify_all(self) -> None:
        """Wake the threads waiting on the wire; lock held. Skips Condition.notify_all's
        Python-level work when nobody waits (waiters register under the lock we hold)."""
        if self._cond._waiters:  # type: ignore[attr-defined]
            self._cond.notify_all()

    # -- endpoint operations (called through Endpoint) ------------------------------------------

    def _wait(self, deadline: float | None) -> float | None:
        """Let time pass until the next wire event, ``deadline``, or another thread's
        activity, whichever is first. Lock held.

        In real time, returns the time of a wire event less than ``spin_window`` away for
        the caller to spin towards *after releasing the lock* (see :meth:`_spin`).
        """
        now = self.clock.now()
        event = self._next_event_time()
        wake = event
        if deadline is not None:
            wake = deadline if wake is None else min(wake, deadline)
        if self.clock.is_virtual:
            if wake is None:
                self._cond.wait()  # nothing scheduled: only another thread can change that
            else:
                self.clock.sleep_until(wake)
            return None
        if wake is None:
            self._cond.wait()
            return None
        remaining = wake - now
        if self.spin_window > 0 and wake == event:
            if remaining <= self.spin_window:
                return wake
            remaining -= self.spin_window  # wake up early, spin the rest
        self._cond.wait(max(remaining, 0.0))
        return None

    def _spin(self, until: float) -> None:
        """Busy-wait (yielding the GIL) until ``until``; lock not held."""
        while self.clock.now() < until:
            time.sleep(0)

    def _send(self, endpoint: Endpoint, frame: WireFrame, timeout: float | None) -> None:
        durations = self.frame_durations(frame)  # ValueError for a frame CAN cannot carry
        with self._lock:
            if endpoint.closed:
                raise NetworkClosedError(f"{endpoint.name} is closed")
            now = self.clock.now()
            self._advance(now, start_at_horizon=False)
            node = endpoint._node
            if len(node.queue) >= endpoint.tx_queue_size:
                deadline = None if timeout is None else now + timeout
                while len(node.queue) >= endpoint.tx_queue_size:
                    if deadline is not None and self.clock.now() >= deadline:
                        raise TransmitTimeoutError(
                            f"{endpoint.name}: transmit queue full ({endpoint.tx_queue_size} "
                            f"frames) for {timeout} s")
                    if self._wait(deadline) is not None:
                        self._cond.wait(0)  # rare: sleep-wait is precise enough here
                    if endpoint.closed:
                        raise NetworkClosedError(f"{endpoint.name} is closed")
                    self._advance(self.clock.now())
                now = self.clock.now()
            if frame.sender != endpoint.name or type(frame.data) is not bytes:
                # (a queued frame's timestamp is never seen: delivery stamps a new one)
                frame = WireFrame(frame.can_id, bytes(frame.data), frame.is_extended,
                                  frame.is_remote, frame.dlc, 0.0, endpoint.name)
            self._queue(node, frame, now, durations)
            self._notify_all()

    def _receive(self, endpoint: Endpoint, deadline: float | None) -> WireFrame | None:
        clock = self.clock
        inbox = endpoint._inbox
        if clock.is_virtual:
            return self._receive_virtual(endpoint, deadline)
        while True:
            with self._lock:
                while True:
                    if endpoint.closed:
                        raise NetworkClosedError(f"{endpoint.name} is closed")
                    now = clock.now()
                    self._advance(now)
                    if inbox:
                        return inbox.popleft()
                    if deadline is not None and now >= deadline:
                        return None
                    # (waiting releases the lock, as does spinning, below)
                    spin_until = self._wait(deadline)
                    if spin_until is not None:
                        break
            self._spin(spin_until)

    def _receive_virtual(self, endpoint: Endpoint, deadline: float | None
                         ) -> WireFrame | None:
        """:meth:`_receive` on a virtual clock: the wire runs event by event up to the
        frame for ``endpoint`` (or ``deadline``) in one go, and the clock moves to where
        it stops, as if it had been stepped to every event in between."""
        clock = self.clock
        inbox = endpoint._inbox
        horizon = math.inf if deadline is None else deadline
        with self._lock:
            while True:
                if endpoint.closed:
                    raise NetworkClosedError(f"{endpoint.name} is closed")
                now = clock.now()
                self._advance(now)
                if inbox:
                    return inbox.popleft()
                if deadline is not None and now >= deadline:
                    return None
                last = self._run_until_received(inbox, horizon)
                if inbox:
                    assert last is not None  # a frame was delivered: an event was processed
                    clock.sleep_until(last)
                    return inbox.popleft()
                if deadline is not None:
                    clock.sleep_until(deadline)
                    continue  # (returns None: nothing came by the deadline)
                if last is not None:
                    clock.sleep_until(last)
                self._cond.wait()  # nothing scheduled: only another thread can change that
