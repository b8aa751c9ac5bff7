"""Choosing the bus: a real CAN adapter through python-can, or the built-in simulator.

Selection follows python-can's own tools: ``-i/--interface``, ``-c/--channel``,
``-b/--bitrate`` and extra ``--bus-kwargs``, then python-can's configuration
(``CAN_INTERFACE``/``CAN_CHANNEL``/``CAN_BITRATE``, ``~/.canrc``, ``/etc/can.conf``).
When none of them names an interface, the simulated arm runs (in real time for ``run``)
and the caller prints a banner saying so.
"""

from __future__ import annotations

import itertools
import logging
import os
import sys
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Iterable, Mapping, Sequence

from seqrun.clock import Clock, RealClock
from seqrun.errors import UserInputError

if TYPE_CHECKING:  # python-can (and its can.io: asyncio, ssl, sqlite3) only when a bus opens
    import can

    from seqrun.service.bus_claim import BusClaim

    from seqrun.sim.faults import Fault
    from seqrun.sim.module import ModuleOptions

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
    #: (interface, channel) of a bus other processes can reach (one controller per bus:
    #: seqrun/service/bus_claim.py); None for a bus of this process only (the simulator).
    bus_key: tuple[str, str] | None = None
    #: This process's claim of the bus, released by :meth:`close`.
    claim: BusClaim | None = None
    #: The bus hands this process its own frames back (``receive_own_messages``).
    echoes_own: bool = False
    #: The options that reach this bus from another terminal (:func:`reach_options`).
    reach: tuple[str, ...] = ()

    def close(self) -> None:
        try:
            self.bus.shutdown()
        except Exception as exc:  # noqa: BLE001 - a dead connection cannot be closed cleanly
            logging.getLogger(__name__).debug("closing the bus failed: %r", exc)
        finally:
            if self.claim is not None:
                self.claim.release()


def parse_bus_kwargs(items: Sequence[str]) -> dict[str, Any]:
    """``["host=127.0.0.1", "port=29536"]`` -> dict, values cast like python-can's config."""
    import can

    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise UserInputError(f"--bus-kwargs expects KEY=VALUE, got '{item}'")
        out[key.strip()] = can.util.cast_from_string(value.strip())
    return out


def sim_options_from_env(environ: Mapping[str, str] | None = None) -> ModuleOptions | None:
    """Simulator module options from ``SEQRUN_SIM_OPTIONS`` (None when unset), e.g.
    ``SEQRUN_SIM_OPTIONS=framp_from_standstill seqrun run ...``."""
    from seqrun.sim.module import SIM_OPTIONS_ENV
    from seqrun.sim.options import parse_module_options

    spec = (os.environ if environ is None else environ).get(SIM_OPTIONS_ENV, "").strip()
    if not spec:
        return None
    try:
        return parse_module_options(spec)
    except ValueError as exc:
        raise UserInputError(f"{SIM_OPTIONS_ENV}: {exc}") from None


def parse_faults(specs: Iterable[str]) -> list[Fault]:
    from seqrun.sim.faults import parse_fault_spec

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
    import can

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
    except (ValueError, TypeError) as exc:  # e.g. port=abc: "Port config must be a number!"
        raise UserInputError(f"bad CAN configuration: {exc}") from None


#: Interfaces whose bus lives in this process only: nobody else can be on it, no claim.
PROCESS_LOCAL_INTERFACES = (SIM_INTERFACE, "virtual")


def bus_key(config: Mapping[str, Any]) -> tuple[str, str] | None:
    """(interface, channel) naming a bus for the one-controller claim, from a resolved
    configuration; None for a bus of this process only. socketcand's channel includes the
    server's address: two servers are two buses."""
    interface = config.get("interface")
    if not interface or interface in PROCESS_LOCAL_INTERFACES:
        return None
    if interface == "socketcand":
        return interface, (f"{endpoint_host(str(config.get('host') or '127.0.0.1'))}:"
                           f"{config.get('port') or DEFAULT_SOCKETCAND_PORT}/"
                           f"{config.get('channel') or 'can0'}")
    return str(interface), str(config.get("channel"))


def endpoint_host(host: str) -> str:
    """One spelling for every name of a socketcand server's host, so that a claim or a
    same-bus check keys on the server reached, not on the text: ``localhost``,
    ``127.0.0.1`` and this machine's own addresses are all ``127.0.0.1``; another host is
    its IPv4 address (python-can's socketcand client connects over IPv4). A name that does
    not resolve stays as given (connecting to it fails with its own line)."""
    import ipaddress
    import socket

    try:
        address = socket.gethostbyname(host)
    except (OSError, UnicodeError):
        return host
    if ipaddress.ip_address(address).is_loopback:
        return "127.0.0.1"
    try:
        # an address this machine can bind to is one of its own (0.0.0.0 included)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.bind((address, 0))
    except OSError:
        return address
    return "127.0.0.1"


