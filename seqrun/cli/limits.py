"""``seqrun limits show`` and ``seqrun limits set``: the limits stored in the modules.

``show`` reads MinPos/MaxPos/MaxVel/MaxAcc/MaxCur from every module (user units) and
prints them beside the arm file's values, marking every difference (``--json`` too);
``set`` writes the arm file's values and confirms each one by reading it back. Both act
on the bus of the arm context and claim it: refused while a run or console holds it (it
writes and reads the same parameters the run relies on). With no bus configured, as
``seqrun reset``: there is no private simulator to read (give ``--sim`` for one).
"""

from __future__ import annotations

import json
from typing import Annotated, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.common import (EXIT_FAULT, ArmFileOption, BitrateOption, BusKwargsOption,
                               CampaignOption, ChannelOption, InterfaceOption, OneArmOption,
                               ResponseTimeoutOption, SimOption, fail, user_errors)
from seqrun.cli.zero import ZeroConfirmedOption

limits_app = typer.Typer(help="The limits stored in the modules (MinPos/MaxPos/MaxVel/"
                              "MaxAcc/MaxCur) beside the arm file's.", no_args_is_help=True)
app.add_typer(limits_app, name="limits")

JsonOption = Annotated[bool, typer.Option("--json", help="Machine-readable output.")]
JointsOption = Annotated[Optional[str], typer.Option(
    "--joints", metavar="J1,J2", help="Write only these joints (default: every joint).")]


def _context(arm_file, project_dir, interface, channel, bitrate, bus_kwargs, sim,
             response_timeout_ms, what: str, arm_id: str | None = None):
    """The arm context whose bus the command opens: refused when no bus is given while a
    run or console is live (never a private simulator instead)."""
    from seqrun.cli.bus_owner import live_targets
    from seqrun.service.arm_context import resolve_context
    from seqrun.service.connection import response_timeout_s

    context = resolve_context(project_dir=project_dir, arm_file=arm_file,
                              interface=interface, channel=channel, bitrate=bitrate,
                              bus_kwargs=bus_kwargs or [], sim=sim,
                              response_timeout_ms=response_timeout_ms, arm_id=arm_id)
    response_timeout_s(context.arm, response_timeout_ms)
    live = live_targets(context, what)
    if live:
        from seqrun.errors import UserInputError

        raise UserInputError(
            "no bus configured, and " + ", ".join(f"seqrun pid {h.pid} ({h.command})"
                                                  for h in live)
            + " live on this machine: name its bus with -i/-c (refused while it holds it)")
    return context


def _number(value: float | None) -> str:
    from seqrun.cli.output import fixed

    return "-" if value is None else fixed(value, 3)


def _print_rows(rows, title: str) -> int:
    """The table of ``limits show``; returns the number of differences."""
    from rich.table import Table

    from seqrun.cli.output import make_console
    from seqrun.service.module_limits import LIMIT_FIELDS

    table = Table(title=title)
    table.add_column("joint")
    table.add_column("module")
    for _, heading, unit, _ in LIMIT_FIELDS:
        table.add_column(f"{heading} {unit}")
    differences = 0
    for row in rows:
        cells = []
        for key, *_ in LIMIT_FIELDS:
            held, arm = _number(row.held[key]), _number(row.arm[key])
            if row.differs(key):
                differences += 1
                cells.append(f"{held} ≠ {arm}")
            else:
                cells.append(held)
        table.add_row(row.joint, str(row.module), *cells,
                      style="yellow" if row.differences else None)
    table.caption = (f"{differences} value(s) differ from the arm file (module ≠ arm file)"
                     if differences else "every value as the arm file says")
    console = make_console()
    console.width = max(console.width, 160)
    console.print(table)
    return differences


