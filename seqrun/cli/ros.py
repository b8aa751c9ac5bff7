"""``seqrun ros``: the arm session as a ROS 2 node (docs/ros2-node.md).

    seqrun ros                          # simulator (no bus configured)
    seqrun ros -i socketcan -c can0     # the real arm
    seqrun ros --ros-args -r __ns:=/cell1 -p rate:=50   # ROS arguments, to rclpy

Everything from ``--ros-args`` on (to a ``--`` that ends it) is ROS's, handed to rclpy as
it is (remapping, namespace, parameters, log levels); the rest is this command's options.

Needs the optional extra ``seqrun[ros]`` (or a sourced ROS 2 installation); without it the
command prints one line saying how to install it (exit 2). rclpy is imported only when the
command runs.
"""

from __future__ import annotations

import signal
import threading
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
from typer.core import TyperCommand

from seqrun.cli.app import app
from seqrun.cli.common import (EXIT_USAGE, ArmFileOption, BitrateOption,
                               BusKwargsOption, CampaignOption, ChannelOption,
                               InterfaceOption, OneArmOption, ResponseTimeoutOption,
                               SimOption, fail, user_errors)
from seqrun.cli.questions import ask
from seqrun.defaults import EXIT_OPERATOR_ABORT


#: Where ``seqrun ros`` keeps the ROS arguments of its command line (``ctx.meta``).
ROS_ARGS = "seqrun.ros_args"


def split_ros_args(args: list[str]) -> tuple[list[str], list[str]]:
    """``args`` as (this command's, ROS's): ROS's run from ``--ros-args`` to a ``--`` (which
    ends them, as rcl reads it) or the end; there may be several such runs."""
    ours: list[str] = []
    ros: list[str] = []
    inside = False
    for token in args:
        if token == "--ros-args":
            inside = True
            ros.append(token)
        elif inside and token == "--":
            inside = False
        elif inside:
            ros.append(token)
        else:
            ours.append(token)
    return ours, ros


class RosCommand(TyperCommand):
    """``seqrun ros`` with ``--ros-args ...``: click never sees ROS's arguments (``-r``,
    ``-p`` would be read as unknown options of this command)."""

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        ours, ros = split_ros_args(list(args))
        ctx.meta[ROS_ARGS] = ros
        return super().parse_args(ctx, ours)


