"""SimBus: the simulated LWA 3 as a python-can interface, ``interface="seqrun-sim"``.

::

    bus = can.Bus(interface="seqrun-sim", channel="arm0", clock=VirtualClock(),
                  faults=["4:tow_error@2.5"], bitrate=1_000_000, ignore_config=True)

Registered through the ``can.interface`` entry point in ``pyproject.toml``. Like
python-can's ``virtual`` interface, buses opened on the same ``channel`` in one process
share one wire — here one :class:`~seqrun.sim.network.SimNetwork` with one
:class:`~seqrun.sim.arm.SimArm` — and see each other's frames. The first bus on a channel
creates the arm (with its clock, faults, bitrate, ...); later ones join it (their faults are
added); when the last one shuts down the arm is gone and the next bus gets a fresh one
(power cycle). :func:`get_network` reaches a channel's wire and arm from tests.

Clock: with a :class:`~seqrun.clock.VirtualClock`, :meth:`SimBus.recv` returns the next
frame due within the timeout and advances the clock to its delivery time, or advances
the clock by the whole timeout and returns None — it never spins on wall-clock time as
``BusABC.recv`` would. With the default :class:`~seqrun.clock.RealClock` it blocks in real
time until a frame is due. ``Message.timestamp`` is the delivery time on that clock.
``recv(None)`` on a virtual clock with nothing on its way waits (really) for another
thread to send — in a single-threaded test that is forever, as on an idle real bus.
``send`` does not wait, except while 256 of this bus's frames are still queued for the
wire; then it waits (on the clock) for room, never forever.

Not simulated (besides what :mod:`seqrun.sim.network` and :mod:`seqrun.sim.module` list):
CAN FD, error frames, bus state changes, hardware filters (filters are applied in software).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import can
from can import BusABC, CanInitializationError, CanOperationError, Message

from seqrun.clock import Clock, RealClock
from seqrun.sim.arm import SimArm
from seqrun.sim.faults import Fault, parse_faults
from seqrun.sim.module import ModuleOptions
from seqrun.sim.options import module_options, pop_switches
from seqrun.sim.network import (
    DEFAULT_TX_QUEUE_SIZE,
    Endpoint,
    NetworkClosedError,
    SimNetwork,
    TransmitTimeoutError,
    WireFrame,
)

logger = logging.getLogger(__name__)

#: channel name -> (network, number of open buses on it)
_channels: dict[str, list[Any]] = {}
_channels_lock = threading.RLock()


def get_network(channel: str = "arm0") -> SimNetwork:
    """The wire (and, as ``.arm``, the simulated arm) of a channel with an open bus.

    :raises LookupError: no bus is open on ``channel``.
    """
    with _channels_lock:
        try:
            return _channels[str(channel)][0]
        except KeyError:
            raise LookupError(f"no seqrun-sim bus is open on channel {channel!r}") from None


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
            raise CanInitializationError(
                f"seqrun-sim channel {channel!r} already runs on another clock; "
                "pass the same clock object (or none) to every bus on a channel")
        if bitrate is not None and bitrate != network.bitrate:
            raise CanInitializationError(
                f"seqrun-sim channel {channel!r} runs at {network.bitrate} bit/s, "
                f"not {bitrate}: nodes with different bitrates cannot talk")
        given = sorted(k for k, v in arm_kwargs.items() if v is not None)
        if given:
            raise CanInitializationError(
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


def _bitrate_from(bitrate: Any, timing: Any) -> int | None:
    if timing is not None:
        if isinstance(timing, can.BitTimingFd):
            raise CanInitializationError("seqrun-sim is classic CAN; CAN FD timing given")
        return int(timing.bitrate)
    if bitrate is None:
        return None
    try:
        value = int(bitrate)
    except (TypeError, ValueError):
        raise CanInitializationError(f"bitrate must be an integer, got {bitrate!r}") from None
    if value <= 0:
        raise CanInitializationError(f"bitrate must be positive, got {value}")
    return value


class SimBus(BusABC):
    """A python-can bus on the simulated LWA 3 (see the module docstring).

    :param channel: name of the simulated bus; buses with the same name share one arm.
    :param clock: :class:`~seqrun.clock.Clock` of the simulation (default: real time).
    :param faults: :class:`~seqrun.sim.faults.Fault` objects or spec strings
        (``"4:tow_error@2.5"``; one string may hold several, comma separated).
    :param bitrate: bit/s of the wire (default 1 Mbit/s, the LWA 3's).
    :param receive_own_messages: also receive the frames this bus sends.
    :param module_latency: request-to-ack time of the modules (first bus only).
    :param seed: seed of ``drop_acks`` losses (first bus only).
    :param options: :class:`~seqrun.sim.module.ModuleOptions` (first bus only); single
        switches may also be given by name as keyword arguments
        (``home_ok_at_power_on=True``, strings like "true" too, see :mod:`seqrun.sim.options`).
    :param positions: start positions in rad, module coordinates (first bus only).
    :param modules: module ids of the arm, default 1..7 (first bus only).
    :param power_on_pose: where the arm stood at power-on (first bus only; see SimArm).
    :param tx_queue_size: frames that may wait for the wire before ``send`` waits.
    """

    def __init__(self, channel: Any = "arm0", *, clock: Clock | None = None,
                 faults: Iterable[Fault | str] | str | None = None,
                 bitrate: int | None = None, receive_own_messages: bool = False,
                 can_filters: can.typechecking.CanFilters | None = None,
                 module_latency: float | None = None, seed: int | None = None,
                 options: ModuleOptions | None = None,
                 positions: Mapping[int, float] | Sequence[float] | None = None,
                 modules: Iterable[int] | None = None,
                 power_on_pose: str | None = None,
                 tx_queue_size: int = DEFAULT_TX_QUEUE_SIZE,
                 fd: bool = False, timing: Any = None, **kwargs: Any) -> None:
        if fd:
            raise CanInitializationError("seqrun-sim simulates a classic CAN bus; fd=True given")
        channel = "arm0" if channel is None else str(channel)
        try:
            fault_list = parse_faults(faults)
            switches = pop_switches(kwargs)
            if switches:
                options = module_options(switches, options)
        except (TypeError, ValueError) as exc:
            raise CanInitializationError(str(exc)) from None
        arm_kwargs = {"module_latency": module_latency, "seed": seed, "options": options,
                      "positions": positions,
                      "modules": None if modules is None else list(modules),
                      "power_on_pose": power_on_pose}
        self._channel_name = channel
        self.network = _join_channel(channel, clock, _bitrate_from(bitrate, timing),
                                     fault_list, arm_kwargs)
        #: The simulated arm behind this bus (shared by every bus on the channel).
        self.arm = self.network.arm
        self.clock = self.network.clock
        self.bitrate = self.network.bitrate
        self.receive_own_messages = receive_own_messages
        self._endpoint: Endpoint = self.network.attach(
            receive_own=receive_own_messages, tx_queue_size=tx_queue_size)
        self.channel = channel
        self.channel_info = (f"seqrun-sim channel {channel!r}: simulated LWA 3, "
                             f"{self.bitrate} bit/s")
        try:
            super().__init__(channel=channel, can_filters=can_filters, **kwargs)
        except Exception:
            self._endpoint.close()
            _leave_channel(channel, self.network)
            raise

    # -- receive --------------------------------------------------------------------------

    def recv(self, timeout: float | None = None) -> Message | None:
        """The next frame (passing the filters) delivered within ``timeout`` seconds of the
        simulation clock; None when none is. See the module docstring for virtual time."""
        self._check_open()
        deadline = None if timeout is None else self.clock.now() + max(timeout, 0.0)
        while True:
            msg = self._receive(deadline)
            if msg is None:
                return None
            if self._matches_filters(msg):
                logger.log(self.RECV_LOGGING_LEVEL, "Received: %s", msg)
                return msg

    def _recv_internal(self, timeout: float | None) -> tuple[Message | None, bool]:
        self._check_open()
        deadline = None if timeout is None else self.clock.now() + max(timeout, 0.0)
        return self._receive(deadline), False

    def _receive(self, deadline: float | None) -> Message | None:
        try:
            frame = self._endpoint.receive(deadline)
        except NetworkClosedError:
            raise CanOperationError("Cannot operate on a closed bus") from None
        if frame is None:
            return None
        return Message(timestamp=frame.timestamp, arbitration_id=frame.can_id,
                       is_extended_id=frame.is_extended, is_remote_frame=frame.is_remote,
                       dlc=frame.length, data=frame.data, channel=self.channel,
                       is_rx=frame.sender != self._endpoint.name)

    # -- send ---------------------------------------------------------------------------------

    def send(self, msg: Message, timeout: float | None = None) -> None:
        """Queue ``msg`` for the simulated wire (see the module docstring).

        :raises ~can.exceptions.CanOperationError: closed bus, a frame a classic CAN bus
            cannot carry (FD, error frame, bad id or length), or a full transmit queue
            for longer than ``timeout``.
        """
        self._check_open()
        if msg.is_fd:
            raise CanOperationError("seqrun-sim is classic CAN: cannot send a CAN FD frame")
        if msg.is_error_frame:
            raise CanOperationError("seqrun-sim: error frames cannot be sent")
        data = bytes(msg.data or b"")
        # Stamped with this endpoint as the sender, as the wire would, so it is not copied.
        sender = self._endpoint.name
        if msg.is_remote_frame:
            frame = WireFrame(msg.arbitration_id, b"", msg.is_extended_id, True, msg.dlc,
                              0.0, sender)
        else:
            if msg.dlc != len(data):
                raise CanOperationError(f"dlc {msg.dlc} does not match {len(data)} data bytes")
            frame = WireFrame(msg.arbitration_id, data, msg.is_extended_id, False, None, 0.0,
                              sender)
        try:
            self._endpoint.send(frame, timeout)
        except ValueError as exc:
            raise CanOperationError(f"seqrun-sim: {exc}") from None
        except TransmitTimeoutError as exc:
            raise CanOperationError(str(exc)) from None
        except NetworkClosedError:
            raise CanOperationError("Cannot operate on a closed bus") from None

    # -- lifecycle -----------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._is_shutdown:
            raise CanOperationError("Cannot operate on a closed bus")

    def shutdown(self) -> None:
        """Detach from the wire; the last bus of a channel takes the arm with it."""
        if self._is_shutdown:
            return
        super().shutdown()
        self._endpoint.close()
        _leave_channel(self._channel_name, self.network)

    @staticmethod
    def _detect_available_configs() -> list[can.typechecking.AutoDetectedConfig]:
        """The channels that have open buses (and so a running arm)."""
        with _channels_lock:
            return [{"interface": "seqrun-sim", "channel": name} for name in _channels]
