"""``seqrun sim serve``: the simulated LWA 3 as a socketcand server for other processes.

    seqrun sim serve                                   # 127.0.0.1:29536, channel can0
    seqrun sim serve --port 29600 --fault 4:tow_error@2.5 --fault 3:drop_acks=0.3@0
    seqrun sim serve --home-ok-at-power-on --addressed-refresh-arms-watchdog

Connect with python-can: ``can.Bus(interface="socketcand", host="127.0.0.1",
port=29536, channel="can0")``. Runs in real time until Ctrl-C.
"""

from __future__ import annotations

from typing import Annotated

import typer

from seqrun.cli.app import sim_app
from seqrun.cli.common import fail


def _power_off_pose(name: str) -> str:
    """``name`` as a power-off pose of the shipped arm (one line and exit 2 otherwise)."""
    from seqrun.arm.description import load_arm
    from seqrun.errors import UserInputError
    from seqrun.shipped import DEFAULT_ARM_NAME, shipped_arm

    path = shipped_arm(DEFAULT_ARM_NAME)
    assert path is not None  # (shipped with seqrun)
    arm = load_arm(path)
    try:
        arm.power_off_pose(name)
    except UserInputError as exc:
        fail(f"--power-on-at: {exc}")
    return name if name in arm.power_off_poses else name.lower()


@sim_app.command("serve")
def serve(
    port: Annotated[int, typer.Option(help="TCP port to listen on.")] = 29536,
    host: Annotated[str, typer.Option(
        help="Loopback address to bind (127.0.0.1, ::1 or localhost only).")] = "127.0.0.1",
    channel: Annotated[str, typer.Option(help="socketcand channel name clients open.")] = "can0",
    fault: Annotated[list[str] | None, typer.Option(
        "--fault", metavar="SPEC",
        help="Inject a fault MODULE:KIND[=RATE]@SECONDS, e.g. 4:tow_error@2.5, all:halt@1, "
             "3:drop_acks=0.3@0. Repeatable. Kinds: tow_error, halt, no_ack, drop_acks, "
             "stuck, missing.")] = None,
    bitrate: Annotated[int, typer.Option(help="Bit rate of the simulated bus, bit/s.")]
    = 1_000_000,
    home_ok_at_power_on: Annotated[bool, typer.Option(
        "--home-ok-at-power-on",
        help="Modules power on with HOME_OK set (as drivers that never home PRL modules "
             "expect). Default: not homed until Home, as this facility's arm.")] = False,
    addressed_refresh_arms_watchdog: Annotated[bool, typer.Option(
        "--addressed-refresh-arms-watchdog",
        help="Only an addressed WatchdogRefresh (0x0E0+m [07]) arms the watchdog, setting "
             "its Config bit (KTH driver). Default: the Config bit, then any refresh.")]
    = False,
    module_option: Annotated[list[str] | None, typer.Option(
        "--module-option", metavar="NAME=VALUE",
        help="Any other simulator switch (ModuleOptions field), e.g. "
             "watchdog_timeout=0.1. Repeatable.")] = None,
    power_on_at: Annotated[str, typer.Option(
        "--power-on-at", metavar="POSE", help="The power-off pose the simulated arm stands in "
        "at power-on (its modules read zero there): park or totem.")] = "park",
) -> None:
    """Serve a simulated LWA 3 (7 modules, powered on at Park or --power-on-at, real time)
    over socketcand."""
    from seqrun.clock import RealClock
    from seqrun.sim.arm import SimArm
    from seqrun.sim.faults import parse_faults
    from seqrun.sim.network import SimNetwork
    from seqrun.sim.options import module_options
    from seqrun.sim.socketcand import SocketcandServer

    try:
        faults = parse_faults(fault or [])
    except ValueError as exc:
        fail(str(exc))
    power_on_at = _power_off_pose(power_on_at)
    if not 0 <= port <= 65535:
        fail(f"--port {port}: must be 0..65535")
    if bitrate <= 0:
        fail(f"--bitrate {bitrate}: must be positive")
    switches: dict[str, object] = {}
    for item in module_option or []:
        name, sep, value = item.partition("=")
        if not sep or not name:
            fail(f"--module-option expects NAME=VALUE, got '{item}'")
        switches[name.strip()] = value.strip()
    if home_ok_at_power_on:
        switches["home_ok_at_power_on"] = True
    if addressed_refresh_arms_watchdog:
        switches["addressed_refresh_arms_watchdog"] = True
    from seqrun.service.connection import sim_options_from_env
    from seqrun.errors import UserInputError

    try:  # SEQRUN_SIM_OPTIONS first, the flags on top
        options = module_options(switches, sim_options_from_env())
    except ValueError as exc:
        fail(f"--module-option {exc}")
    except UserInputError as exc:
        fail(str(exc))
    clock = RealClock()
    # No spinning: TCP adds more latency than a late wake-up, and clients may be many.
    try:
        arm = SimArm(clock, faults=faults, options=options, power_on_pose=power_on_at)
    except ValueError as exc:  # a fault for a module the arm does not have
        fail(str(exc))
    network = SimNetwork(clock, arm, bitrate, spin_window=0.0)
    try:
        server = SocketcandServer(network, host=host, port=port, channel=channel)
    except ValueError as exc:
        fail(str(exc))
    except OSError as exc:
        fail(f"cannot listen on {host}:{port}: {exc.strerror or exc}")
    typer.echo(f"simulated LWA 3 (modules 1-7, {bitrate} bit/s, powered on at "
               f"{power_on_at}) on socketcand {server.host}:{server.port}, channel {channel}")
    for injected in faults:
        typer.echo(f"  fault {injected.spec}")
    for switch in switches:
        typer.echo(f"  switch {switch}={getattr(options, switch)}")
    typer.echo(f'  python-can: can.Bus(interface="socketcand", host="{server.host}", '
               f'port={server.port}, channel="{channel}")')
    typer.echo("Ctrl-C to stop.")
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        typer.echo("stopping")
    finally:
        server.shutdown()
