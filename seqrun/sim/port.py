"""SimPort: one host connection to a simulated channel, without python-can.

:class:`~seqrun.sim.bus.SimBus` (the ``seqrun-sim`` python-can interface) is a SimPort in
python-can's clothes; the dry run talks to a SimPort directly, because importing python-can
(its ``can.io`` pulls in asyncio, ssl and sqlite3) costs more than a whole dry run of a
short sequence. Both join the same channels (:func:`get_network`) and see the same wire,
clock and arm; only the message objects differ: a SimPort takes and returns
:class:`SimMessage`, which has python-can's :class:`can.Message` fields, so the PowerCube
client, its frame listeners and the run log read both alike.

A SimPort offers the part of python-can's bus interface the client uses: ``send(msg,
timeout)``, ``recv(timeout)``, ``shutdown()``, ``channel``; its ``message_class`` tells the
client which messages to build. No filters, no notifier, no CAN FD.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from seqrun.clock import Clock, RealClock
from seqrun.sim.arm import SimArm
from seqrun.sim.faults import Fault, parse_faults
from seqrun.sim.module import ModuleOptions
from seqrun.sim.options import module_options
from seqrun.sim.network import (
    DEFAULT_TX_QUEUE_SIZE,
    Endpoint,
    NetworkClosedError,
    SimNetwork,
    WireFrame,
)

__all__ = ["SimMessage", "SimPort", "SimSetupError", "get_network"]

#: Builds a WireFrame without the named tuple's Python-level ``__new__`` (once per frame).
_new_tuple = tuple.__new__

#: channel name -> [network, number of open ports on it]
_channels: dict[str, list[Any]] = {}
_channels_lock = threading.RLock()


class SimSetupError(ValueError):
    """A port that cannot be opened as asked (SimBus raises it as CanInitializationError)."""


class SimMessage:
    """A classic CAN frame with the fields (names, defaults, types) of python-can's
    :class:`can.Message` that a reader of frames uses; ``data`` is a bytearray."""

    __slots__ = ("arbitration_id", "bitrate_switch", "channel", "data", "dlc",
                 "error_state_indicator", "is_error_frame", "is_extended_id", "is_fd",
                 "is_remote_frame", "is_rx", "timestamp")

    def __init__(self, timestamp: float = 0.0, arbitration_id: int = 0,
                 is_extended_id: bool = True, is_remote_frame: bool = False,
                 is_error_frame: bool = False, channel: str | int | None = None,
                 dlc: int | None = None, data: bytes | bytearray | Sequence[int] | None = None,
                 is_fd: bool = False, is_rx: bool = True) -> None:
        self.timestamp = timestamp
        self.arbitration_id = arbitration_id
        self.is_extended_id = is_extended_id
        self.is_remote_frame = is_remote_frame
        self.is_error_frame = is_error_frame
        self.channel = channel
        self.data = bytearray() if data is None else bytearray(data)
        self.dlc = len(self.data) if dlc is None else dlc
        self.is_fd = is_fd
        self.is_rx = is_rx
        self.bitrate_switch = False
        self.error_state_indicator = False

    def __len__(self) -> int:
        return self.dlc

    def __repr__(self) -> str:
        return (f"SimMessage(timestamp={self.timestamp!r}, arbitration_id={self.arbitration_id:#x}, "
                f"is_extended_id={self.is_extended_id}, dlc={self.dlc}, "
                f"data={bytes(self.data).hex(' ')!r}, is_rx={self.is_rx})")


def get_network(channel: str = "arm0") -> SimNetwork:
    """The wire (and, as ``.arm``, the simulated arm) of a channel with an open port or bus.

    :raises LookupError: nothing is open on ``channel``.
    """
    with _channels_lock:
        try:
            return _channels[str(channel)][0]
        except KeyError:
            raise LookupError(f"no seqrun-sim bus is open on channel {channel!r}") from None


def open_channels() -> list[str]:
    """The channels that have open ports (and so a running arm)."""
    with _channels_lock:
        return list(_channels)


def _join_channel(channel: str, clock: Clock | None, bitrate: int | None,
                  faults: list[Fault], arm_kwargs: dict[str, Any]) -> SimNetwork:
    with _channels_lock:
        entry = _channels.get(channel)
        if entry is None:
            clock = clock or RealClock()
            arm = SimArm(clock, faults=faults, **{k: v for k, v in arm_kwargs.items()
                                                  if v is not None})
            network = SimNetwork(clock, arm, bitrate or 1_000_000)
            _channels[channel] = [network, 1]
            return network
        network = entry[0]
        if clock is not None and clock is not network.clock:
            raise SimSetupError(
                f"seqrun-sim channel {channel!r} already runs on another clock; "
                "pass the same clock object (or none) to every bus on a channel")
        if bitrate is not None and bitrate != network.bitrate:
            raise SimSetupError(
                f"seqrun-sim channel {channel!r} runs at {network.bitrate} bit/s, "
                f"not {bitrate}: nodes with different bitrates cannot talk")
        given = sorted(k for k, v in arm_kwargs.items() if v is not None)
        if given:
            raise SimSetupError(
                f"seqrun-sim channel {channel!r} already has an arm; {', '.join(given)} "
                "can only be given to the first bus on a channel")
        for fault in faults:
            network.arm.inject(fault)
        entry[1] += 1
        return network


def _leave_channel(channel: str, network: SimNetwork) -> None:
    with _channels_lock:
        entry = _channels.get(channel)
        if entry is None or entry[0] is not network:
            return
        entry[1] -= 1
        if entry[1] <= 0:
            del _channels[channel]


def check_bitrate(bitrate: Any) -> int | None:
    """``bitrate`` as a positive int (None stays None)."""
    if bitrate is None:
        return None
    try:
        value = int(bitrate)
    except (TypeError, ValueError):
        raise SimSetupError(f"bitrate must be an integer, got {bitrate!r}") from None
    if value <= 0:
        raise SimSetupError(f"bitrate must be positive, got {value}")
    return value


class SimPort:
    """A host connection to the simulated LWA 3 on ``channel`` (parameters as
    :class:`~seqrun.sim.bus.SimBus`'s; ``switches``: single module options by name).

    :raises SimSetupError: bad faults, switches or bitrate, or a channel that already
        runs with another clock, bitrate or arm.
    """

    message_class = SimMessage

    def __init__(self, channel: Any = "arm0", *, clock: Clock | None = None,
                 faults: Iterable[Fault | str] | str | None = None,
                 bitrate: int | None = None, receive_own_messages: bool = False,
                 module_latency: float | None = None, seed: int | None = None,
                 options: ModuleOptions | None = None,
                 positions: Mapping[int, float] | Sequence[float] | None = None,
                 modules: Iterable[int] | None = None,
                 power_on_pose: str | None = None,
                 serials: Mapping[int, int] | None = None,
                 tx_queue_size: int = DEFAULT_TX_QUEUE_SIZE, **switches: Any) -> None:
        channel = "arm0" if channel is None else str(channel)
        try:
            fault_list = parse_faults(faults)
            if switches:
                options = module_options(switches, options)
        except (TypeError, ValueError) as exc:
            raise SimSetupError(str(exc)) from None
        arm_kwargs = {"module_latency": module_latency, "seed": seed, "options": options,
                      "positions": positions,
                      "modules": None if modules is None else list(modules),
                      "power_on_pose": power_on_pose, "serials": serials}
        self.network = _join_channel(channel, clock, check_bitrate(bitrate), fault_list,
                                     arm_kwargs)
        #: The simulated arm behind this port (shared by every port on the channel).
        self.arm = self.network.arm
        self.clock = self.network.clock
        self.bitrate = self.network.bitrate
        self.channel = channel
        self.receive_own_messages = receive_own_messages
        self.endpoint: Endpoint = self.network.attach(receive_own=receive_own_messages,
                                                      tx_queue_size=tx_queue_size)
        self._closed = False

    # -- the wire's frames ----------------------------------------------------------------

    def receive_frame(self, deadline: float | None) -> WireFrame | None:
        """The next frame delivered by ``deadline`` (clock time; None: no limit).

        :raises NetworkClosedError: the port is closed.
        """
        return self.endpoint.receive(deadline)

    def is_own(self, frame: WireFrame) -> bool:
        return frame.sender == self.endpoint.name

    def wire_frame(self, msg: Any) -> WireFrame:
        """``msg`` (python-can's Message or a SimMessage) as this port's frame.

        :raises ValueError: a frame a classic CAN bus cannot carry.
        """
        if msg.is_fd:
            raise ValueError("seqrun-sim is classic CAN: cannot send a CAN FD frame")
        if msg.is_error_frame:
            raise ValueError("seqrun-sim: error frames cannot be sent")
        data = bytes(msg.data or b"")
        # Stamped with this endpoint as the sender, as the wire would, so it is not copied.
        sender = self.endpoint.name
        if msg.is_remote_frame:
            return WireFrame(msg.arbitration_id, b"", msg.is_extended_id, True, msg.dlc, 0.0,
                             sender)
        if msg.dlc != len(data):
            raise ValueError(f"dlc {msg.dlc} does not match {len(data)} data bytes")
        return _new_tuple(WireFrame, (msg.arbitration_id, data, msg.is_extended_id, False, None,
                                      0.0, sender))

    def send_frame(self, frame: WireFrame, timeout: float | None = None) -> None:
        """Queue ``frame`` for the wire.

        :raises ValueError: a frame a classic CAN bus cannot carry ("seqrun-sim: ...").
        :raises ~seqrun.sim.network.TransmitTimeoutError: the transmit queue stayed full.
        :raises NetworkClosedError: the port is closed.
        """
        try:
            self.endpoint.send(frame, timeout)
        except NetworkClosedError:
            raise
        except ValueError as exc:
            raise ValueError(f"seqrun-sim: {exc}") from None

    # -- python-can's bus interface, with SimMessage ------------------------------------------

    def recv(self, timeout: float | None = None) -> SimMessage | None:
        """The next frame delivered within ``timeout`` seconds of the simulation clock
        (see :mod:`seqrun.sim.bus` for virtual time); None when none is."""
        deadline = None if timeout is None else self.clock.now() + max(timeout, 0.0)
        frame = self.endpoint.receive(deadline)
        if frame is None:
            return None
        can_id, data, extended, remote, dlc, timestamp, sender = frame
        return SimMessage(timestamp, can_id, extended, remote, False, self.channel,
                          dlc if remote else None, data, False, sender != self.endpoint.name)

    def send(self, msg: Any, timeout: float | None = None) -> None:
        """Queue ``msg`` for the simulated wire (errors as :meth:`wire_frame` and
        :meth:`send_frame`)."""
        self.send_frame(self.wire_frame(msg), timeout)

    def shutdown(self) -> None:
        """Detach from the wire; the last port of a channel takes the arm with it. Safe to
        call twice."""
        if self._closed:
            return
        self._closed = True
        self.endpoint.close()
        _leave_channel(self.channel, self.network)

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self) -> SimPort:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.shutdown()
