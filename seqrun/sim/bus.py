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
A SimBus is a :class:`~seqrun.sim.port.SimPort` (the same connection to the wire, without
python-can) with python-can's messages, errors and filters; the dry run uses a SimPort.

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
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import can
from can import BusABC, CanInitializationError, CanOperationError, Message

from seqrun.clock import Clock
from seqrun.sim.faults import Fault
from seqrun.sim.module import ModuleOptions
from seqrun.sim.network import DEFAULT_TX_QUEUE_SIZE, NetworkClosedError, TransmitTimeoutError
from seqrun.sim.options import pop_switches
from seqrun.sim.port import SimPort, SimSetupError, get_network, open_channels

__all__ = ["SimBus", "get_network"]

logger = logging.getLogger(__name__)


def _bitrate_from(bitrate: Any, timing: Any) -> Any:
    if timing is not None:
        if isinstance(timing, can.BitTimingFd):
            raise CanInitializationError("seqrun-sim is classic CAN; CAN FD timing given")
        return int(timing.bitrate)
    return bitrate


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
    :param serials: the modules' serial numbers by id (first bus only; see SimArm).
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
                 serials: Mapping[int, int] | None = None,
                 tx_queue_size: int = DEFAULT_TX_QUEUE_SIZE,
                 fd: bool = False, timing: Any = None, **kwargs: Any) -> None:
        if fd:
            raise CanInitializationError("seqrun-sim simulates a classic CAN bus; fd=True given")
        try:
            self._port = SimPort(channel, clock=clock, faults=faults,
                                 bitrate=_bitrate_from(bitrate, timing),
                                 receive_own_messages=receive_own_messages,
                                 module_latency=module_latency, seed=seed, options=options,
                                 positions=positions, modules=modules,
                                 power_on_pose=power_on_pose, serials=serials,
                                 tx_queue_size=tx_queue_size,
                                 **pop_switches(kwargs))
        except SimSetupError as exc:
            raise CanInitializationError(str(exc)) from None
        self.network = self._port.network
        #: The simulated arm behind this bus (shared by every bus on the channel).
        self.arm = self._port.arm
        self.clock = self._port.clock
        self.bitrate = self._port.bitrate
        self.receive_own_messages = receive_own_messages
        self.channel = channel = self._port.channel
        self.channel_info = (f"seqrun-sim channel {channel!r}: simulated LWA 3, "
                             f"{self.bitrate} bit/s")
        try:
            super().__init__(channel=channel, can_filters=can_filters, **kwargs)
        except Exception:
            self._port.shutdown()
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
            frame = self._port.receive_frame(deadline)
        except NetworkClosedError:
            raise CanOperationError("Cannot operate on a closed bus") from None
        if frame is None:
            return None
        return Message(timestamp=frame.timestamp, arbitration_id=frame.can_id,
                       is_extended_id=frame.is_extended, is_remote_frame=frame.is_remote,
                       dlc=frame.length, data=frame.data, channel=self.channel,
                       is_rx=not self._port.is_own(frame))

    # -- send ---------------------------------------------------------------------------------

    def send(self, msg: Message, timeout: float | None = None) -> None:
        """Queue ``msg`` for the simulated wire (see the module docstring).

        :raises ~can.exceptions.CanOperationError: closed bus, a frame a classic CAN bus
            cannot carry (FD, error frame, bad id or length), or a full transmit queue
            for longer than ``timeout``.
        """
        self._check_open()
        try:
            self._port.send(msg, timeout)
        except ValueError as exc:  # a frame classic CAN cannot carry
            raise CanOperationError(str(exc)) from None
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
        self._port.shutdown()

    @staticmethod
    def _detect_available_configs() -> list[can.typechecking.AutoDetectedConfig]:
        """The channels that have open buses (and so a running arm)."""
        return [{"interface": "seqrun-sim", "channel": name} for name in open_channels()]
