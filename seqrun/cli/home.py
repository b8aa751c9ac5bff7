"""``seqrun home [--joints j1,j2]``: Home the modules, confirmed by reading each one back.

Like ``seqrun reset`` it acts on the bus of the arm context (seqrun/service/arm_context.py)
and claims it: refused (exit 2, one line naming the holder) while a run or a console holds
the bus, and with no bus configured it never homes a private simulator of its own (a live
console has a Home button). A module that is halted or in error is not homed: Home is
not a Reset (exit 3, naming it). Success means every module named reported HOME_OK at
rest; a module that travels to its home switch is waited for.

In a campaign with several arms (``[arms.ID]``, docs/two-arms.md) it homes every arm, or
those named with ``--arm-id``, one after the other, each confirmed as one arm is: the
arm's line, then its verdict. An arm that fails (refused, not sent, not confirmed) does
not keep the next from being homed; the command then exits with the worst code, naming
the arms that failed.
"""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.common import (ArmFileOption, BitrateOption, BusKwargsOption,
                               CampaignOption, ChannelOption, InterfaceOption,
                               ResponseTimeoutOption, SimOption, ZeroConfirmedPerArmOption,
                               fail, user_errors, zero_confirmed_of)
from seqrun.cli.arm_commands import ArmIdOption

JointsOption = Annotated[Optional[str], typer.Option(
    "--joints", metavar="J1,J2", help="Home only these joints (names, comma-separated; "
                                      "default: every module of the arm, broadcast).")]


@app.command("home")
def home_command(joints: JointsOption = None,
                 arm_file: ArmFileOption = None, project_dir: CampaignOption = None,
                 interface: InterfaceOption = None,
                 channel: ChannelOption = None, bitrate: BitrateOption = None,
                 bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
                 response_timeout_ms: ResponseTimeoutOption = None,
                 arm_id: ArmIdOption = None,
                 zero_confirmed: ZeroConfirmedPerArmOption = None) -> None:
    """Home the modules (enables the motors; a PRL does not move). Confirmed by reading
    every module back (HOME_OK, not moving); exit 3 naming the modules that did not
    confirm, or that are halted or in error (seqrun reset first). Refused while a run or
    console holds the bus. With no bus configured: exit 2 (a live console homes its arm
    with its Home button). In a campaign with several arms: every arm, one after the other
    (--arm-id ID: that one); an arm that fails does not keep the next from being homed."""
    from seqrun.cli.arm_commands import arm_ids_of, each_arm

    with user_errors():
        ids = arm_ids_of(arm_id, project_dir, interface, channel, arm_file)
    confirmed = zero_confirmed_of(zero_confirmed, ids)
    each_arm(ids, lambda one: _home_arm(one, joints, arm_file, project_dir, interface,
                                         channel, bitrate, bus_kwargs, sim,
                                         response_timeout_ms, confirmed.get(one)))


def _home_arm(arm_id, joints, arm_file, project_dir, interface, channel, bitrate, bus_kwargs,
              sim, response_timeout_ms, zero_confirmed=None) -> None:
    """Home one arm (None: the one arm of the context) and confirm it; a failure is one
    ``error:`` line and ``typer.Exit`` with its code."""
    from seqrun.cli.arm_commands import command_context
    from seqrun.cli.bus_owner import live_targets
    from seqrun.errors import Refused, UserInputError
    from seqrun.cli.confirmation import confirmed_or_exit
    from seqrun.cli.zero import open_arm_at_zero
    from seqrun.service.arm_access import home_and_confirm, modules_of

    arm = f"arm {arm_id}: " if arm_id is not None else ""
    with user_errors():
        context = command_context(arm_file, project_dir, interface, channel, bitrate, bus_kwargs,
                           sim, response_timeout_ms, arm_id)
        modules = modules_of(context.arm, _names(joints))
        try:
            live_targets(context, "home")
            connection, driver, _ = open_arm_at_zero(context, zero_confirmed, arm_id)
        except (UserInputError, Refused) as exc:  # which arm's bus is held, or missing
            fail(f"{arm}{exc}")
    try:
        result = home_and_confirm(driver, modules)
    finally:
        driver.close()
        connection.close()
    confirmed_or_exit(result, connection.description, what="home", prefix=arm,
                      confirmed_in=f" in {result.duration_s:.2f} s")


def _names(joints: str | None) -> list[str] | None:
    if joints is None:
        return None
    return [name.strip() for name in joints.split(",") if name.strip()]