def bus_text(config: Mapping[str, Any]) -> str:
    """How a bus is named in every line that names one: ``CAN interface 'socketcand'
    127.0.0.1:29536 channel 'can0'`` (host:port for socketcand: two servers are two
    arms), ``CAN interface 'socketcan' channel 'can0'``."""
    interface = config.get("interface")
    where = ""
    if interface == "socketcand":
        where = (f" {config.get('host') or '127.0.0.1'}:"
                 f"{config.get('port') or DEFAULT_SOCKETCAND_PORT}")
    return f"CAN interface '{interface}'{where} channel '{config.get('channel')}'"


def reach_options(config: Mapping[str, Any]) -> tuple[str, ...]:
    """The command-line options that reach this bus from another terminal (``-i … -c …
    --bus-kwargs host=… port=…``); empty for a bus of one process only."""
    interface = config.get("interface")
    if not interface or interface in PROCESS_LOCAL_INTERFACES:
        return ()
    words = ["-i", str(interface)]
    if config.get("channel") is not None:
        words += ["-c", str(config["channel"])]
    if interface == "socketcand":
        words += ["--bus-kwargs", f"host={config.get('host') or '127.0.0.1'}",
                  f"port={config.get('port') or DEFAULT_SOCKETCAND_PORT}"]
    return tuple(words)


def shared_bus(*, interface: str | None = None, channel: str | None = None,
               bitrate: int | None = None, bus_kwargs: Mapping[str, Any] | None = None,
               force_sim: bool = False) -> tuple[str, str] | None:
    """The claim key of the bus :func:`open_connection` would open with these arguments
    (None: the simulator, nobody else's); opens nothing."""
    if force_sim:
        return None
    return bus_key(resolve_config(interface, channel, bitrate, bus_kwargs))