@limits_app.command("show")
def show_command(as_json: JsonOption = False,
                 arm_file: ArmFileOption = None, project_dir: CampaignOption = None,
                 interface: InterfaceOption = None,
                 channel: ChannelOption = None, bitrate: BitrateOption = None,
                 bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
                 response_timeout_ms: ResponseTimeoutOption = None,
                 arm_id: OneArmOption = None) -> None:
    """Read MinPos/MaxPos/MaxVel/MaxAcc/MaxCur from every module (reads only) and print
    them in user units beside the arm file's, marking every difference. Exit 0 either
    way (differences are information: `seqrun limits set` writes the arm file's)."""
    from seqrun.errors import BusError
    from seqrun.formatting import terminal_text
    from seqrun.service.module_limits import read_module_limits

    with user_errors():
        context = _context(arm_file, project_dir, interface, channel, bitrate, bus_kwargs,
                           sim, response_timeout_ms, "read the limits of", arm_id)
        # MinPos/MaxPos converted with the zero in force: after a power-off elsewhere than
        # the arm file's default pose, the default offsets would shift them
        connection, driver, arm, zero_text = context.open_arm_for_reading()
        zero_text = terminal_text(zero_text, lines=True)   # the record's text is a file's
    try:
        rows = read_module_limits(driver, arm)
    except BusError as exc:
        fail(f"limits not read: {exc}", EXIT_FAULT)
    finally:
        driver.close()
        connection.close()
    if as_json:
        typer.echo(json.dumps({"arm": context.arm.name, "bus": connection.description,
                               "zero": zero_text,
                               "differences": sum(len(r.differences) for r in rows),
                               "joints": [r.as_dict() for r in rows]}))
        return
    typer.echo(context.headline(connection))
    typer.echo(zero_text)
    _print_rows(rows, f"{context.arm.name}: limits in the modules")


@limits_app.command("set")
def set_command(joints: JointsOption = None, as_json: JsonOption = False,
                arm_file: ArmFileOption = None, project_dir: CampaignOption = None,
                interface: InterfaceOption = None,
                channel: ChannelOption = None, bitrate: BitrateOption = None,
                bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
                response_timeout_ms: ResponseTimeoutOption = None,
                 arm_id: OneArmOption = None,
                 zero_confirmed: ZeroConfirmedOption = None) -> None:
    """Write the arm file's MinPos/MaxPos/MaxVel/MaxAcc (and MaxCur where it gives one)
    into the modules, each confirmed by reading it back (exit 3 naming a value that
    reads back different), then show them as `limits show` does. The positions are
    converted with the zero in force: after a power-on the operator confirms it first (or
    --zero-confirmed POSE)."""
    from seqrun.cli.zero import open_arm_at_zero
    from seqrun.errors import BusError, RunAborted
    from seqrun.service.arm_access import modules_of
    from seqrun.service.module_limits import read_module_limits, write_arm_limits

    names = None if joints is None else [n.strip() for n in joints.split(",") if n.strip()]
    with user_errors():
        context = _context(arm_file, project_dir, interface, channel, bitrate, bus_kwargs,
                           sim, response_timeout_ms, "write the limits of", arm_id)
        # What the modules let the arm do changes: the zero decided and the arm's identity
        # checked first, as before every motion (--json: what that says goes to stderr).
        connection, driver, _ = open_arm_at_zero(context, zero_confirmed, arm_id,
                                                 to_stderr=as_json)
    try:
        with user_errors():
            modules_of(context.arm, names)   # unknown joint names: one line, exit 2
        written = write_arm_limits(driver, context.arm, names)
        rows = read_module_limits(driver, context.arm)
    except (BusError, RunAborted) as exc:
        fail(f"limits not written: {exc}", EXIT_FAULT)
    finally:
        driver.close()
        connection.close()
    if as_json:
        typer.echo(json.dumps({"arm": context.arm.name, "bus": connection.description,
                               "written": written,
                               "differences": sum(len(r.differences) for r in rows),
                               "joints": [r.as_dict() for r in rows]}))
        return
    typer.echo(context.headline(connection))
    typer.echo(f"{written} values written and read back ({connection.description})")
    _print_rows(rows, f"{context.arm.name}: limits in the modules")
