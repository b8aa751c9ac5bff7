"""Choosing the bus: a real CAN adapter through python-can, or the built-in simulator.

Selection follows python-can's own tools: ``-i/--interface``, ``-c/--channel``,
``-b/--bitrate`` and extra ``--bus-kwargs``, then python-can's configuration
(``CAN_INTERFACE``/``CAN_CHANNEL``/``CAN_BITRATE``, ``~/.canrc``, ``/etc/can.conf``).
When none of them names an interface, the simulated arm runs (in real time for ``run``)
and the caller prints a banner saying so.
"""

from __future__ import annotations

import itertools
import socket
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

import can

from seqrun.clock import Clock, RealClock
from seqrun.errors import UserInputError
from seqrun.sim.bus import SimBus
from seqrun.sim.faults import Fault, parse_fault_spec

#: The interface name of the simulator (the python-can plugin).
SIM_INTERFACE = "seqrun-sim"
#: Port of ``seqrun sim serve`` (socketcand), used when ``-i socketcand`` names none.
DEFAULT_SOCKETCAND_PORT = 29536

_sim_channels = itertools.count(1)


@dataclass
class Connection:
    bus: can.BusABC
    clock: Clock
    is_simulator: bool
    description: str
    faults: list[Fault] = field(default_factory=list)
    #: The built-in simulator's power-on pose (its zero reference); None on other buses.
    power_on_pose: str | None = None

    def close(self) -> None:
        self.bus.shutdown()


def parse_bus_kwargs(items: Sequence[str]) -> dict[str, Any]:
    """``["host=127.0.0.1", "port=29536"]`` -> dict, values cast like python-can's config."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise UserInputError(f"--bus-kwargs expects KEY=VALUE, got '{item}'")
        out[key.strip()] = can.util.cast_from_string(value.strip())
    return out


def parse_faults(specs: Iterable[str]) -> list[Fault]:
    faults = []
    for spec in specs:
        try:
            faults.append(parse_fault_spec(spec))
        except ValueError as exc:
            raise UserInputError(f"--sim-fault '{spec}': {exc}") from None
    return faults


def resolve_config(interface: str | None, channel: str | None, bitrate: int | None,
                   bus_kwargs: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """python-can's merged configuration (command line first, then env/config files)."""
    given: dict[str, Any] = {k: v for k, v in (("interface", interface), ("channel", channel),
                                               ("bitrate", bitrate)) if v is not None}
    given.update(bus_kwargs or {})
    sources = (given, can.rc, can.util.load_environment_config(), can.util.load_file_config())
    if not any(src.get("interface") or src.get("bustype") for src in sources):
        return {}  # nothing configured anywhere: the simulator
    try:
        return dict(can.util.load_config(config=given))
    except can.CanInterfaceNotImplementedError as exc:
        raise UserInputError(f"unknown CAN interface: {exc}") from None


def _probe_tcp(host: str, port: int, timeout: float = 2.0) -> None:
    """python-can's socketcand client retries a refused connection for 10 s, logging a
    warning each time; one probe first turns "nobody there" into one clear line."""
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        raise UserInputError(f"no socketcand server at {host}:{port} ({exc.strerror or exc}); "
                             "start the simulated arm with 'seqrun sim serve'") from None


def open_connection(*, interface: str | None = None, channel: str | None = None,
                    bitrate: int | None = None, bus_kwargs: Mapping[str, Any] | None = None,
                    force_sim: bool = False, faults: Sequence[Fault] = (),
                    clock: Clock | None = None,
                    sim_positions: Mapping[int, float] | Sequence[float] | None = None,
                    default_bitrate: int = 1_000_000,
                    power_on_pose: str | None = None) -> Connection:
    """Open the bus the operator asked for (see the module docstring)."""
    config = {} if force_sim else resolve_config(interface, channel, bitrate, bus_kwargs)
    if force_sim or not config.get("interface") or config["interface"] == SIM_INTERFACE:
        if force_sim and (interface or channel or bus_kwargs):
            raise UserInputError("--sim cannot be combined with -i/-c/--bus-kwargs")
        clock = clock or RealClock()
        name = str(config.get("channel") or f"seqrun-{next(_sim_channels)}")
        bus = SimBus(channel=name, clock=clock, faults=list(faults),
                     bitrate=bitrate or config.get("bitrate") or default_bitrate,
                     positions=sim_positions, power_on_pose=power_on_pose)
        kind = "virtual time" if clock.is_virtual else "real time"
        return Connection(bus, clock, True,
                          f"SIMULATOR ({kind}): simulated LWA 3 on '{name}', "
                          f"{bus.bitrate} bit/s - no hardware is moved", list(faults),
                          power_on_pose=bus.arm.power_on_pose)
    if faults:
        raise UserInputError("--sim-fault only applies to the simulator (no -i/-c, or --sim)")
    if config["interface"] == "socketcand":  # python-can's config gives channel=None
        # tcp_tune: TCP_NODELAY + TCP_QUICKACK. Without it Nagle holds a frame back until
        # the previous one is acknowledged, and a delayed ACK takes 40 ms: enough for a
        # late acknowledge, or a watchdog refresh that comes too late.
        for key, value in (("host", "127.0.0.1"), ("port", DEFAULT_SOCKETCAND_PORT),
                           ("channel", "can0"), ("tcp_tune", True)):
            if config.get(key) is None:
                config[key] = value
        _probe_tcp(str(config["host"]), int(config["port"]))
    config.setdefault("bitrate", default_bitrate)
    try:
        bus = can.Bus(**config)
    # TypeError: --bus-kwargs the interface does not take
    except (can.CanError, OSError, ValueError, TypeError, ImportError) as exc:
        raise UserInputError(f"cannot open CAN interface '{config['interface']}' "
                             f"channel '{config.get('channel')}': {exc}") from None
    desc = (f"CAN interface '{config['interface']}' channel '{config.get('channel')}' "
            f"at {config.get('bitrate')} bit/s")
    return Connection(bus, clock or RealClock(), False, desc)