@app.command("ros", cls=RosCommand)
def ros_command(
    ctx: typer.Context,
    interface: InterfaceOption = None,
    channel: ChannelOption = None,
    bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None,
    sim: SimOption = False,
    arm_file: ArmFileOption = None,
    project_dir: CampaignOption = None,
    log_dir: Annotated[Optional[Path], typer.Option(
        "--log-dir", metavar="DIR", help="Where run folders go (default: the project's runs/).")]
    = None,
    arm_name: Annotated[Optional[str], typer.Option(
        "--arm-name", metavar="NAME",
        help="The <arm> of /<arm>/joint_states and /<arm>/joint_trajectory (default: the "
             "arm file's name, e.g. lwa3; in a campaign with several arms, the arm's id).")]
    = None,
    node_name: Annotated[Optional[str], typer.Option(
        "--node-name", metavar="NAME",
        help="The node's name: its services and events are /NAME/stop, /NAME/home, "
             "/NAME/reset, /NAME/events (default seqrun; in a campaign with several arms, "
             "seqrun_ID: each arm's node its own).")] = None,
    rate: Annotated[float, typer.Option(
        "--rate", metavar="HZ", help="joint_states (and /tf) rate in Hz (at least 50).")]
    = 100.0,
    response_timeout_ms: ResponseTimeoutOption = None,
    zero_confirmed: Annotated[Optional[str], typer.Option(
        "--zero-confirmed", metavar="POSE", help="Answer 'does the arm stand in POSE?' after "
        "a power-on without asking (a different record refuses to start).")] = None,
    arm_id: OneArmOption = None,
) -> None:
    """Serve the arm on ROS 2: joint_states, robot_description, /tf, JointTrajectory,
    ~/stop ~/home ~/reset. ROS arguments follow --ros-args (-r __ns:=/NS, -p rate:=50)."""
    from seqrun.ros import missing

    absent = missing()
    if absent is not None:
        typer.echo(absent, err=True)
        raise typer.Exit(EXIT_USAGE)
    from seqrun.cli.zero import zero_or_exit
    from seqrun.service.arm_context import resolve_context
    from seqrun.service.connection import response_timeout_s

    with user_errors():
        if not 50 <= rate <= 1000:
            fail(f"--rate must lie in 50-1000 Hz, got {rate:g}")
        context = resolve_context(project_dir=project_dir, arm_file=arm_file,
                                  log_dir=log_dir, interface=interface, channel=channel,
                                  bitrate=bitrate, bus_kwargs=bus_kwargs or [], sim=sim,
                                  response_timeout_ms=response_timeout_ms, arm_id=arm_id)
        project, arm = context.project, context.arm
        timeout = response_timeout_s(arm, response_timeout_ms)
        context.refuse_private_simulator("ros")
        connection = context.open_connection(live=True)
    typer.echo(context.headline(connection))
    try:
        zero = zero_or_exit(connection, arm, lambda q: ask(q, False), typer.echo,
                            confirmed=zero_confirmed)
        arm = zero.apply(arm)
    except BaseException:
        connection.close()
        raise
    runs = context.runs_dir
    runs = runs if runs.is_absolute() else Path.cwd() / runs

    import rclpy
    from rclpy.executors import ExternalShutdownException

    from seqrun.ros.node import NodeTaken, SeqrunNode, spin
    from seqrun.service.session import ArmSession

    session = ArmSession(arm, connection, project=project, log_root=runs, zero=zero,
                         response_timeout_s=timeout, arm_id=context.arm_id)
    from seqrun.service.arm_separation import attach_other_arms

    attach_other_arms(session, context)  # every trajectory against the other arms
    from seqrun.ros.node import ros_name
    from seqrun.service.arm_context import campaign_arm_ids

    one_of_several = len(campaign_arm_ids(project)) > 1 and context.arm_id is not None
    name = arm_name or (str(context.arm_id) if one_of_several
                        else Path(arm.source_file or "arm").stem)
    node_name = node_name or (f"seqrun_{ros_name(str(context.arm_id))}" if one_of_several
                              else "seqrun")
    ros_args = list(ctx.meta.get(ROS_ARGS, []))
    try:
        rclpy.init(args=["seqrun", *ros_args])
    except Exception as exc:  # noqa: BLE001 - rcl's parse error: one line, no traceback
        session.close()
        fail(f"--ros-args: {str(exc).strip().splitlines()[0] if str(exc).strip() else exc}")
    terminated = threading.Event()
    # the handler only sets a flag: an exception raised into the executor at any bytecode
    # could leave a worker thread started but not registered, and the process never ends
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: terminated.set())
    node = None
    try:
        try:
            with user_errors():  # a parameter out of range (-p rate:=5): one line
                node = SeqrunNode(session, arm_name=name, rate_hz=rate, node_name=node_name,
                                  discovery_s=_discovery_s())
        except NodeTaken as exc:
            fail(str(exc))
        banner = "SIMULATOR" if connection.is_simulator else connection.description
        typer.echo(f"seqrun ros on {banner}: {node.joint_states.topic_name}, "
                   f"{node.node.resolve_topic_name(node.arm + '/joint_trajectory')}, "
                   f"{node.node.get_fully_qualified_name()}/stop;"
                   " Ctrl-C ends it (any motion is stopped first)")
        spin(node, until=terminated.is_set)
        if not terminated.is_set():
            raise ExternalShutdownException()  # the context was shut down (Ctrl-C)
        result = session.halt("SIGTERM (seqrun ros)")
        typer.echo(f"seqrun ros: ended by SIGTERM; {result.describe()}")
        raise typer.Exit(EXIT_OPERATOR_ABORT)
    except (KeyboardInterrupt, ExternalShutdownException):
        typer.echo("seqrun ros: ended by Ctrl-C; anything still moving is stopped")
        raise typer.Exit(EXIT_OPERATOR_ABORT) from None
    finally:
        signal.signal(signal.SIGTERM, previous)
        if node is not None:
            node.close()
        session.close()  # controlled stop of anything still moving, then the bus
        if rclpy.ok():
            rclpy.shutdown()


#: How long the node watches the ROS graph for another node of its name or arm before it
#: serves (s): ``$SEQRUN_ROS_DISCOVERY_S``, else the node's default (a busy host may need
#: more: discovery there takes over a second).
DISCOVERY_ENV = "SEQRUN_ROS_DISCOVERY_S"


def _discovery_s() -> float | None:
    import math
    import os

    text = os.environ.get(DISCOVERY_ENV)
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or not 0 < value <= 300:
        fail(f"${DISCOVERY_ENV}={text!r}: expected seconds, more than 0 and at most 300")
    return value
