"""``seqrun status``, ``seqrun halt``, ``seqrun reset``: the arm outside a sequence.

With no interface configured these talk to a fresh simulator (they say so); point them at
a shared simulator with ``-i socketcand`` (``seqrun sim serve``) or at the real bus.
"""

from __future__ import annotations

import json
import math
import time
from typing import Annotated

import numpy as np
import typer
from rich.console import Console
from rich.live import Live
from rich.table import Table

from seqrun.arm import DEFAULT_ARM
from seqrun.cli.app import app
from seqrun.cli.common import (EXIT_FAULT, ArmOption, BitrateOption, BusKwargsOption,
                               ChannelOption, InterfaceOption, SimOption, connect, fail,
                               load_arm_file, user_errors)
from seqrun.errors import BusError
from seqrun.kinematics import Chain, fk, rpy_from_matrix
from seqrun.powercube.codec import GetParam
from seqrun.powercube.protocol import ParamId, StateFlag



def read_status(client, arm) -> dict:
    """Joints (user degrees), velocities, state words and the end-effector pose."""
    requests = [GetParam(j.module, p) for j in arm.joints
                for p in (ParamId.ACT_POS, ParamId.ACT_VEL, ParamId.CUBE_STATE)]
    acks = client.transact(requests)
    joints = []
    for k, joint in enumerate(arm.joints):
        pos, vel, state = (a.value for a in acks[3 * k:3 * k + 3])
        joints.append({"joint": joint.name, "module": joint.module,
                       "position_deg": round(joint.to_user_deg(float(pos)), 4),
                       "velocity_deg_s": round(math.degrees(float(vel)), 4),
                       "state": StateFlag(state).describe(),
                       "fault": bool(StateFlag(state) & StateFlag.FAULTS)})
    q = np.radians([j["position_deg"] for j in joints])
    T = fk(Chain.from_arm(arm), q)
    return {"joints": joints,
            "end_effector": {"position_mm": [round(float(x), 3) for x in T[:3, 3]],
                             "rpy_deg": [round(float(x), 3)
                                         for x in np.degrees(rpy_from_matrix(T[:3, :3]))]}}


def _table(status: dict, title: str) -> Table:
    table = Table(title=title)
    for col in ("joint", "module", "position °", "velocity °/s", "state"):
        table.add_column(col)
    for j in status["joints"]:
        table.add_row(j["joint"], str(j["module"]), f"{j['position_deg']:.3f}",
                      f"{j['velocity_deg_s']:.3f}", j["state"],
                      style="red" if j["fault"] else None)
    ee = status["end_effector"]
    table.caption = (f"end-effector {ee['position_mm']} mm, roll/pitch/yaw {ee['rpy_deg']} °")
    return table


@app.command("status")
def status_command(
    watch: Annotated[bool, typer.Option("--watch", help="Refresh until Ctrl-C.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
    period: Annotated[float, typer.Option(
        "--period", help="Refresh period with --watch, s.")] = 0.2,
    arm_file: ArmOption = DEFAULT_ARM, interface: InterfaceOption = None,
    channel: ChannelOption = None, bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
) -> None:
    """Joints, state flags and end-effector pose (reads only; nothing moves)."""
    with user_errors():
        arm = load_arm_file(arm_file)
        connection, client = connect(arm, interface, channel, bitrate, bus_kwargs, sim)
    console = Console()
    try:
        # Positions in user angles need the zeros the modules really have.
        from seqrun.cli.zero import zero_for_reading

        arm, zero_text = zero_for_reading(connection, arm)
        if not as_json:
            console.print(connection.description, style="bold", highlight=False)
            console.print(zero_text, highlight=False, markup=False)
        if not watch:
            status = read_status(client, arm)
            if as_json:
                typer.echo(json.dumps(status))
            else:
                console.print(_table(status, arm.name))
            return
        with Live(console=console, refresh_per_second=10) as live:
            while True:
                live.update(_table(read_status(client, arm), arm.name))
                time.sleep(period)
    except KeyboardInterrupt:
        pass
    except BusError as exc:
        console.print(f"error: {exc}", style="red", highlight=False)
        raise typer.Exit(EXIT_FAULT) from None
    finally:
        client.close()
        connection.close()


def _broadcast(what: str, arm_file, interface, channel, bitrate, bus_kwargs, sim) -> None:
    with user_errors():
        arm = load_arm_file(arm_file)
        connection, client = connect(arm, interface, channel, bitrate, bus_kwargs, sim)
    try:
        getattr(client, what)(None)
        typer.echo(f"{what.capitalize()} broadcast sent ({connection.description})")
    except BusError as exc:
        fail(f"{what} not sent: {exc}", EXIT_FAULT)
    finally:
        client.close()
        connection.close()


@app.command("halt")
def halt_command(arm_file: ArmOption = DEFAULT_ARM, interface: InterfaceOption = None,
                 channel: ChannelOption = None, bitrate: BitrateOption = None,
                 bus_kwargs: BusKwargsOption = None, sim: SimOption = False) -> None:
    """Broadcast Halt: every module stops at once and refuses motion until Reset."""
    _broadcast("halt", arm_file, interface, channel, bitrate, bus_kwargs, sim)


@app.command("reset")
def reset_command(arm_file: ArmOption = DEFAULT_ARM, interface: InterfaceOption = None,
                  channel: ChannelOption = None, bitrate: BitrateOption = None,
                  bus_kwargs: BusKwargsOption = None, sim: SimOption = False) -> None:
    """Broadcast Reset: clears ERROR/HALTED (motion still needs Home)."""
    _broadcast("reset", arm_file, interface, channel, bitrate, bus_kwargs, sim)
