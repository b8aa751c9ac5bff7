"""The simulated arm as a server for other processes (``seqrun sim serve``).

:func:`serve_simulated_arm` builds the simulated LWA 3 (its faults and switches checked
first, one line each) on a socketcand server bound to a loopback address; the face prints
what it serves and runs it until Ctrl-C.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from seqrun.errors import UserInputError

__all__ = ["SimulatedArmServer", "serve_simulated_arm"]


@dataclass
class SimulatedArmServer:
    """A simulated arm being served: ``server`` (``host``, ``port``, ``serve_forever()``,
    ``shutdown()``), what it was started with, and its switches in force."""

    server: Any
    channel: str
    bitrate: int
    power_on_pose: str
    faults: list[str]
    switches: dict[str, Any]
    #: What each module says its serial number is (the arm's identity), by module id.
    serials: dict[int, int]


def _power_off_pose(name: str) -> str:
    """``name`` as a power-off pose of the shipped arm."""
    from seqrun.arm.description import load_arm
    from seqrun.shipped import DEFAULT_ARM_NAME, shipped_arm

    path = shipped_arm(DEFAULT_ARM_NAME)
    assert path is not None  # (shipped with seqrun)
    arm = load_arm(path)
    try:
        arm.power_off_pose(name)
    except UserInputError as exc:
        raise UserInputError(f"--power-on-at: {exc}") from None
    return name if name in arm.power_off_poses else name.lower()


def serve_simulated_arm(*, host: str, port: int, channel: str, faults: Sequence[str],
                        bitrate: int, module_options: Sequence[str],
                        switches: dict[str, Any], power_on_at: str) -> SimulatedArmServer:
    """The simulated LWA 3 (7 modules, powered on at ``power_on_at``, real time) on a
    socketcand server; not serving yet. Every bad argument is one
    :class:`~seqrun.errors.UserInputError` line, checked before anything listens."""
    from seqrun.clock import RealClock
    from seqrun.service.connection import sim_options_from_env
    from seqrun.sim.arm import SimArm
    from seqrun.sim.faults import parse_faults
    from seqrun.sim.network import SimNetwork
    from seqrun.sim.options import module_options as parse_module_options
    from seqrun.sim.socketcand import SocketcandServer

    try:
        injected = parse_faults(list(faults))
    except ValueError as exc:
        raise UserInputError(str(exc)) from None
    pose = _power_off_pose(power_on_at)
    if not 0 <= port <= 65535:
        raise UserInputError(f"--port {port}: must be 0..65535")
    if bitrate <= 0:
        raise UserInputError(f"--bitrate {bitrate}: must be positive")
    settings: dict[str, object] = {}
    for item in module_options:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise UserInputError(f"--module-option expects NAME=VALUE, got '{item}'")
        settings[name.strip()] = value.strip()
    settings.update(switches)
    try:  # SEQRUN_SIM_OPTIONS first, the flags on top
        options = parse_module_options(settings, sim_options_from_env())
    except ValueError as exc:
        raise UserInputError(f"--module-option {exc}") from None
    clock = RealClock()
    try:
        arm = SimArm(clock, faults=injected, options=options, power_on_pose=pose)
    except ValueError as exc:  # a fault for a module the arm does not have, a bad serial
        raise UserInputError(str(exc)) from None
    # No spinning: TCP adds more latency than a late wake-up, and clients may be many.
    network = SimNetwork(clock, arm, bitrate, spin_window=0.0)
    try:
        server = SocketcandServer(network, host=host, port=port, channel=channel)
    except ValueError as exc:
        raise UserInputError(str(exc)) from None
    except OSError as exc:
        raise UserInputError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    return SimulatedArmServer(server, channel, bitrate, pose, [f.spec for f in injected],
                              {name: getattr(options, name) for name in settings},
                              arm.serials)