class _OneLineHandler(logging.Handler):
    """python-can logs some failures with a whole traceback (its socketcand client on a
    lost connection); the operator gets the first line, once, and the run's own fault
    line says what it means."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self._seen: set[str] = set()

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage().split("Traceback (most recent call last)")[0]
            line = (text.strip().splitlines() or [""])[0].strip()
            if line and line not in self._seen:
                self._seen.add(line)
                sys.stderr.write(f"python-can: {line}\n")
        except Exception:  # noqa: BLE001 - logging must never break a run
            pass


def _one_line_library_logs() -> None:
    logger = logging.getLogger("can")
    if not any(isinstance(h, _OneLineHandler) for h in logger.handlers):
        logger.addHandler(_OneLineHandler())
        logger.propagate = False


def _probe_tcp(host: str, port: int, timeout: float = 2.0) -> None:
    """python-can's socketcand client retries a refused connection for 10 s, logging a
    warning each time; one probe first turns "nobody there" into one clear line."""
    import socket  # only for socketcand: not imported by commands that never reach it

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
                    sim_modules: Sequence[int] | None = None,
                    default_bitrate: int = 1_000_000,
                    power_on_pose: str | None = None,
                    python_can: bool = True, claim: bool = True,
                    transient: bool = False) -> Connection:
    """Open the bus the operator asked for (see the module docstring).

    A bus other processes can reach is claimed first (``claim``; ``transient`` for a
    command that holds it for a moment): when another seqrun holds it this raises
    :class:`~seqrun.errors.Refused` naming the holder, before anything is opened or sent.

    ``python_can=False`` (with ``force_sim``): the simulator as a
    :class:`~seqrun.sim.port.SimPort`, without importing python-can (the dry run: nobody
    outside this process talks to that bus)."""
    from seqrun.sim.module import SIM_OPTIONS_ENV

    response_timeout_s(None)  # a bad $SEQRUN_RESPONSE_TIMEOUT_MS: one line, before the bus
    config = {} if force_sim else resolve_config(interface, channel, bitrate, bus_kwargs)
    if force_sim or not config.get("interface") or config["interface"] == SIM_INTERFACE:
        # Simulator switches (home_ok_at_power_on=true, ...) are the only --bus-kwargs
        # the built-in simulator takes.
        from seqrun.sim.options import SWITCHES as SIM_SWITCHES

        switches = {k: v for k, v in (bus_kwargs or {}).items() if k in SIM_SWITCHES}
        if force_sim and (interface or channel):
            raise UserInputError("--sim cannot be combined with -i/-c")
        if others := sorted(set(bus_kwargs or {}) - set(switches)):
            raise UserInputError(f"--bus-kwargs {', '.join(others)}: the built-in simulator "
                                 "takes only its switches (e.g. home_ok_at_power_on=true); "
                                 "name an interface with -i")
        clock = clock or RealClock()
        name = str(config.get("channel") or f"seqrun-{next(_sim_channels)}")
        options = sim_options_from_env()  # SEQRUN_SIM_OPTIONS, then --bus-kwargs switches
        if python_can or not force_sim:
            import can

            from seqrun.sim.bus import SimBus as bus_class
            refused: tuple[type[Exception], ...] = (can.CanInitializationError,)
        else:
            from seqrun.sim.port import SimPort as bus_class  # type: ignore[assignment]
            from seqrun.sim.port import SimSetupError
            refused = (SimSetupError,)
        try:
            bus = bus_class(channel=name, clock=clock, faults=list(faults),
                            bitrate=bitrate or config.get("bitrate") or default_bitrate,
                            positions=sim_positions, options=options,
                            power_on_pose=power_on_pose, modules=sim_modules, **switches)
        except refused as exc:
            raise UserInputError(f"--bus-kwargs: {exc}") from None
        kind = "virtual time" if clock.is_virtual else "real time"
        changed = "" if options is None else f", options {os.environ[SIM_OPTIONS_ENV].strip()}"
        return Connection(bus, clock, True,
                          f"SIMULATOR ({kind}): simulated LWA 3 on '{name}', "
                          f"{bus.bitrate} bit/s{changed} - no hardware is moved", list(faults),
                          power_on_pose=bus.arm.power_on_pose)
    if faults:
        raise UserInputError("--sim-fault only applies to the simulator (no -i/-c, or --sim)")
    import can

    if config["interface"] == "socketcand":  # python-can's config gives channel=None
        # tcp_tune: TCP_NODELAY + TCP_QUICKACK. Without it Nagle holds a frame back until
        # the previous one is acknowledged, and a delayed ACK takes 40 ms: enough for a
        # late acknowledge, or a watchdog refresh that comes too late.
        for key, value in (("host", "127.0.0.1"), ("port", DEFAULT_SOCKETCAND_PORT),
                           ("channel", "can0"), ("tcp_tune", True)):
            if config.get(key) is None:
                config[key] = value
        try:
            port = int(config["port"])
        except (TypeError, ValueError):
            raise UserInputError(f"socketcand port must be a number, got "
                                 f"{config['port']!r}") from None
        _probe_tcp(str(config["host"]), port)
    config.setdefault("bitrate", default_bitrate)
    _one_line_library_logs()
    claim_key = bus_key(config)
    held = None
    if claim and claim_key is not None:
        from seqrun.service.bus_claim import claim_bus

        held = claim_bus(*claim_key, transient=transient)
    try:
        real_bus = can.Bus(**config)
    # TypeError: --bus-kwargs the interface does not take
    except (can.CanError, OSError, ValueError, TypeError, ImportError) as exc:
        if held is not None:
            held.release()
        from seqrun.service.adapters import adapter_hint

        hint = adapter_hint(config["interface"], sys.platform)
        raise UserInputError(f"cannot open CAN interface '{config['interface']}' "
                             f"channel '{config.get('channel')}': {hint or exc}") from None
    except BaseException:
        if held is not None:
            held.release()
        raise
    desc = f"{bus_text(config)} at {config.get('bitrate')} bit/s"
    return Connection(real_bus, clock or RealClock(), False, desc, bus_key=claim_key, claim=held,
                      echoes_own=bool(config.get("receive_own_messages")),
                      reach=reach_options(config))


#: Environment variable that overrides the arm file's response timeout, in milliseconds.
RESPONSE_TIMEOUT_ENV = "SEQRUN_RESPONSE_TIMEOUT_MS"


def response_timeout_s(arm: Any, override_ms: float | None = None) -> float:
    """Seconds to wait for each module's answer: ``override_ms`` (a command's
    ``--response-timeout-ms``), else ``$SEQRUN_RESPONSE_TIMEOUT_MS``, else the arm file's
    ``can.response_timeout_s``. A shared simulator on a loaded machine may need more than
    the real arm's 50 ms. (``arm=None`` only checks the overrides; returns 0 if none.)

    :raises UserInputError: a value that is not a positive number of milliseconds.
    """
    import os

    value: float | str | None
    source, value = "--response-timeout-ms", override_ms
    if value is None and os.environ.get(RESPONSE_TIMEOUT_ENV, "").strip():
        source, value = RESPONSE_TIMEOUT_ENV, os.environ[RESPONSE_TIMEOUT_ENV]
    if value is None:
        return float(arm.can.response_timeout_s) if arm is not None else 0.0
    try:
        ms = float(value)
    except ValueError:
        ms = float("nan")
    if not 0 < ms <= 60_000:
        raise UserInputError(f"{source} {value!r}: give milliseconds, more than 0 and at "
                             "most 60000")
    return ms / 1000.0

