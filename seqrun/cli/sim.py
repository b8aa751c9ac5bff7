"""``seqrun sim serve``: the simulated LWA 3 as a socketcand server for other processes.

    seqrun sim serve                                   # 127.0.0.1:29536, channel can0
    seqrun sim serve --port 29600 --fault 4:tow_error@2.5 --fault 3:drop_acks=0.3@0
    seqrun sim serve --home-ok-at-power-on --addressed-refresh-arms-watchdog
    seqrun sim serve --serial-base 5230100 --power-on-at totem   # the same arm, powered on again

Every server is an arm of its own: its modules' serial numbers (which key the zero
reference) are drawn afresh unless ``--serial-base`` names them.

Connect with python-can: ``can.Bus(interface="socketcand", host="127.0.0.1",
port=29536, channel="can0")``. Runs in real time until Ctrl-C.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from seqrun.cli.app import sim_app
from seqrun.cli.common import fail


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
    project_dir: Annotated[Path | None, typer.Option(
        "--project", metavar="DIR", help="Campaign folder (default: the nearest seqrun.toml "
        "above the current folder): its [sim] gripper_part_mm puts the arm file's gripper "
        "on the bus with that part between its jaws, as the dry run has it.")] = None,
    serial_base: Annotated[int, typer.Option(
        "--serial-base", metavar="N", help="Module M says serial number N+M (DefCubeSerial). "
        "Default: a base drawn for this server alone (every server is another arm); give "
        "the same N to power the same arm on again.")] = 0,
) -> None:
    """Serve a simulated LWA 3 (7 modules, powered on at Park or --power-on-at, real time)
    over socketcand."""
    from seqrun.errors import UserInputError
    from seqrun.service.simulator import serve_simulated_arm

    switches: dict[str, object] = {}
    if home_ok_at_power_on:
        switches["home_ok_at_power_on"] = True
    if addressed_refresh_arms_watchdog:
        switches["addressed_refresh_arms_watchdog"] = True
    if serial_base:
        switches["serial_base"] = serial_base
    try:
        part = _campaign_gripper(project_dir, module_option or [], switches)
        served = serve_simulated_arm(host=host, port=port, channel=channel,
                                     faults=fault or [], bitrate=bitrate,
                                     module_options=module_option or [], switches=switches,
                                     power_on_at=power_on_at)
    except UserInputError as exc:
        fail(str(exc))
    server = served.server
    typer.echo(f"simulated LWA 3 (modules 1-7, {bitrate} bit/s, powered on at "
               f"{served.power_on_pose}) on socketcand {server.host}:{server.port}, "
               f"channel {channel}")
    typer.echo("  serials " + ", ".join(f"{m}:{n}" for m, n in served.serials.items()))
    for spec in served.faults:
        typer.echo(f"  fault {spec}")
    for switch, value in served.switches.items():
        typer.echo(f"  switch {switch}={value}")
    if part is not None:
        typer.echo(f"  {part.describe()}")
    typer.echo(f'  python-can: can.Bus(interface="socketcand", host="{server.host}", '
               f'port={server.port}, channel="{channel}")')
    typer.echo("Ctrl-C to stop.")
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        typer.echo("stopping")
    finally:
        server.shutdown()


def _campaign_gripper(project_dir: Path | None, module_options: list[str],
                      switches: dict[str, object]):
    """The campaign's ``[sim] gripper_part_mm`` (seqrun.service.simulated_part): the arm
    file's gripper in ``switches``, with that part between its jaws, so that a run over
    this server finds what the campaign's dry run found. None: no such setting (or the
    part given by hand with --module-option, which wins)."""
    from seqrun.service.arm_context import resolve_context
    from seqrun.service.simulated_part import PART_SWITCH, campaign_part, switch_given

    given = {item.partition("=")[0].strip() for item in module_options}
    if switch_given(dict.fromkeys(given)):
        return None
    context = resolve_context(project_dir=project_dir, sim=True)
    part = campaign_part(context.project)
    gripper = context.arm.gripper if part is not None else None
    if part is None or gripper is None:
        return None
    switches["gripper_module"] = gripper.module
    switches[PART_SWITCH] = part.width_mm
    return part
